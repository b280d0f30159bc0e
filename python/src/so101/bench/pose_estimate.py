#!/usr/bin/env python3
"""pose_act's cube-pose estimator in closed loop: its estimate against the sim's own cube pose at
every control period while the policy acts (in-process), binned by how far the gripper is from the
cube. The anchor, in the same run: the same estimator on the frames of recorded demonstrations
(--dataset; pass demonstrations the policy was not trained on), binned alike, as a ratio.

Why: on demonstration frames an estimator can be millimetres off and still centimetres off while
its own policy acts, where the gripper stands where no demonstration put it. The ratio says how
much of the error is that shift (docs/benchmarks.md, "The cube's pose estimated beside ACT").

No DDS. Prints a Markdown report; --json writes the numbers.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..subcommands import Subcommand, run_alone

# Gripper-to-cube distance bins (m): at the grasp, approaching, on the way, far.
DISTANCE_BINS = (0.02, 0.05, 0.10)


@dataclass
class EstimateLog:
    """Per frame: the estimator's position error (m) and the gripper's distance to the cube (m)."""

    errors: list[float] = field(default_factory=list)
    distances: list[float] = field(default_factory=list)

    def add(self, estimate: np.ndarray, cube: np.ndarray, gripper: np.ndarray) -> None:
        self.errors.append(float(np.linalg.norm(estimate[:3] - cube[:3])))
        self.distances.append(float(np.linalg.norm(gripper - cube[:3])))


def gripper_in_world(joints: np.ndarray) -> np.ndarray:
    """The grasp point (m, the sim's world frame) of joint positions (rad)."""
    import so101_native

    from ..ee import ee_poses

    return ee_poses(joints)[:3] + np.asarray(so101_native.SIM_BASE_IN_WORLD)


def bin_labels() -> list[str]:
    edges = [f"{100 * edge:g}" for edge in DISTANCE_BINS]
    return [f"< {edges[0]} cm"] + [f"{a}-{b} cm" for a, b in zip(edges, edges[1:])] + [f"> {edges[-1]} cm"]


def binned(log: EstimateLog) -> list[dict]:
    """Per distance bin (bin_labels' order, then all frames): frames, mean and median error (mm)."""
    errors, distances = np.asarray(log.errors), np.asarray(log.distances)
    which = np.digitize(distances, DISTANCE_BINS)
    rows = []
    for index in range(len(DISTANCE_BINS) + 2):
        chosen = errors if index == len(DISTANCE_BINS) + 1 else errors[which == index]
        rows.append(
            {
                "frames": int(chosen.size),
                "mean_mm": float(1000 * chosen.mean()) if chosen.size else None,
                "median_mm": float(1000 * np.median(chosen)) if chosen.size else None,
            }
        )
    return rows


class RecordingPolicy:
    """so101.evaluate.StackPolicy of a pose_act checkpoint, keeping the estimator's last pose
    (m, quaternion; the world frame) of each call."""

    def __init__(self, checkpoint: str):
        from ..evaluate.policy import PolicyError, StackPolicy

        self.stack = StackPolicy(checkpoint)
        model = self.stack.policy
        if getattr(model, "name", None) != "pose_act":
            raise PolicyError(f"{checkpoint} is a {self.stack.config.type} policy: this benchmark reads pose_act's estimator")
        self.last: np.ndarray | None = None
        estimated_pose = model.estimated_pose

        def recorded(batch):
            pose = estimated_pose(batch)
            self.last = pose[0].detach().cpu().double().numpy()
            return pose

        model.estimated_pose = recorded

    def act(self, joints: np.ndarray, images: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """The joint targets and the pose the estimator saw in this observation."""
        self.last = None
        action = self.stack.act(self.stack.observation(joints, images))
        if self.last is None:
            raise RuntimeError("the policy acted without estimating the cube's pose")
        return action, self.last


def closed_loop(policy: RecordingPolicy, args) -> tuple[EstimateLog, int]:
    """The policy's own episodes: (the estimates' log, successes)."""
    from .. import contract
    from ..envs import make_env

    cameras = {camera.name: (camera.height, camera.width) for camera in policy.stack.cameras}
    env = make_env("cube_to_bin", backend="inprocess", lite=True, cameras=cameras, randomize=args.randomize)
    log, successes = EstimateLog(), 0
    steps = contract.TASKS["cube_to_bin"].episode_steps
    try:
        for episode in range(args.episodes):
            observation, _ = env.reset(seed=args.seed + episode)
            policy.stack.reset()
            success = False
            for _ in range(steps):
                joints = np.asarray(observation["agent_pos"], dtype=np.float64)
                action, estimate = policy.act(joints, observation["pixels"])
                log.add(estimate, np.asarray(observation["environment_state"]), gripper_in_world(joints))
                observation, _, terminated, _, info = env.step(action)
                success = success or bool(info["is_success"])
                if terminated:
                    break
            successes += int(success)
    finally:
        env.close()
    return log, successes


def on_demonstrations(policy: RecordingPolicy, dataset: Path, episodes: int) -> EstimateLog:
    """The estimator on the first `episodes` episodes' frames of a recorded dataset."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from ..evaluate.policy import ENVIRONMENT_STATE, IMAGE_PREFIX, STATE
    from ..units import radians_from_lerobot

    chosen = LeRobotDataset("local/pose_estimate_anchor", root=dataset, episodes=list(range(episodes)))
    if ENVIRONMENT_STATE not in chosen.meta.features:
        raise SystemExit(f"{dataset} has no {ENVIRONMENT_STATE}: record its demos without --no-environment-state")
    log, episode = EstimateLog(), None
    for index in range(len(chosen)):
        frame = chosen[index]
        if int(frame["episode_index"]) != episode:
            episode = int(frame["episode_index"])
            policy.stack.reset()
        joints = radians_from_lerobot(frame[STATE].double().numpy())
        images = {
            camera.name: (255 * frame[IMAGE_PREFIX + camera.name].permute(1, 2, 0).numpy()).round().astype(np.uint8)
            for camera in policy.stack.cameras
        }
        _, estimate = policy.act(joints, images)
        log.add(estimate, frame[ENVIRONMENT_STATE].double().numpy(), gripper_in_world(joints))
    return log


def run(args: argparse.Namespace) -> int:
    import torch

    torch.set_num_threads(args.threads)
    policy = RecordingPolicy(str(args.checkpoint))
    loop, successes = closed_loop(policy, args)
    anchor = on_demonstrations(policy, args.dataset, args.anchor_episodes)
    loop_rows, anchor_rows = binned(loop), binned(anchor)
    labels = bin_labels() + ["all frames"]
    print(
        f"## pose_act's estimator: {args.episodes} closed-loop episodes (seeds {args.seed}-{args.seed + args.episodes - 1}, "
        f"randomize {args.randomize}, {successes} successful) against {args.anchor_episodes} demonstrations of {args.dataset}\n"
    )
    print(
        "| gripper to cube | closed loop: frames, mean / median error | demonstrations: frames, mean / median error | median ratio |"
    )
    print("|---|---|---|---|")

    def cell(row: dict) -> str:
        return f"{row['frames']}, {row['mean_mm']:.1f} / {row['median_mm']:.1f} mm" if row["frames"] else "0"

    for label, ours, theirs in zip(labels, loop_rows, anchor_rows, strict=True):
        ratio = f"{ours['median_mm'] / theirs['median_mm']:.2f}" if ours["frames"] and theirs["frames"] else "n/a"
        print(f"| {label} | {cell(ours)} | {cell(theirs)} | {ratio} |")
    if args.json:
        numbers = {
            "checkpoint": str(args.checkpoint),
            "episodes": args.episodes,
            "seed": args.seed,
            "randomize": args.randomize,
            "successes": successes,
            "bins": labels,
            "closed_loop": loop_rows,
            "demonstrations": anchor_rows,
        }
        args.json.write_text(json.dumps(numbers, indent=2))
    return 0


def add_arguments(p: argparse.ArgumentParser) -> None:
    from .. import sim_options

    p.add_argument("checkpoint", type=Path, help="a pose_act checkpoint (.../checkpoints/last/pretrained_model)")
    p.add_argument("--dataset", type=Path, required=True, help="recorded demonstrations with the cube's pose (the anchor)")
    p.add_argument("--anchor-episodes", type=int, default=10, help="the dataset's first N episodes are the anchor's frames")
    p.add_argument("--episodes", type=int, default=10, help="closed-loop episodes")
    p.add_argument("--seed", type=int, default=88000, help="seed of the first closed-loop episode (kept apart from others)")
    p.add_argument(
        "--randomize",
        type=sim_options.randomize_argument,
        nargs="?",
        const=sim_options.RANDOMIZE_DEFAULT,
        default=sim_options.RANDOMIZE_OFF,
        help="the closed-loop episodes' randomization, as so101-run-policy takes it (default off)",
    )
    p.add_argument("--threads", type=int, default=2, help="torch threads")
    p.add_argument("--bin-dir", type=Path, default=None, help="the built binaries (scripts/bench.sh passes it; unused)")
    p.add_argument("--json", type=Path, default=None, help="also write the numbers here")


SUBCOMMAND = Subcommand("pose_act's estimator in closed loop against demonstrations", add_arguments, run, __doc__)


def main(argv: list[str] | None = None) -> int:
    return run_alone("so101-bench pose_estimate", SUBCOMMAND, argv)


if __name__ == "__main__":
    raise SystemExit(main())
