#!/usr/bin/env python3
"""Where a policy's grasps land: its cube_to_bin episodes replayed in-process on their seeds (the
same episodes as so101-run-policy's --backend inprocess on the same seeds and options), each told
apart by what the arm did: where the jaws were first commanded shut relative to the cube, how often,
whether the cube was ever lifted, and whether the episode ended with the jaws open away from the
cube. The anchor, in the same run: the scripted expert (with the demos recipe's noise) on the same
seeds, as a ratio of the median distance from the grasp point to the cube at the first closing.

Why: the dense reward says only that a failure never held the cube ("stopped short"); this says
whether the arm closed its jaws beside the cube, above it, or never (docs/benchmarks.md, "What
stopped short is, in the arm's terms").

No DDS. Prints a Markdown report; --json writes every episode.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..subcommands import Subcommand, run_alone

# The gripper command (rad) counts as a closing when it falls below CLOSING_BELOW after having been
# above OPEN_ABOVE: the expert opens to about 0.9 and closes to -0.17, whatever the cube's size.
CLOSING_BELOW = 0.3
OPEN_ABOVE = 0.5
# A closing this far (m) or more from the cube's centre cannot hold it (the cube is about 3 cm wide).
MISS_FROM = 0.015
# Raised this much (m) above where it started, the cube was held.
LIFTED_BY = 0.01
# Ended waiting: the jaws open (rad) and the grasp point this far (m) from the cube.
AWAY_FROM = 0.05

KINDS = ("success", "missed the cube", "lost the cube", "never closed", "other failure")


@dataclass
class GraspEpisode:
    seed: int
    success: bool
    kind: str
    # The grasp point minus the cube's centre (m, the base frame's axes) at the first closing.
    first_closing: list[float] | None
    closings: int
    closest: float  # m, the grasp point's closest approach to the cube
    lifted: bool
    ended_open_away: bool


def closings(gripper_commands: np.ndarray) -> list[int]:
    """The steps at which the gripper command falls below CLOSING_BELOW after being above OPEN_ABOVE."""
    found, opened = [], False
    for step, command in enumerate(gripper_commands):
        if command > OPEN_ABOVE:
            opened = True
        elif opened and command < CLOSING_BELOW:
            found.append(step)
            opened = False
    return found


def grasp_episode(seed: int, success: bool, grasp_points, cubes, gripper_states, gripper_commands) -> GraspEpisode:
    """One episode's account from its per-step grasp points and cube centres (m, one frame) and its
    gripper joint and command (rad)."""
    grasp_points, cubes = np.asarray(grasp_points, dtype=float), np.asarray(cubes, dtype=float)
    offsets = grasp_points - cubes
    distances = np.linalg.norm(offsets, axis=1)
    shut = closings(np.asarray(gripper_commands, dtype=float))
    first = offsets[shut[0]] if shut else None
    lifted = bool((cubes[:, 2] > cubes[0, 2] + LIFTED_BY).any())
    ended_open_away = bool(gripper_states[-1] > OPEN_ABOVE and distances[-1] > AWAY_FROM)
    if success:
        kind = "success"
    elif first is None:
        kind = "never closed"
    elif np.linalg.norm(first) >= MISS_FROM and not lifted:
        kind = "missed the cube"
    elif lifted:
        kind = "lost the cube"
    else:
        kind = "other failure"
    return GraspEpisode(
        seed=seed,
        success=success,
        kind=kind,
        first_closing=None if first is None else [round(float(v), 4) for v in first],
        closings=len(shut),
        closest=float(distances.min()),
        lifted=lifted,
        ended_open_away=ended_open_away,
    )


def summary(episodes: list[GraspEpisode]) -> dict:
    """Counts by kind, and the median distance (m) from the cube at the first closing."""
    first = [np.linalg.norm(e.first_closing) for e in episodes if e.first_closing is not None]
    failed_first = [np.linalg.norm(e.first_closing) for e in episodes if e.first_closing is not None and not e.success]
    return {
        "episodes": len(episodes),
        "kinds": {kind: sum(e.kind == kind for e in episodes) for kind in KINDS},
        "median_first_closing_m": float(np.median(first)) if first else None,
        "median_first_closing_of_failures_m": float(np.median(failed_first)) if failed_first else None,
        "ended_open_away": sum(e.ended_open_away for e in episodes),
        "closed_more_than_once": sum(e.closings > 1 for e in episodes),
    }


def replay(act, reset, env, seeds: list[int], max_steps: int) -> list[GraspEpisode]:
    """Each seed's episode with `act(observation) -> joint targets (rad)`, run by so101-run-policy's
    own episode loop (so101.evaluate.episodes.run_episodes), each step's joints, cube and gripper
    command kept on the way, then accounted for."""
    import so101_native

    from .. import contract
    from ..ee import ee_poses
    from ..evaluate.episodes import run_episodes

    steps: list[list[tuple]] = []  # per episode: (joints, cube centre, gripper command) each step

    def recording_reset(observation: dict) -> None:
        steps.append([])
        reset(observation)

    def recording_act(observation: dict) -> np.ndarray:
        action = np.asarray(act(observation), dtype=float)
        steps[-1].append((observation["agent_pos"], observation["environment_state"][:3], action[5]))
        return action

    # No video is filmed, so nothing is written under `output`.
    results = run_episodes(
        env, recording_act, recording_reset, seeds, max_steps, [], Path("."), contract.CONTROL_RATE, quiet=True
    )
    base = np.asarray(so101_native.SIM_BASE_IN_WORLD)
    episodes = []
    for result, episode in zip(results, steps, strict=True):
        joints = np.asarray([joint for joint, _, _ in episode], dtype=float)
        cubes = [cube for _, cube, _ in episode]
        commands = [command for _, _, command in episode]
        grasp_points = ee_poses(joints)[:, :3] + base
        episodes.append(grasp_episode(result.seed, result.success, grasp_points, cubes, joints[:, 5], commands))
    return episodes


def sim_settings(args) -> dict:
    return {"servo_params": args.servo_params, "randomize": args.randomize, "camera_poses": args.camera_poses}


def policy_episodes(args, seeds: list[int]) -> list[GraspEpisode]:
    from .. import contract
    from ..envs import make_env
    from ..evaluate.policy import StackPolicy

    policy = StackPolicy(str(args.checkpoint), task=contract.TASKS["cube_to_bin"].description)
    cameras = {camera.name: (camera.height, camera.width) for camera in policy.cameras}
    env = make_env("cube_to_bin", backend="inprocess", lite=True, cameras=cameras or None, **sim_settings(args))
    try:
        return replay(
            policy.act_on_env,
            lambda _o: policy.reset(),
            env,
            seeds,
            contract.TASKS["cube_to_bin"].episode_steps,
        )
    finally:
        env.close()


def expert_episodes(args, seeds: list[int]) -> list[GraspEpisode]:
    from .. import contract
    from ..envs import make_env
    from ..evaluate.expert import ExpertPolicy

    env = make_env("cube_to_bin", backend="inprocess", lite=True, **sim_settings(args))
    expert = ExpertPolicy(waypoint_noise=0.005, action_noise=0.01)
    try:
        return replay(expert, expert.reset, env, seeds, contract.TASKS["cube_to_bin"].episode_steps)
    finally:
        env.close()


def chosen_seeds(args) -> list[int]:
    """--failures-of's failing seeds, or --episodes from --seed."""
    if args.failures_of:
        report = json.loads(Path(args.failures_of).read_text())
        return [episode["seed"] for episode in report["per_episode"] if not episode["success"]]
    return list(range(args.seed, args.seed + args.episodes))


def run(args: argparse.Namespace) -> int:
    import torch

    torch.set_num_threads(args.threads)
    seeds = chosen_seeds(args)
    if not seeds:
        print("no episodes to replay (no failures in the report)")
        return 0
    ours, anchor = policy_episodes(args, seeds), expert_episodes(args, seeds)
    mine, theirs = summary(ours), summary(anchor)
    where = f"--failures-of {args.failures_of}" if args.failures_of else f"seeds {seeds[0]}-{seeds[-1]}"
    print(
        f"## Grasps of {args.checkpoint}: {len(seeds)} episodes ({where}, randomize {args.randomize}); the expert on the same seeds\n"
    )
    print("| | policy | expert |\n|---|---|---|")
    for kind in KINDS:
        print(f"| {kind} | {mine['kinds'][kind]} | {theirs['kinds'][kind]} |")
    for key, label in (
        ("ended_open_away", "ended with the jaws open away from the cube"),
        ("closed_more_than_once", "closed more than once"),
    ):
        print(f"| {label} | {mine[key]} | {theirs[key]} |")

    def cm(value) -> str:
        return "n/a" if value is None else f"{100 * value:.1f} cm"

    first, anchor_first = mine["median_first_closing_m"], theirs["median_first_closing_m"]
    ratio = f"{first / anchor_first:.1f}" if first is not None and anchor_first else "n/a"
    print(f"| median distance from the cube at the first closing | {cm(first)} | {cm(anchor_first)} (ratio {ratio}) |")
    if args.json:
        numbers = {"checkpoint": str(args.checkpoint), "randomize": args.randomize, "seeds": seeds, "policy": mine,
                   "expert": theirs, "policy_episodes": [asdict(e) for e in ours],
                   "expert_episodes": [asdict(e) for e in anchor]}  # fmt: skip
        args.json.write_text(json.dumps(numbers, indent=2))
    return 0


def add_arguments(p: argparse.ArgumentParser) -> None:
    from .. import sim_options

    p.add_argument("checkpoint", type=Path, help="a policy checkpoint (.../checkpoints/last/pretrained_model)")
    p.add_argument(
        "--failures-of",
        type=Path,
        default=None,
        help="replay only the failing seeds of this eval_info.json (so101-run-policy --backend inprocess, same options)",
    )
    p.add_argument("--episodes", type=int, default=10, help="episodes from --seed (without --failures-of)")
    p.add_argument("--seed", type=int, default=1000, help="seed of the first episode (without --failures-of)")
    # The sim's options as so101-run-policy takes them: pass the evaluation's own.
    sim_options.add_arguments(p)
    p.add_argument("--threads", type=int, default=2, help="torch threads")
    p.add_argument("--bin-dir", type=Path, default=None, help="the built binaries (scripts/bench.sh passes it; unused)")
    p.add_argument("--json", type=Path, default=None, help="also write every episode's account here")


SUBCOMMAND = Subcommand("where a policy's grasps land against the expert's", add_arguments, run, __doc__)


def main(argv: list[str] | None = None) -> int:
    return run_alone("so101-bench grasps", SUBCOMMAND, argv)


if __name__ == "__main__":
    raise SystemExit(main())
