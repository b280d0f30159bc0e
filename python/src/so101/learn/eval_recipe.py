"""so101-learn eval POLICY: evaluate a policy over M seeded episodes: success rate with its 95 %
interval, mean and best reward, eval_info.json (and MP4s) in --output. The recipes evaluate
through it too: bc its saved policy (evaluate_saved), act and diffusion theirs through
so101-run-policy (run_policy_command). The episodes and the report are so101.evaluate.episodes'.

Which way depends on POLICY:
  - a policy of `so101-learn bc` or `sac` (its output directory, which holds so101_learn.json, a
    checkpoint directory, or the model file itself: policy.pth, model.zip): loaded with
    Stable-Baselines3 and evaluated in-process (so101.envs) with the wrappers it was trained
    with (flat observation, relative actions, VecNormalize statistics if it used them),
    deterministic actions; --videos films the front camera (320x240).
  - anything else (a LeRobot pretrained_model directory, a Hugging Face Hub id): handed to
    `so101-run-policy POLICY --eval M`, the stack's real interface (so101_sim_node in lockstep
    over ROS with --backend ros, the default), inside scripts/isolated when not already in a
    private network namespace.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from .. import contract
from ..envs.spaces import reward_mode
from .wrappers import SETTINGS_FILE, EnvSettings

VEC_NORMALIZE_FILE = "vecnormalize.pkl"
VIDEO_CAMERA = ("front", (240, 320))


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("policy", help="so101-learn bc/sac output (directory or model file), or a LeRobot policy")
    p.add_argument("--eval", type=int, default=50, metavar="M", help="episodes")
    p.add_argument("--seed", type=int, default=1000, help="seed of the first episode (then seed+1, ...)")
    p.add_argument(
        "--output", default=None, help="directory for eval_info.json and videos/ (default <checkout>/eval/<policy>-<time>)"
    )
    p.add_argument(
        "--sim-task", choices=list(contract.TASKS), default=None, help="the task (default: the policy's; LeRobot: cube_to_bin)"
    )
    p.add_argument(
        "--episode-time", type=float, default=None, help="sim seconds before an episode counts as failed (default: the task's)"
    )
    p.add_argument("--lite", action="store_true", help="sim without meshes (faster to render on a CPU)")
    p.add_argument(
        "--videos",
        action="store_true",
        help="an MP4 per episode (bc/sac: the front camera; LeRobot: the policy's cameras, else the front)",
    )
    p.add_argument("--backend", choices=["ros", "inprocess"], default="ros", help="LeRobot policies: so101-run-policy's backend")
    p.add_argument("--torch-threads", type=int, default=1, help="torch's CPU threads (bc/sac)")
    p.add_argument("--quiet", action="store_true", help="no progress bar, no per-episode lines")


def find_saved(policy: str) -> tuple[dict, Path] | None:
    """(so101_learn.json's record, the model file) when `policy` is a bc/sac policy, else None."""
    path = Path(policy)
    if path.is_dir() and (path / SETTINGS_FILE).is_file():
        record = json.loads((path / SETTINGS_FILE).read_text())
        return record, path / record["model"]
    if path.is_dir() and (path / "model.zip").is_file():  # a checkpoint directory
        path = path / "model.zip"
    if path.is_file() and path.suffix in (".zip", ".pth"):
        # The settings live in the run's output directory: beside the file or above its checkpoint.
        for folder in list(path.parents)[:3]:
            if (folder / SETTINGS_FILE).is_file():
                return json.loads((folder / SETTINGS_FILE).read_text()), path
    return None


def load_policy(record: dict, model: Path, settings: EnvSettings):
    """observation dict -> action in [-1, 1]^6 (deterministic) of a saved bc or sac policy."""
    if record["algorithm"] == "bc":
        from stable_baselines3.common.policies import ActorCriticPolicy

        predictor = ActorCriticPolicy.load(str(model), device="cpu")
    elif record["algorithm"] == "sac":
        from stable_baselines3 import SAC

        predictor = SAC.load(str(model), device="cpu")
    else:
        raise SystemExit(f"so101-learn eval: unknown algorithm {record['algorithm']!r} in {SETTINGS_FILE}")
    normalize = None
    if record.get("vec_normalize"):
        from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

        statistics = VecNormalize.load(str(model.parent / VEC_NORMALIZE_FILE), DummyVecEnv([settings.make]))
        statistics.training = False
        normalize = statistics.normalize_obs

    def act(observation: dict) -> np.ndarray:
        flat = settings.flat(observation)
        if normalize is not None:
            flat = normalize(flat).astype(np.float32)
        action, _ = predictor.predict(flat, deterministic=True)
        return action

    return act


def evaluate_saved(
    policy,
    episodes: int,
    seed: int,
    output: Path,
    videos: bool = False,
    lite: bool = True,
    task: str | None = None,
    episode_time: float | None = None,
    quiet: bool = False,
) -> dict:
    """Evaluates a bc/sac policy in-process; writes output/eval_info.json, returns the summary."""
    from ..evaluate.episodes import run_episodes, summarize, write_report

    found = find_saved(str(policy))
    if found is None:
        raise SystemExit(f"so101-learn eval: {policy} is no so101-learn bc/sac policy (no {SETTINGS_FILE})")
    record, model = found
    settings = EnvSettings.from_dict(record["env"])
    if task and task != settings.task:
        settings = dataclasses.replace(settings, task=task, episode_steps=None)
    act = load_policy(record, model, settings)
    max_steps = int(round(episode_time * contract.CONTROL_RATE)) if episode_time else settings.episode_steps
    env = settings.make(flat=False, cameras=dict([VIDEO_CAMERA]) if videos else None, lite=lite)
    try:
        results = run_episodes(
            env,
            act,
            lambda _observation: None,
            seeds=[seed + index for index in range(episodes)],
            max_steps=max_steps,
            video_cameras=[VIDEO_CAMERA[0]] if videos else [],
            output=Path(output),
            fps=contract.CONTROL_RATE,
            quiet=quiet,
        )
    finally:
        env.close()
    summary = summarize(
        results,
        policy=str(model),
        algorithm=record["algorithm"],
        task=settings.task,
        reward=reward_mode(settings.task, settings.dense_reward),
        backend="inprocess",
        fps=contract.CONTROL_RATE,
        episode_time_s=max_steps / contract.CONTROL_RATE,
    )
    write_report(Path(output), summary, results, quiet=quiet)
    return summary


def run_policy_command(
    policy: str,
    *,
    episodes: int,
    seed: int,
    output: str,
    backend: str,
    videos: int | None = None,
    sim_task: str | None = None,
    episode_time: float | None = None,
    lite: bool = False,
    device: str | None = None,
    quiet: bool = False,
) -> list[str]:
    """so101-run-policy's evaluation of a LeRobot policy (every recipe evaluates through it), inside
    scripts/isolated when this process is not in a private network namespace already. `videos`:
    how many episodes are filmed (None: so101-run-policy's default, every one)."""
    from ..stack.isolation import isolated_command

    command = [sys.executable, "-m", "so101.evaluate.run_policy", policy, f"--eval={episodes}", f"--seed={seed}"]
    command += [f"--output={output}", f"--backend={backend}", f"--sim-task={sim_task or 'cube_to_bin'}"]
    if episode_time:
        command.append(f"--episode-time={episode_time}")
    if lite:
        command.append("--lite")
    if device:
        command.append(f"--device={device}")
    if videos is not None:
        command.append(f"--videos={videos}")
    if quiet:
        command.append("--quiet")
    return isolated_command(command)


def lerobot_eval_command(args, output: str) -> list[str]:
    """`so101-learn eval` of a LeRobot policy: so101-run-policy with this command's options."""
    return run_policy_command(
        args.policy,
        episodes=args.eval,
        seed=args.seed,
        output=output,
        backend=args.backend,
        videos=None if args.videos else 0,
        sim_task=args.sim_task,
        episode_time=args.episode_time,
        lite=args.lite,
        quiet=args.quiet,
    )


def run(args) -> int:
    from ..paths import repo_root

    if args.eval <= 0:
        raise SystemExit("so101-learn eval: --eval must be positive")
    name = Path(args.policy.rstrip("/")).name or "policy"
    output = args.output or str(repo_root() / "eval" / f"{name}-{time.strftime('%Y%m%d-%H%M%S')}")
    if find_saved(args.policy) is None:
        command = lerobot_eval_command(args, output)
        print("so101-learn eval: " + " ".join(command), flush=True)
        return subprocess.run(command).returncode
    import torch

    torch.set_num_threads(args.torch_threads)
    evaluate_saved(
        args.policy,
        args.eval,
        args.seed,
        Path(output),
        videos=args.videos,
        lite=args.lite or not args.videos,  # meshes only matter to the pictures
        task=args.sim_task,
        episode_time=args.episode_time,
        quiet=args.quiet,
    )
    return 0
