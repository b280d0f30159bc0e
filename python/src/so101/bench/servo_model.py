"""What the STS3215 servo model costs: physics steps/s of one in-process world with the scene's
gain-80 position servos (the anchor) against the STS3215 model (its torques computed in Rust before
every physics step), and with domain randomization on top, measured in one run, interleaved,
median of --repeats. Issue 31's target: the model at >= 0.9x the anchor.

    so101-bench servo_model [--steps 3000] [--repeats 5]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np

from .. import contract
from ..envs.inprocess import default_scene
from ..subcommands import Subcommand, run_alone
from .sim_core import random_actions

CASES = (
    ("gain80 position servos (anchor)", "gain80", "off"),
    ("STS3215 model", "sts3215", "off"),
    ("STS3215 model, randomized", "sts3215", "default"),
)


def physics_steps_per_second(servo_params: str, randomize: str, steps: int) -> float:
    import so101_native

    world = so101_native.World(default_scene(), lite=True, servo_params=servo_params, randomize=randomize)
    world.reset(0)
    limits = np.asarray(world.joint_limits)
    actions = random_actions(limits[:, 0], limits[:, 1], steps)
    # Episodes as a policy runs them: a reset every episode's length.
    episode = contract.TASKS["cube_to_bin"].episode_steps
    started = time.perf_counter()
    physics_before = world.physics_steps
    for index, action in enumerate(actions):
        if index and index % episode == 0:
            world.reset()
        world.step(action)
    elapsed = time.perf_counter() - started
    return (world.physics_steps - physics_before) / elapsed


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--bin-dir", type=Path, default=None, help="the built binaries (scripts/bench.sh passes it)")
    p.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    p.add_argument("--steps", type=int, default=3000, help="control periods per measurement")
    p.add_argument("--repeats", type=int, default=5, help="measurements per case (interleaved); the median is reported")


def run(args: argparse.Namespace) -> int:
    rates: dict[str, list[float]] = {label: [] for label, _, _ in CASES}
    for _ in range(args.repeats):
        for label, servo_params, randomize in CASES:
            rates[label].append(physics_steps_per_second(servo_params, randomize, args.steps))
    anchor = statistics.median(rates[CASES[0][0]])
    print("| servos | physics steps/s (median) | runs | ratio to gain80 |")
    print("|---|---|---|---|")
    for label, _, _ in CASES:
        median = statistics.median(rates[label])
        runs = ", ".join(f"{rate:,.0f}" for rate in rates[label])
        print(f"| {label} | {median:,.0f} | {runs} | {median / anchor:.2f}x |")
    model = statistics.median(rates[CASES[1][0]])
    print(f"servo model cost: {model / anchor:.2f}x the gain-80 servos' physics steps/s (target >= 0.9x)")
    if args.json:
        args.json.write_text(json.dumps({"physics_steps_per_second": rates, "ratio": model / anchor}, indent=2))
    return 0


SUBCOMMAND = Subcommand("physics steps/s with the STS3215 servo model against the gain-80 servos", add_arguments, run, __doc__)


def main(argv: list[str] | None = None) -> int:
    return run_alone("so101-bench servo_model", SUBCOMMAND, argv)


if __name__ == "__main__":
    raise SystemExit(main())
