"""so101-learn bc --continue-with-sac STEPS: behaviour cloning first, then SAC continuing from it on
the dense reward, the expert's demonstrations in its replay buffer.

SAC alone never put the cube in the bin (0 % at every evaluation over 20,000 steps: the staged
reward's later stages, grasping and carrying, are too far for random exploration to find). Started
from what behaviour cloning learnt, it has a policy that succeeds from its first step and is left
to improve it. The parts, in order, and why each:

1. actor: SAC's actor (a tanh-squashed Gaussian, unlike bc's policy) is cloned on the same
   transitions as `bc` (same observation, same standardization): the squared error of its
   deterministic action, plus NLL_WEIGHT times the likelihood loss of the expert's actions
   (clipped to +-CLONE_CLIP where atanh is finite) so that its spread is fitted too. Likelihood
   alone let the mean go slack where the learnt spread is wide: its clone succeeded in 1 of 20
   episodes, the squared error's in 20 of 20 (seeds 2000-2019);
2. replay buffer: the demonstrations, with their dense rewards, go in first and stay (the buffer
   is larger than the run): SAC keeps seeing what success looks like;
3. critics: warmed up on the demonstrations with the actor frozen (--critic-warmup gradient
   steps). A fresh critic's gradient points anywhere, and the actor follows it from the first
   update; the cloned policy would be lost before the critic has learnt anything;
4. SAC online from there, the cloning loss on a batch of demonstrations added to every actor
   update (BC_WEIGHT times it, as TD3+BC does): without it the first 2,500 steps took the clone
   from 20 of 20 episodes to 0 of 20, the critic's values of actions the demonstrations never
   took being guesses that the actor climbs; the entropy coefficient starts at ENT_COEF_START (SB3's 1.0
   rewards randomness so much that the first updates widen the cloned policy into a random one),
   still tuned automatically by SB3.

Its output (<bc output>/sac/) is a `so101-learn sac` run: progress.csv (with the cloned actor's
success at step 0), success.png, model.zip, checkpoints; `so101-learn eval` evaluates it.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from . import sb3_sac
from .wrappers import SETTINGS_FILE, EnvSettings

CLONE_CLIP = 0.99
NLL_WEIGHT = 0.01
BC_WEIGHT = 10.0
ENT_COEF_START = 0.01
CLONE_BATCH = 256
CLONE_LR = 1e-3


def add_arguments(p: argparse.ArgumentParser) -> None:
    """bc's options for the SAC that continues from it."""
    sac = p.add_argument_group("SAC continuing from the clone (--continue-with-sac)")
    sac.add_argument(
        "--continue-with-sac", type=int, default=0, metavar="STEPS", help="then SAC for STEPS environment steps (0: none)"
    )
    sac.add_argument("--critic-warmup", type=int, default=2000, metavar="K", help="critic-only gradient steps on the demos")
    sac.add_argument("--sac-n-envs", type=int, default=1, help="worlds stepped together")
    sac.add_argument("--sac-eval-every", type=int, default=2500, help="steps between evaluations")
    sac.add_argument("--sac-eval-episodes", type=int, default=20, help="episodes of each evaluation")


def sac_arguments(args) -> argparse.Namespace:
    """The sac recipe's defaults, with bc's run settings and --sac-* options in place."""
    parser = argparse.ArgumentParser()
    sb3_sac.add_arguments(parser)
    sac = parser.parse_args([])
    sac.steps = args.continue_with_sac
    sac.n_envs = args.sac_n_envs
    sac.eval_every = args.sac_eval_every
    sac.eval_episodes = args.sac_eval_episodes
    sac.eval_seed = args.eval_seed
    sac.checkpoint_every = max(args.continue_with_sac, 1)
    sac.seed = args.seed
    sac.quiet = args.quiet
    sac.hidden = list(args.hidden)
    return sac


def clone_actor(model, transitions, epochs: int, seed: int) -> float:
    """Trains SAC's actor on the demonstrations (step 1 of the module's docstring); returns the last
    epoch's mean loss."""
    import torch

    generator = torch.Generator().manual_seed(seed)
    observations = torch.as_tensor(np.array(transitions.obs))
    actions = torch.as_tensor(np.array(transitions.acts))
    clipped = actions.clamp(-CLONE_CLIP, CLONE_CLIP)
    actor = model.actor
    optimizer = torch.optim.Adam(actor.parameters(), lr=CLONE_LR)
    actor.set_training_mode(True)
    loss_sum = 0.0
    for _ in range(epochs):
        order = torch.randperm(len(observations), generator=generator)
        loss_sum, batches = 0.0, 0
        for start in range(0, len(order), CLONE_BATCH):
            index = order[start : start + CLONE_BATCH]
            mean, log_std, _ = actor.get_action_dist_params(observations[index])
            distribution = actor.action_dist.proba_distribution(mean, log_std)
            loss = squared_error(mean, actions[index]) - NLL_WEIGHT * distribution.log_prob(clipped[index]).mean()
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            loss_sum, batches = loss_sum + float(loss), batches + 1
        loss_sum /= batches
    actor.set_training_mode(False)
    return loss_sum


def squared_error(mean, actions):
    """Squared error of the deterministic actions tanh(mean) against the demonstrations'."""
    import torch

    return ((torch.tanh(mean) - actions) ** 2).sum(dim=1).mean()


def cloning_loss(actor, observations, actions):
    """The actor's squared error (squared_error) on these demonstrations."""
    mean, _, _ = actor.get_action_dist_params(observations)
    return squared_error(mean, actions)


def keep_cloning(model, transitions, weight: float, seed: int) -> None:
    """From now on each of SAC's actor updates also descends weight x the cloning loss on a
    random batch of demonstrations: the actor's optimizer adds that gradient before its step."""
    import torch

    observations = torch.as_tensor(np.array(transitions.obs))
    actions = torch.as_tensor(np.array(transitions.acts))
    generator = torch.Generator().manual_seed(seed)
    actor, batch = model.actor, model.batch_size

    class CloningAdam(torch.optim.Adam):
        def step(self, closure=None):
            index = torch.randint(len(observations), (batch,), generator=generator)
            (weight * cloning_loss(actor, observations[index], actions[index])).backward()
            return super().step(closure)

    optimizer = CloningAdam(actor.parameters(), lr=actor.optimizer.param_groups[0]["lr"])
    optimizer.load_state_dict(actor.optimizer.state_dict())
    actor.optimizer = optimizer


def fill_replay_buffer(model, transitions) -> int:
    """The demonstrations as the first transitions of SAC's replay buffer, n_envs at a time as the
    buffer stores them (the last len % n_envs are left out); returns how many went in."""
    buffer, worlds = model.replay_buffer, model.n_envs
    count = len(transitions.obs) - len(transitions.obs) % worlds
    for start in range(0, count, worlds):
        rows = slice(start, start + worlds)
        buffer.add(
            transitions.obs[rows],
            transitions.next_obs[rows],
            transitions.acts[rows],
            transitions.rews[rows],
            transitions.dones[rows],
            [{}] * worlds,
        )
    return count


def warm_up_critic(model, gradient_steps: int) -> None:
    """SAC's own update with the actor's parameters frozen: only the critics (and the entropy
    coefficient) learn, the values of the cloned policy on the demonstrations."""
    from stable_baselines3.common.logger import configure

    model.set_logger(configure(None, []))
    parameters = list(model.actor.parameters())
    for parameter in parameters:
        parameter.requires_grad_(False)
    try:
        model.train(gradient_steps=gradient_steps, batch_size=model.batch_size)
    finally:
        for parameter in parameters:
            parameter.requires_grad_(True)


def throughput(model, venv, steps: int = 500, gradient_steps: int = 200) -> dict:
    """Environment steps/s (random actions, all worlds counted) and gradient steps/s, each alone.
    The model's parameters, optimizers and entropy coefficient are put back afterwards."""
    import copy

    import torch

    venv.reset()
    started = time.perf_counter()
    for _ in range(steps // venv.num_envs):
        venv.step(np.stack([venv.action_space.sample() for _ in range(venv.num_envs)]))
    env_rate = (steps // venv.num_envs) * venv.num_envs / (time.perf_counter() - started)
    saved = copy.deepcopy(model.get_parameters())
    log_ent_coef = model.log_ent_coef.detach().clone()
    started = time.perf_counter()
    model.train(gradient_steps=gradient_steps, batch_size=model.batch_size)
    gradient_rate = gradient_steps / (time.perf_counter() - started)
    model.set_parameters(saved, exact_match=True)
    with torch.no_grad():
        model.log_ent_coef.copy_(log_ent_coef)
    return {"env_steps_per_s": env_rate, "gradient_steps_per_s": gradient_rate}


def continue_with_sac(args, settings: EnvSettings, transitions, bc_output: Path) -> int:
    """Steps 1-4 of the module's docstring; the run goes to bc_output/sac/."""
    sac_args = sac_arguments(args)
    sac_settings = dataclasses.replace(settings, dense_reward=True)
    output = bc_output / "sac"
    if sb3_sac.checkpoints(output):
        raise SystemExit(f"so101-learn bc: {output} holds a SAC run already")
    output.mkdir(parents=True, exist_ok=True)
    venv = sb3_sac.make_vec_env(sac_settings, sac_args.n_envs, sac_args.seed)
    model = sb3_sac.new_model(
        sac_args,
        venv,
        learning_starts=0,
        buffer_size=max(sac_args.buffer_size or 0, len(transitions.obs) + sac_args.steps),
        ent_coef=f"auto_{ENT_COEF_START}",
    )
    begun = time.monotonic()
    clone_loss = clone_actor(model, transitions, args.epochs, args.seed)
    buffered = fill_replay_buffer(model, transitions)
    warm_up_critic(model, args.critic_warmup)
    keep_cloning(model, transitions, BC_WEIGHT, args.seed)
    prepared_s = time.monotonic() - begun
    print(
        f"sac: actor cloned (loss {clone_loss:.3f}), {buffered} demonstration transitions in the replay buffer, critics warmed up {args.critic_warmup} steps: {prepared_s:.0f} s"
    )
    speed = throughput(model, venv)
    print(f"sac: {speed['env_steps_per_s']:.0f} env steps/s, {speed['gradient_steps_per_s']:.0f} gradient steps/s (each alone)")

    eval_env = sac_settings.make(flat=False)
    rows = [
        {**sb3_sac.evaluate_model(model, sac_settings, eval_env, sac_args.eval_episodes, sac_args.eval_seed), "wall_time_s": 0.0}
    ]
    eval_env.close()
    record = {
        "algorithm": "sac",
        "model": sb3_sac.MODEL_FILE,
        "vec_normalize": False,
        "env": sac_settings.to_dict(),
        "started_from": "bc",
        "training": {
            **{key: getattr(sac_args, key) for key in ("steps", "n_envs", "hidden", "lr", "batch_size", "gamma", "seed")},
            "demonstration_transitions": buffered,
            "clone_epochs": args.epochs,
            "clone_loss": clone_loss,
            "critic_warmup": args.critic_warmup,
            "ent_coef_start": ENT_COEF_START,
            "bc_weight": BC_WEIGHT,
            "preparation_s": prepared_s,
            **speed,
        },
    }
    (output / SETTINGS_FILE).write_text(json.dumps(record, indent=2))
    return sb3_sac.train_and_report(sac_args, model, sac_settings, venv, output, record, rows, prepared_s)
