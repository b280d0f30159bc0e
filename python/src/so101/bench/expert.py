#!/usr/bin/env python3
"""Success rate of teleop_node's scripted expert on a task (--task, cube_to_bin by default): N seeded episodes against
so101_sim_node (sim time, --speed S), judged by the sim's /task/success (issue 4's target: >= 90 %
over 50 episodes). Also the same episodes with waypoint and action noise, as used to make varied
demonstrations.

Must run inside one private network namespace (scripts/bench.sh does that). Prints a Markdown
report on stdout and writes the raw numbers as JSON to --json.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from so101 import contract
from so101.bench import common as bench_common
from so101.subcommands import Subcommand, run_alone


def node_env() -> dict:
    return bench_common.node_env("info", keep_callers_level=True)


def run_expert(
    bin_dir: Path,
    episodes: int,
    speed: float,
    sim_seed: int,
    expert_seed: int,
    noise: tuple[float, float],
    lite: bool,
    task: str = "cube_to_bin",
) -> dict:
    with tempfile.TemporaryDirectory() as work:
        report = Path(work) / "report.json"
        sim_args = [str(bin_dir / "so101_sim_node"), "--cameras", "none", "--speed", str(speed), "--seed", str(sim_seed)]
        sim_args += ["--task", task]
        if lite:
            sim_args.append("--lite")
        sim = subprocess.Popen(sim_args, env=node_env(), stderr=subprocess.DEVNULL)
        started = time.monotonic()
        try:
            expert = subprocess.run(
                [
                    str(bin_dir / "teleop_node"),
                    "--source",
                    "expert",
                    "--sim-time",
                    "--episodes",
                    str(episodes),
                    "--seed",
                    str(expert_seed),
                    "--waypoint-noise",
                    str(noise[0]),
                    "--action-noise",
                    str(noise[1]),
                    "--report",
                    str(report),
                    "--sim-task",
                    task,
                ],
                env=node_env(),
                stderr=subprocess.PIPE,
                text=True,
                timeout=episodes * 12 / speed + 120,
            )
        finally:
            sim.terminate()
            sim.wait(timeout=20)
        if expert.returncode != 0:
            raise RuntimeError(f"teleop_node exited with {expert.returncode}:\n{expert.stderr[-3000:]}")
        result = json.loads(report.read_text())
        result["wall_seconds"] = time.monotonic() - started
        return result


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--bin-dir", type=Path, required=True)
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--speed", type=float, default=4.0, help="sim speed factor (the expert runs on sim time)")
    parser.add_argument("--seed", type=int, default=1, help="sim seed (cube placements)")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--task", choices=list(contract.TASKS), default="cube_to_bin", help="the task the expert plays")


def run(args: argparse.Namespace) -> int:
    noises = {
        "no noise": (0.0, 0.0),
        "waypoint noise 3 mm, action noise 0.005 rad": (0.003, 0.005),
        "waypoint noise 5 mm, action noise 0.01 rad": (0.005, 0.01),
    }
    runs = {
        label: run_expert(args.bin_dir, args.episodes, args.speed, args.seed, 1, noise, lite=False, task=args.task)
        for label, noise in noises.items()
    }
    lines = [
        "| expert | episodes | successes | success rate | wall time |",
        "|---|---|---|---|---|",
    ]
    for label, result in runs.items():
        lines.append(
            f"| {label} | {result['episodes']} | {result['successes']} | **{100 * result['success_rate']:.0f} %** "
            f"| {result['wall_seconds']:.0f} s |"
        )
        failures = [r for r in result["results"] if not r["success"]]
        for failure in failures:
            lines.append(
                f"|  failed: episode {failure['episode']} | cube x={failure['cube'][0]:.3f} y={failure['cube'][1]:.3f} "
                f"yaw={failure['cube'][3]:.2f} | {failure['note']} | | |"
            )
        print(f"{label}: {result['successes']}/{result['episodes']}", file=sys.stderr)
    return bench_common.report(lines, runs, args.json)


SUBCOMMAND = Subcommand(
    "the scripted expert's success rate on a task (cube_to_bin) against so101_sim_node", add_arguments, run, __doc__
)


def main(argv: list[str] | None = None) -> int:
    return run_alone("so101-bench expert", SUBCOMMAND, argv)


if __name__ == "__main__":
    sys.exit(main())
