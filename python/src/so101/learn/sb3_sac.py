"""so101-learn sac: Soft Actor-Critic (Stable-Baselines3) on the dense reward of touch_cube (minus
the gripper tip's distance to the cube) or cube_to_bin (staged shaping), in-process, with the
success rate measured while it trains.

  envs         --n-envs in-process worlds (SB3 DummyVecEnv) with the learning wrappers
               (so101.learn.wrappers: flat observation, relative actions); --vec-normalize
               standardizes the observations with running statistics (SB3 VecNormalize)
  evaluation   every --eval-every steps: --eval-episodes seeded episodes (the same seeds each time,
               from --eval-seed), deterministic actions; a row of progress.csv (steps, success
               rate, its 95 % Wilson interval, mean reward) and, at the end, success.png
  checkpoints  every --checkpoint-every steps and at the end: checkpoints/step_<N>/ with model.zip,
               vecnormalize.pkl and replay_buffer.pkl (only the newest keeps its replay buffer:
               it is what resuming needs, and the largest file); model.zip (+ vecnormalize.pkl)
               of the last step also in --output
  --resume     continues from the newest checkpoint in --output (model, replay buffer, statistics,
               progress.csv up to that step) until --steps in all

Measured: docs/benchmarks.md, "Learning".

Evaluate again, with videos: so101-learn eval OUTPUT --videos.
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
import time
from pathlib import Path

import numpy as np

from .. import contract
from ..paths import repo_root
from .eval_recipe import VEC_NORMALIZE_FILE
from .wrappers import MAX_STEP, SETTINGS_FILE, EnvSettings

MODEL_FILE = "model.zip"
REPLAY_FILE = "replay_buffer.pkl"
CHECKPOINT_FILE = "checkpoint.json"  # steps and training wall time up to the checkpoint
# SAC learns from the dense reward: the tasks that have one.
DENSE_TASKS = [name for name, task in contract.TASKS.items() if "dense" in task.reward_modes]
PROGRESS_FIELDS = ["timesteps", "episodes", "successes", "success_rate", "ci95_low", "ci95_high", "mean_reward", "wall_time_s"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--task", choices=DENSE_TASKS, default="touch_cube", help="a task with a dense reward")
    p.add_argument("--steps", type=int, default=50_000, help="environment steps in all (with --resume: the total to reach)")
    p.add_argument("--n-envs", type=int, default=1, help="worlds stepped together (one gradient step per vector step)")
    p.add_argument("--vec-normalize", action="store_true", help="standardize observations with running statistics")
    p.add_argument("--output", default=None, help="directory of the run (default <checkout>/outputs/sac-<time>/)")
    p.add_argument("--resume", action="store_true", help="continue from the newest checkpoint in --output")
    p.add_argument("--checkpoint-every", type=int, default=10_000, metavar="K", help="steps between checkpoints")
    p.add_argument("--eval-every", type=int, default=5_000, help="steps between evaluations")
    p.add_argument("--eval-episodes", type=int, default=10, help="episodes of each evaluation")
    p.add_argument("--eval-seed", type=int, default=1000, help="seed of the first evaluation episode")
    p.add_argument("--seed", type=int, default=0, help="seed of SAC and of the training episodes")
    sac = p.add_argument_group("SAC")
    sac.add_argument(
        "--hidden", type=int, nargs="+", default=[256, 256], metavar="UNITS", help="hidden layers of actor and critics"
    )
    sac.add_argument("--lr", type=float, default=3e-4)
    sac.add_argument("--batch-size", type=int, default=256)
    sac.add_argument("--gamma", type=float, default=0.98, help="discount")
    sac.add_argument("--learning-starts", type=int, default=1000, help="random steps before learning")
    sac.add_argument(
        "--buffer-size",
        type=int,
        default=None,
        help="replay buffer size (default: --steps, at least 1e5, at most 1e6; a resumed run keeps its size)",
    )
    sac.add_argument("--max-step", type=float, default=MAX_STEP, help="largest joint move per control period (rad)")
    p.add_argument(
        "--torch-threads", type=int, default=1, help="torch's CPU threads (small MLPs: 1 is as fast, more stall on busy cores)"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")


# =========================================================================== checkpoints
def checkpoints(output: Path) -> list[Path]:
    """The checkpoint directories of a run, oldest first."""
    return sorted(path.parent for path in (output / "checkpoints").glob(f"step_*/{MODEL_FILE}"))


def save_checkpoint(model, output: Path, wall_time: float) -> Path:
    """checkpoints/step_<N>/ with the model, the replay buffer and the VecNormalize statistics;
    older checkpoints lose their replay buffer (resuming needs only the newest)."""
    folder = output / "checkpoints" / f"step_{model.num_timesteps:09d}"
    folder.mkdir(parents=True, exist_ok=True)
    (folder / CHECKPOINT_FILE).write_text(json.dumps({"timesteps": model.num_timesteps, "wall_time_s": wall_time}))
    model.save(folder / MODEL_FILE)
    model.save_replay_buffer(folder / REPLAY_FILE)
    if model.get_vec_normalize_env() is not None:
        model.get_vec_normalize_env().save(str(folder / VEC_NORMALIZE_FILE))
    for older in checkpoints(output):
        if older != folder:
            (older / REPLAY_FILE).unlink(missing_ok=True)
    return folder


# =========================================================================== evaluation
def evaluate_model(model, settings: EnvSettings, env, episodes: int, seed: int) -> dict:
    """The current policy over `episodes` seeded episodes (deterministic): a progress.csv row."""
    from ..evaluate.episodes import run_episodes
    from ..evaluate.stats import wilson_interval

    normalizer = model.get_vec_normalize_env()

    def act(observation: dict) -> np.ndarray:
        flat = settings.flat(observation)
        if normalizer is not None:
            flat = normalizer.normalize_obs(flat).astype(np.float32)
        return model.predict(flat, deterministic=True)[0]

    results = run_episodes(
        env,
        act,
        lambda _observation: None,
        seeds=[seed + index for index in range(episodes)],
        max_steps=settings.episode_steps,
        video_cameras=[],
        output=Path("."),
        fps=contract.CONTROL_RATE,
        quiet=True,
    )
    successes = sum(r.success for r in results)
    low, high = wilson_interval(successes, episodes)
    return {
        "timesteps": model.num_timesteps,
        "episodes": episodes,
        "successes": successes,
        "success_rate": successes / episodes,
        "ci95_low": low,
        "ci95_high": high,
        "mean_reward": float(np.mean([r.sum_reward for r in results])),
    }


def read_progress(path: Path) -> list[dict]:
    if not path.is_file():
        return []
    with path.open() as f:
        counts = ("timesteps", "episodes", "successes")
        return [{key: int(value) if key in counts else float(value) for key, value in row.items()} for row in csv.DictReader(f)]


def write_progress(path: Path, rows: list[dict]) -> None:
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, PROGRESS_FIELDS)
        writer.writeheader()
        writer.writerows({key: row[key] for key in PROGRESS_FIELDS} for row in rows)


def plot_success(rows: list[dict], path: Path, title: str) -> None:
    """success.png: success rate (%) with its 95 % interval over training steps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = [row["timesteps"] for row in rows]
    fig, ax = plt.subplots(figsize=(6, 3.5), dpi=100)
    ax.fill_between(
        steps, [100 * r["ci95_low"] for r in rows], [100 * r["ci95_high"] for r in rows], alpha=0.25, label="95 % interval"
    )
    ax.plot(steps, [100 * r["success_rate"] for r in rows], marker="o", label="success rate")
    ax.set(xlabel="environment steps", ylabel="success (%)", ylim=(-2, 102), title=title)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def callback(args, settings: EnvSettings, output: Path, rows: list[dict], begun: float):
    """SB3 callback: progress bar, evaluations into progress.csv, checkpoints."""
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm import tqdm

    class Progress(BaseCallback):
        def _on_training_start(self) -> None:
            self.bar = tqdm(total=args.steps, initial=self.num_timesteps, unit="step", desc="sac", disable=args.quiet)
            self.last = self.num_timesteps
            self.eval_env = settings.make(flat=False)

        def _crossed(self, every: int) -> bool:
            return every > 0 and self.num_timesteps // every > self.last // every

        def _on_step(self) -> bool:
            self.bar.update(self.num_timesteps - self.bar.n)
            if self.model.ep_info_buffer:
                self.bar.set_postfix(ep_reward=f"{np.mean([info['r'] for info in self.model.ep_info_buffer]):.2f}", refresh=False)
            return True

        def _on_rollout_end(self) -> None:
            # Here, not in _on_step: the step's transition is in the replay buffer by now.
            if self._crossed(args.eval_every):
                row = evaluate_model(self.model, settings, self.eval_env, args.eval_episodes, args.eval_seed)
                rows.append({**row, "wall_time_s": time.monotonic() - begun})
                write_progress(output / "progress.csv", rows)
                self.bar.write(
                    f"step {row['timesteps']}: success {100 * row['success_rate']:.0f} % "
                    f"({100 * row['ci95_low']:.0f}-{100 * row['ci95_high']:.0f} %), mean reward {row['mean_reward']:.2f}"
                )
            if self._crossed(args.checkpoint_every):
                save_checkpoint(self.model, output, time.monotonic() - begun)
            self.last = self.num_timesteps

        def _on_training_end(self) -> None:
            self.bar.close()
            self.eval_env.close()

    return Progress()


# =========================================================================== run
def make_vec_env(settings: EnvSettings, n_envs: int, seed: int):
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv

    venv = DummyVecEnv([lambda: Monitor(settings.make())] * n_envs)
    venv.seed(seed)
    return venv


def run(args) -> int:
    import torch
    from stable_baselines3 import SAC
    from stable_baselines3.common.vec_env import VecNormalize

    torch.set_num_threads(args.torch_threads)
    output = Path(args.output or repo_root() / "outputs" / f"sac-{time.strftime('%Y%m%d-%H%M%S')}")
    if args.resume:
        found = checkpoints(output)
        if not found or not (output / SETTINGS_FILE).is_file():
            raise SystemExit(f"so101-learn sac: --resume: no checkpoint in {output}/checkpoints")
        record = json.loads((output / SETTINGS_FILE).read_text())
        settings = EnvSettings.from_dict(record["env"])
        if settings.task != args.task:
            print(f"so101-learn sac: resuming the run's task {settings.task} (not --task {args.task})")
        checkpoint = found[-1]
        venv = make_vec_env(settings, args.n_envs, args.seed)
        if record.get("vec_normalize"):
            venv = VecNormalize.load(str(checkpoint / VEC_NORMALIZE_FILE), venv)
        model = SAC.load(checkpoint / MODEL_FILE, env=venv, device="cpu")
        model.load_replay_buffer(checkpoint / REPLAY_FILE)
        # Fresh training episodes, not the ones the first run began with; the zip holds the last
        # observation of the first run's envs, which these new ones never produced: reset them.
        venv.seed(args.seed + model.num_timesteps)
        model._last_obs = None
        rows = [row for row in read_progress(output / "progress.csv") if row["timesteps"] <= model.num_timesteps]
        earlier = json.loads((checkpoint / CHECKPOINT_FILE).read_text())["wall_time_s"]
        print(f"resuming {checkpoint} at step {model.num_timesteps}")
    else:
        if checkpoints(output):
            raise SystemExit(f"so101-learn sac: {output} holds a run already (--resume continues it)")
        output.mkdir(parents=True, exist_ok=True)
        settings = EnvSettings(task=args.task, max_step=args.max_step, dense_reward=True)
        venv = make_vec_env(settings, args.n_envs, args.seed)
        if args.vec_normalize:
            # Observations only: the dense rewards are already of order one.
            venv = VecNormalize(venv, norm_obs=True, norm_reward=False)
        model = new_model(args, venv)
        record = {
            "algorithm": "sac",
            "model": MODEL_FILE,
            "vec_normalize": bool(args.vec_normalize),
            "env": settings.to_dict(),
            "training": {
                key: getattr(args, key)
                for key in ("steps", "n_envs", "hidden", "lr", "batch_size", "gamma", "learning_starts", "seed")
            },
        }
        (output / SETTINGS_FILE).write_text(json.dumps(record, indent=2))
        rows = []
        earlier = 0.0

    return train_and_report(args, model, settings, venv, output, record, rows, earlier)


def new_model(args, venv, learning_starts: int | None = None, buffer_size: int | None = None, ent_coef="auto"):
    """A fresh SAC with the recipe's settings (args: the sac recipe's SAC options, steps, seed);
    the keywords override the recipe's where given."""
    from stable_baselines3 import SAC

    return SAC(
        "MlpPolicy",
        venv,
        learning_rate=args.lr,
        buffer_size=buffer_size or args.buffer_size or min(max(args.steps, 100_000), 1_000_000),
        learning_starts=args.learning_starts if learning_starts is None else learning_starts,
        ent_coef=ent_coef,
        batch_size=args.batch_size,
        gamma=args.gamma,
        policy_kwargs={"net_arch": list(args.hidden)},
        seed=args.seed,
        device="cpu",
    )


def train_and_report(
    args, model, settings: EnvSettings, venv, output: Path, record: dict, rows: list[dict], earlier: float
) -> int:
    """SAC's online training up to args.steps with evaluations and checkpoints, then the last
    checkpoint, progress.csv, success.png and a summary."""
    start_steps = model.num_timesteps
    # Wall times in progress.csv and the checkpoints count the training of every run of this output.
    started = time.monotonic()
    begun = started - earlier
    if model.num_timesteps < args.steps:
        model.learn(
            total_timesteps=args.steps - model.num_timesteps,
            callback=callback(args, settings, output, rows, begun),
            reset_num_timesteps=False,
        )
    wall, total = time.monotonic() - started, time.monotonic() - begun
    checkpoint = output / "checkpoints" / f"step_{model.num_timesteps:09d}"
    if not (checkpoint / REPLAY_FILE).is_file():  # the callback's last checkpoint may be this step's
        checkpoint = save_checkpoint(model, output, time.monotonic() - begun)
    shutil.copy2(checkpoint / MODEL_FILE, output / MODEL_FILE)
    if record.get("vec_normalize"):
        shutil.copy2(checkpoint / VEC_NORMALIZE_FILE, output / VEC_NORMALIZE_FILE)
    if not rows or rows[-1]["timesteps"] != model.num_timesteps:
        env = settings.make(flat=False)
        rows.append(
            {**evaluate_model(model, settings, env, args.eval_episodes, args.eval_seed), "wall_time_s": time.monotonic() - begun}
        )
        env.close()
    write_progress(output / "progress.csv", rows)
    plot_success(rows, output / "success.png", f"SAC on {settings.task} (dense reward)")
    venv.close()

    final = rows[-1]
    done = model.num_timesteps - start_steps
    print("\n=== so101-learn sac ===")
    print(f"steps        {model.num_timesteps} ({done} in this run, {args.n_envs} env(s))")
    print(f"wall time    {wall:.0f} s training, {done / max(wall, 1e-9):.0f} steps/s (all runs of this output: {total:.0f} s)")
    print(
        f"success      {100 * final['success_rate']:.0f} % over {int(final['episodes'])} episodes "
        f"(95 % interval {100 * final['ci95_low']:.0f}-{100 * final['ci95_high']:.0f} %), mean reward {final['mean_reward']:.2f}"
    )
    print(f"model        {output / MODEL_FILE} (settings in {output / SETTINGS_FILE})")
    print(f"checkpoint   {checkpoint}")
    print(f"progress     {output / 'progress.csv'}, {output / 'success.png'}")
    print(f"evaluate     so101-learn eval {output} --eval 50 --videos")
    return 0
