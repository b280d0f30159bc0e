"""Seeded evaluation episodes on a Gymnasium env of the stack (so101.envs, either backend) and
their report, whatever the policy: success rate with its 95 % interval (so101.evaluate.stats), mean and
best reward, an MP4 per episode and eval_info.json. so101-run-policy --eval (LeRobot policies) and
so101-learn's evaluations of Stable-Baselines3 / imitation policies (so101.learn.eval_recipe,
so101.learn.sb3_sac) all run their episodes here, so their reports read the same.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .stats import wilson_interval


@dataclass
class EpisodeResult:
    seed: int
    success: bool
    sum_reward: float
    max_reward: float
    steps: int
    video: str | None
    # What the sim simulated the episode with (its servo model and randomization draw), if known.
    settings: dict | None = None


# A video frame is at least this tall: a policy's 72-pixel camera is a smudge on a screen.
WATCHABLE_HEIGHT = 360


def watchable(frame: np.ndarray, height: int = WATCHABLE_HEIGHT) -> np.ndarray:
    """`frame` enlarged by the smallest whole factor that makes it at least `height` tall, each
    pixel repeated (no interpolation: the video shows exactly what the policy saw)."""
    factor = -(-height // frame.shape[0])
    return frame if factor <= 1 else np.repeat(np.repeat(frame, factor, axis=0), factor, axis=1)


def tile(frames: dict[str, np.ndarray]) -> np.ndarray:
    """Frames side by side, each made watchable, then padded at the bottom to the tallest."""
    frames = {name: watchable(frame) for name, frame in frames.items()}
    height = max(frame.shape[0] for frame in frames.values())
    return np.concatenate([np.pad(f, ((0, height - f.shape[0]), (0, 0), (0, 0))) for f in frames.values()], axis=1)


def run_episodes(
    env,
    act: Callable[[dict], np.ndarray],
    reset: Callable[[dict], None],
    seeds: list[int],
    max_steps: int,
    video_cameras: list[str],
    output: Path,
    fps: float,
    quiet: bool = False,
    first_index: int = 0,
) -> list[EpisodeResult]:
    """One episode per seed: `reset(first observation)`, then `act(observation)` each step until
        the env terminates or `max_steps`. Success is info["is_success"] at any step. The frames of
        `video_cameras` (observation["pixels"]) go into output/videos/ as one MP4 per episode, numbered
    from `first_index`."""
    from lerobot.utils.io_utils import write_video
    from tqdm import tqdm

    if video_cameras:
        (output / "videos").mkdir(parents=True, exist_ok=True)
    results: list[EpisodeResult] = []
    for index, seed in enumerate(tqdm(seeds, desc="episodes", unit="ep", disable=quiet), start=first_index):
        observation, reset_info = env.reset(seed=seed)
        reset(observation)
        settings = reset_info.get("episode_settings")
        if settings is not None:
            settings = {"servo_model": settings.get("servo_model"), "draw": settings.get("draw")}
        rewards: list[float] = []
        video: list[np.ndarray] = []
        success = False
        for _ in range(max_steps):
            if video_cameras:
                video.append(tile({name: observation["pixels"][name] for name in video_cameras}))
            observation, reward, terminated, _, info = env.step(act(observation))
            rewards.append(float(reward))
            success = success or bool(info["is_success"])
            if terminated:
                break
        path = None
        if video:
            path = output / "videos" / f"episode_{index:03d}_seed{seed}.mp4"
            write_video(path, video, fps=int(round(fps)))
        results.append(
            EpisodeResult(
                seed,
                success,
                float(np.sum(rewards)),
                float(np.max(rewards)),
                len(rewards),
                str(path) if path else None,
                settings,
            )
        )
    return results


def summarize(results: list[EpisodeResult], **meta) -> dict:
    """The aggregate LeRobot's eval_info.json has (pc_success, avg_sum_reward, ...) plus the
    success rate's 95 % Wilson interval, with `meta` (policy, backend, ...) alongside."""
    successes = sum(r.success for r in results)
    sums = [r.sum_reward for r in results]
    return {
        **meta,
        "episodes": len(results),
        "successes": successes,
        "pc_success": 100.0 * successes / len(results),
        "pc_success_ci95": [100.0 * bound for bound in wilson_interval(successes, len(results))],
        "avg_sum_reward": float(np.mean(sums)),
        "best_sum_reward": float(np.max(sums)),
        "avg_max_reward": float(np.mean([r.max_reward for r in results])),
    }


def write_report(output: Path, summary: dict, results: list[EpisodeResult], quiet: bool = False) -> None:
    """output/eval_info.json, and the per-episode lines and the summary on stdout."""
    output.mkdir(parents=True, exist_ok=True)
    (output / "eval_info.json").write_text(
        json.dumps({"aggregated": summary, "per_episode": [asdict(r) for r in results]}, indent=2)
    )
    if not quiet:
        for r in results:
            print(
                f"seed {r.seed:>4}: {'success' if r.success else 'failure'} after {r.steps} steps, "
                f"reward sum {r.sum_reward:.2f} (max {r.max_reward:.2f})"
            )
    print(summary_line(summary) + f"; videos and eval_info.json in {output}")


def summary_line(summary: dict) -> str:
    low, high = summary["pc_success_ci95"]
    return (
        f"{summary['episodes']} episode(s): success {summary['pc_success']:.0f} % "
        f"(95 % interval {low:.0f}-{high:.0f} %), mean reward {summary['avg_sum_reward']:.2f}, "
        f"best {summary['best_sum_reward']:.2f}"
    )
