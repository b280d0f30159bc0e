#!/usr/bin/env python3
"""End-effector actions: the IK's cost per control period and the share of end-effector targets
out of reach, on the in-process expert's demonstrations of a task (the demos recipe's noise).
Each period's joint targets become the end-effector target they reach (forward kinematics, what
the converter's --action-space ee writes), then the IK turns it back into joint targets from the
targets in force, as an end-effector policy's runner does, one period at a time. The anchor, in
the same run: the in-process env's step of the same periods (the physics of one control period
and the observation), as a ratio.

No DDS. Prints a Markdown report; --json writes the numbers.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from ..subcommands import Subcommand, run_alone


def demonstration_targets(task: str, episodes: int, seed: int) -> tuple[list[np.ndarray], float]:
    """The expert's joint targets per episode (rad), and the seconds the env's steps of those
    periods took."""
    import gymnasium as gym

    from .. import contract
    from ..evaluate.expert import ExpertPolicy

    env = gym.make(contract.TASKS[task].gym_id)
    targets, stepping = [], 0.0
    for episode in range(episodes):
        observation, _ = env.reset(seed=seed + episode)
        expert = ExpertPolicy(waypoint_noise=0.005, action_noise=0.01, seed=seed + episode, task=task)
        expert.reset(observation)
        episode_targets = []
        for _ in range(contract.TASKS[task].episode_steps):
            action = expert(observation)
            episode_targets.append(np.asarray(action, dtype=np.float64))
            started = time.perf_counter()
            observation, *_ = env.step(action)
            stepping += time.perf_counter() - started
            if expert.done:
                break
        targets.append(np.array(episode_targets))
    env.close()
    return targets, stepping


def run(args: argparse.Namespace) -> int:
    from ..ee import EeCommander, ee_poses

    targets, stepping = demonstration_targets(args.task, args.episodes, args.seed)
    periods = sum(len(episode) for episode in targets)
    ik_times, clamped, errors = [], 0, []
    for episode in targets:
        ee_targets = ee_poses(episode)
        commander = EeCommander()
        commander.reset(episode[0])
        for target in ee_targets:
            started = time.perf_counter()
            steps = commander.step(target)
            ik_times.append(time.perf_counter() - started)
            clamped += int(steps.clamped[0])
            errors.append(float(steps.position_error[0]))
    ik_us = 1e6 * np.array(ik_times)
    physics_us = 1e6 * stepping / periods
    numbers = {
        "task": args.task,
        "episodes": args.episodes,
        "periods": periods,
        "ik_us_mean": float(ik_us.mean()),
        "ik_us_p99": float(np.percentile(ik_us, 99)),
        "env_step_us_per_period": physics_us,
        "ik_to_env_step": float(ik_us.mean() / physics_us),
        "clamped": clamped,
        "clamped_share": clamped / periods,
        "position_error_max_m": float(max(errors)),
    }
    print(f"## End-effector actions: {args.task}, {args.episodes} expert episodes, {periods} periods\n")
    print(
        "| IK per period (mean, p99) | env step per period (anchor) | IK / env step | targets out of reach | largest position error |"
    )
    print("|---|---|---|---|---|")
    print(
        f"| {numbers['ik_us_mean']:.1f} us, {numbers['ik_us_p99']:.1f} us | {physics_us:.0f} us | "
        f"{numbers['ik_to_env_step']:.3f} | {clamped} of {periods} ({100 * numbers['clamped_share']:.2f} %) | "
        f"{1000 * numbers['position_error_max_m']:.3f} mm |"
    )
    if args.json:
        args.json.write_text(json.dumps(numbers, indent=2))
    return 0


def add_arguments(p: argparse.ArgumentParser) -> None:
    from .. import contract

    p.add_argument("--bin-dir", type=Path, default=None, help="the built binaries (scripts/bench.sh passes it; unused)")
    p.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    p.add_argument("--task", choices=list(contract.TASKS), default="cube_to_bin", help="the task the expert demonstrates")
    p.add_argument("--episodes", type=int, default=50, help="expert episodes")
    p.add_argument("--seed", type=int, default=43000, help="seed of the first episode (kept apart from the tests')")


SUBCOMMAND = Subcommand("end-effector actions: IK cost per period, targets out of reach", add_arguments, run, __doc__)


def main(argv: list[str] | None = None) -> int:
    return run_alone("so101-bench ee", SUBCOMMAND, argv)


if __name__ == "__main__":
    raise SystemExit(main())
