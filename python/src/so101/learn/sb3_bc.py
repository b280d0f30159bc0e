"""so101-learn bc: behaviour cloning with `imitation` (imitation.algorithms.bc.BC, an SB3 MLP
policy) on demonstrations of the scripted expert, all in-process, then an evaluation.

1. demonstrations: --demos seeded cube_to_bin episodes of so101.evaluate.expert.ExpertPolicy (with
   --waypoint-noise / --action-noise, so the demonstrations cover some states off the ideal path),
   stepped through the learning wrappers (so101.learn.wrappers: flat observation, relative actions
   of at most --max-step rad per period); the expert's targets become relative actions. Failed
   episodes are dropped (and counted). 200 by default: the expert's waits for the servos differ
   from episode to episode, and SAC's clone of 100 succeeded in 68 % of 50 episodes, of 200 in
   98 % (docs/benchmarks.md).
2. training: --epochs over the transitions, MLP --hidden (default 256 256), batch --batch-size.
   The MLP's units are ReLUs and its weights start at PyTorch's default initialization, not SB3's
   ActorCriticPolicy defaults (tanh units, orthogonal initialization): on the STS3215 servos,
   whose ramps make the expert wait for the arm, the defaults' clone stalled short of the grasp in
   every episode (0 of 20); ReLU alone 54 of 70, ReLU without the orthogonal start 64 of 70
   (tuning seeds 1000-1069, docs/benchmarks.md).
3. output (--output, default <checkout>/outputs/bc-<time>/): policy.pth (the SB3 policy, `policy.save`),
   so101_learn.json (task, wrappers' parameters, training settings), bc_log/ (imitation's log).
4. evaluation: --eval seeded episodes from --eval-seed (other seeds than the demonstrations'),
   deterministic actions, eval/eval_info.json; success rate with its 95 % interval.
5. --continue-with-sac STEPS: then SAC on the dense reward continuing from the clone, the
   demonstrations in its replay buffer (so101.learn.bc_to_sac; output in <output>/sac/).

Measured: docs/benchmarks.md, "Learning".

Evaluate again, with videos: so101-learn eval OUTPUT --videos.
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..paths import repo_root
from . import bc_to_sac
from .wrappers import MAX_STEP, SETTINGS_FILE, EnvSettings, flatten, relative_action

# Floor of the standardization's scale: the cube's height and tilt hardly vary while it rests.
MIN_SCALE = 0.01

POLICY_FILE = "policy.pth"


def add_arguments(p: argparse.ArgumentParser) -> None:
    demos = p.add_argument_group("demonstrations")
    demos.add_argument("--demos", type=int, default=200, metavar="N", help="expert episodes to run (failed ones are dropped)")
    demos.add_argument("--waypoint-noise", type=float, default=0.005, help="the expert's waypoint noise (m)")
    demos.add_argument("--action-noise", type=float, default=0.01, help="the expert's joint-target noise (rad)")
    demos.add_argument("--seed", type=int, default=0, help="seed of the expert and of the first episode (then seed+1, ...)")
    train = p.add_argument_group("training")
    train.add_argument("--epochs", type=int, default=100, help="passes over the demonstrations")
    train.add_argument("--batch-size", type=int, default=256)
    train.add_argument("--lr", type=float, default=1e-3, help="Adam's learning rate")
    train.add_argument("--hidden", type=int, nargs="+", default=[256, 256], metavar="UNITS", help="the MLP's hidden layers")
    train.add_argument("--max-step", type=float, default=MAX_STEP, help="largest joint move per control period (rad)")
    train.add_argument(
        "--no-time-cue", action="store_true", help="leave the elapsed time out of the observation (so101.learn.wrappers)"
    )
    train.add_argument("--output", default=None, help="directory for the policy (default <checkout>/outputs/bc-<time>/)")
    ev = p.add_argument_group("evaluation")
    ev.add_argument("--eval", type=int, default=50, metavar="M", help="seeded evaluation episodes (0: none)")
    ev.add_argument("--eval-seed", type=int, default=1000, help="seed of the first evaluation episode")
    bc_to_sac.add_arguments(p)
    p.add_argument(
        "--torch-threads", type=int, default=1, help="torch's CPU threads (small MLPs: 1 is as fast, more stall on busy cores)"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars")


def collect_demonstrations(
    settings: EnvSettings, episodes: int, waypoint_noise: float, action_noise: float, seed: int, quiet: bool = False
):
    """The expert's successful episodes as imitation TransitionsWithRew in the wrappers' spaces
    (rewards of `settings`' reward mode; dones: the episode terminated there), and the number of
    episodes dropped because the expert failed them. Sets `settings`' observation standardization
    to the demonstrations' mean and standard deviation."""
    from imitation.data.types import TransitionsWithRew

    from ..evaluate.expert import ExpertPolicy

    env = settings.make(flat=False)
    expert = ExpertPolicy(waypoint_noise=waypoint_noise, action_noise=action_noise, seed=seed)
    kept: list[tuple[list, list, list, list, list]] = []
    dropped = 0
    for index in tqdm(range(episodes), desc="demonstrations", unit="ep", disable=quiet):
        observation, _ = env.reset(seed=seed + index)
        try:
            expert.reset(observation)
        except ValueError:  # no grasp reaches this cube
            dropped += 1
            continue
        observations, actions, next_observations, rewards, terminals = [], [], [], [], []
        success = False
        for _ in range(settings.episode_steps):
            action = relative_action(expert(observation), observation["agent_pos"], np.asarray(settings.max_step))
            observations.append(flatten(observation, settings.keys))
            actions.append(action)
            observation, reward, terminated, _, info = env.step(action)
            next_observations.append(flatten(observation, settings.keys))
            rewards.append(reward)
            terminals.append(terminated)
            success = success or bool(info["is_success"])
            if terminated:
                break
        if success:
            kept.append((observations, actions, next_observations, rewards, terminals))
        else:
            dropped += 1
    env.close()
    if not kept:
        raise SystemExit("so101-learn bc: the expert succeeded in none of the episodes")
    observations, actions, next_observations, rewards, terminals = (np.concatenate(part) for part in zip(*kept))
    shift, scale = observations.mean(axis=0), np.maximum(observations.std(axis=0), MIN_SCALE)
    settings.observation_shift, settings.observation_scale = shift.tolist(), scale.tolist()
    transitions = TransitionsWithRew(
        obs=((observations - shift) / scale).astype(np.float32),
        acts=actions.astype(np.float32),
        infos=np.array([{}] * len(observations)),
        next_obs=((next_observations - shift) / scale).astype(np.float32),
        dones=terminals.astype(bool),
        rews=rewards.astype(np.float32),
    )
    return transitions, len(kept), dropped


def train(
    transitions,
    settings: EnvSettings,
    epochs: int,
    batch_size: int,
    lr: float,
    hidden: list[int],
    seed: int,
    log_dir: Path,
    quiet: bool = False,
):
    """A BC-trained SB3 ActorCriticPolicy, with the BC loss on all transitions before and after."""
    import torch
    from imitation.algorithms import bc
    from imitation.util import logger as imitation_logger
    from stable_baselines3.common.policies import ActorCriticPolicy

    torch.manual_seed(seed)
    env = settings.make()
    policy = ActorCriticPolicy(
        env.observation_space,
        env.action_space,
        lr_schedule=lambda _: lr,  # unused: BC has its own optimizer
        net_arch=list(hidden),
        activation_fn=torch.nn.ReLU,
        ortho_init=False,
    )
    trainer = bc.BC(
        observation_space=env.observation_space,
        action_space=env.action_space,
        rng=np.random.default_rng(seed),
        policy=policy,
        demonstrations=transitions,
        batch_size=batch_size,
        optimizer_kwargs={"lr": lr},
        device="cpu",
        custom_logger=imitation_logger.configure(str(log_dir), format_strs=["csv"]),
    )
    env.close()

    def loss() -> float:
        with torch.no_grad():
            return float(trainer.loss_calculator(trainer.policy, transitions.obs, transitions.acts).loss)

    before = loss()
    with warnings.catch_warnings():
        # imitation 1.0.1 logs its metrics with float(tensor requiring grad), which torch warns of.
        warnings.filterwarnings("ignore", message="Converting a tensor with requires_grad=True")
        trainer.train(n_epochs=epochs, progress_bar=not quiet, log_interval=max(1, len(transitions) // batch_size))
    return trainer.policy, before, loss()


def run(args) -> int:
    import torch

    from .eval_recipe import evaluate_saved

    torch.set_num_threads(args.torch_threads)
    output = Path(args.output or repo_root() / "outputs" / f"bc-{time.strftime('%Y%m%d-%H%M%S')}")
    output.mkdir(parents=True, exist_ok=True)
    # The dense reward when SAC follows: the demonstrations' rewards go into its replay buffer.
    settings = EnvSettings(
        task="cube_to_bin", max_step=args.max_step, elapsed_time=not args.no_time_cue, dense_reward=args.continue_with_sac > 0
    )
    begun = time.monotonic()
    transitions, kept, dropped = collect_demonstrations(
        settings, args.demos, args.waypoint_noise, args.action_noise, args.seed, quiet=args.quiet
    )
    demo_time = time.monotonic() - begun
    print(
        f"demonstrations: {kept} of {args.demos} expert episodes kept ({dropped} failed, dropped), {len(transitions)} transitions, {demo_time:.0f} s"
    )

    begun = time.monotonic()
    policy, loss_before, loss_after = train(
        transitions, settings, args.epochs, args.batch_size, args.lr, args.hidden, args.seed, output / "bc_log", args.quiet
    )
    train_time = time.monotonic() - begun
    policy.save(str(output / POLICY_FILE))
    record = {
        "algorithm": "bc",
        "model": POLICY_FILE,
        "env": settings.to_dict(),
        "demonstrations": {
            "episodes": args.demos,
            "kept": kept,
            "dropped": dropped,
            "transitions": len(transitions),
            "waypoint_noise": args.waypoint_noise,
            "action_noise": args.action_noise,
            "seed": args.seed,
        },
        "training": {
            "epochs": args.epochs,
            "batch_size": args.batch_size,
            "lr": args.lr,
            "hidden": list(args.hidden),
            "loss_before": loss_before,
            "loss_after": loss_after,
            "wall_time_s": train_time,
        },
    }
    (output / SETTINGS_FILE).write_text(json.dumps(record, indent=2))
    print(f"training: {args.epochs} epochs in {train_time:.0f} s, BC loss {loss_before:.3f} -> {loss_after:.3f}")

    summary = None
    if args.eval > 0:
        summary = evaluate_saved(output, episodes=args.eval, seed=args.eval_seed, output=output / "eval", quiet=args.quiet)
    print_summary(output, kept, dropped, len(transitions), train_time, summary)
    if args.continue_with_sac > 0:
        return bc_to_sac.continue_with_sac(args, settings, transitions, output)
    return 0


def print_summary(output: Path, kept: int, dropped: int, transitions: int, train_time: float, summary: dict | None) -> None:
    print("\n=== so101-learn bc ===")
    print(f"demonstrations  {kept} used ({dropped} failed expert episodes dropped), {transitions} transitions")
    print(f"training        {train_time:.0f} s wall time")
    if summary:
        low, high = summary["pc_success_ci95"]
        print(
            f"evaluation      {summary['successes']}/{summary['episodes']} successes: {summary['pc_success']:.0f} % "
            f"(95 % interval {low:.0f}-{high:.0f} %), mean reward {summary['avg_sum_reward']:.2f}"
        )
    print(f"policy          {output / POLICY_FILE} (settings in {output / SETTINGS_FILE})")
    print(f"evaluate again  so101-learn eval {output} --eval 50 --videos")
