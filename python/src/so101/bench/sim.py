#!/usr/bin/env python3
"""Benchmarks of so101_sim_node, each compared in the same run with its anchor, as a ratio.

1. Physics speed: steps/s of the node at --speed max (no cameras) against `mujoco-testspeed` on the
   same scene file (target: ratio >= 0.9).
2. Reaction latency: command -> /joint_states, from a Rust client (so101_latency_probe) and from
   rclpy (so101.bench.latency), against the rclpy <-> rclpy ping-pong round trip of a JointState.

Must run inside one private network namespace (scripts/bench.sh does that). Prints a Markdown
report on stdout and writes the raw numbers as JSON to --json.
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from so101.bench import common as bench_common
from so101.paths import asset
from so101.stack import process
from so101.subcommands import Subcommand, run_alone


def node_env() -> dict:
    return bench_common.node_env("info")


def testspeed_steps_per_second(steps: int) -> float:
    out = subprocess.run(
        ["mujoco-testspeed", str(asset("so101_cube_to_bin.xml")), str(steps), "1", "0"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    match = re.search(r"Steps per second\s*:\s*([0-9.]+)", out)
    if not match:
        raise RuntimeError(f"unexpected mujoco-testspeed output:\n{out}")
    return float(match.group(1))


def node_steps_per_second(bin_dir: Path, seconds: float, with_subscriber: bool) -> float:
    node = subprocess.Popen(
        [str(bin_dir / "so101_sim_node"), "--cameras", "none", "--speed", "max", "--duration", str(seconds)],
        env=node_env(),
        stderr=subprocess.PIPE,
        text=True,
    )
    subscriber = None
    if with_subscriber:
        subscriber = subprocess.Popen([sys.executable, "-c", SUBSCRIBER], stdout=subprocess.PIPE, text=True)
    _, err = node.communicate(timeout=seconds + 60)
    received = None
    if subscriber is not None:
        received = process.interrupt_and_collect(subscriber, timeout=20)[0].strip()
    if node.returncode != 0:
        raise RuntimeError(f"so101_sim_node exited with {node.returncode}:\n{err}")
    match = re.search(r"steps_per_second=([0-9.]+)", err)
    if not match:
        raise RuntimeError(f"no steps_per_second in the node's log:\n{err}")
    if received is not None:
        print(f"  (rclpy subscriber received {received} joint_states)", file=sys.stderr)
    return float(match.group(1))


SUBSCRIBER = bench_common.counting_subscriber("sensor_msgs", "JointState", "/joint_states", 100)


def start_node(bin_dir: Path, rate: float) -> subprocess.Popen:
    # One second for the node to be up and announcing before the client starts.
    return process.start_and_check(
        [bin_dir / "so101_sim_node", "--lite", "--cameras", "none", "--rate", str(rate)],
        settle=1.0,
        log=tempfile.TemporaryFile(mode="w+"),
        env=node_env(),
    )


def run_tool(command: list[str], **kwargs) -> str:
    """Runs a measuring tool; on failure its stderr goes into the error."""
    done = subprocess.run(command, capture_output=True, text=True, timeout=300, **kwargs)
    if done.returncode != 0:
        raise RuntimeError(f"{command[0]} exited with {done.returncode}:\n{done.stderr[-3000:]}")
    return done.stdout


def json_line(output: str) -> dict:
    for line in reversed(output.strip().splitlines()):
        if line.startswith("{"):
            return json.loads(line)
    raise RuntimeError(f"no JSON result in:\n{output}")


def rust_reaction(bin_dir: Path, rate: float, samples: int) -> dict:
    node = start_node(bin_dir, rate)
    try:
        out = run_tool([str(bin_dir / "so101_latency_probe"), "--samples", str(samples)], env=node_env())
    finally:
        process.stop(node, timeout=20)
    return json_line(out)


def rclpy_reaction(bin_dir: Path, rate: float, samples: int) -> dict:
    node = start_node(bin_dir, rate)
    try:
        out = run_tool([sys.executable, "-m", "so101.bench.latency", "--samples", str(samples)])
    finally:
        process.stop(node, timeout=20)
    return json_line(out)


def pingpong(samples: int) -> dict:
    out = run_tool([sys.executable, "-m", "so101.bench.latency", "--pingpong", "--samples", str(samples)])
    return json_line(out)


def us(result: dict, key: str) -> float:
    """A percentile in microseconds, whichever unit the tool reported."""
    for name, scale in ((f"{key}_us", 1.0), (f"{key}_ms", 1e3), (f"{key}_s", 1e6)):
        if name in result:
            return float(result[name]) * scale
    raise KeyError(f"{key} not in {result}")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--bin-dir", type=Path, required=True)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=10.0, help="wall time of each --speed max run")
    parser.add_argument("--samples", type=int, default=1000, help="latency samples per measurement")
    parser.add_argument("--json", type=Path, default=None)


def run(args: argparse.Namespace) -> int:
    results: dict = {"speed": [], "latency": {}}
    for repeat in range(args.repeats):
        # Interleaved, so drift of the machine affects both sides of each ratio alike.
        anchor = testspeed_steps_per_second(int(args.seconds * 50_000))
        node = node_steps_per_second(args.bin_dir, args.seconds, with_subscriber=False)
        node_sub = node_steps_per_second(args.bin_dir, args.seconds, with_subscriber=True)
        results["speed"].append({"testspeed": anchor, "node": node, "node_with_rclpy_subscriber": node_sub})
        print(
            f"speed run {repeat + 1}: testspeed {anchor:.0f}, node {node:.0f}, node + rclpy subscriber {node_sub:.0f} steps/s",
            file=sys.stderr,
        )

    results["latency"]["pingpong_rclpy"] = pingpong(args.samples)
    for rate in (100.0, 500.0):
        results["latency"][f"rust_rate{rate:g}"] = rust_reaction(args.bin_dir, rate, args.samples)
        results["latency"][f"rclpy_rate{rate:g}"] = rclpy_reaction(args.bin_dir, rate, args.samples)
    print(json.dumps(results["latency"]), file=sys.stderr)

    median = lambda key: statistics.median(run[key] for run in results["speed"]) if results["speed"] else float("nan")  # noqa: E731
    anchor = median("testspeed")
    lines = [
        f"| measurement | steps/s (median of {args.repeats}) | ratio to mujoco-testspeed |",
        "|---|---|---|",
        f"| mujoco-testspeed, same scene, 1 thread | {anchor:,.0f} | 1.00 |",
        f"| so101_sim_node --speed max, no subscriber | {median('node'):,.0f} | {median('node') / anchor:.2f} |",
        f"| so101_sim_node --speed max, rclpy /joint_states subscriber | {median('node_with_rclpy_subscriber'):,.0f}"
        f" | {median('node_with_rclpy_subscriber') / anchor:.2f} |",
        "",
        "| reaction latency | p50 (us) | p99 (us) | p50 ratio to rclpy ping-pong |",
        "|---|---|---|---|",
    ]
    base = results["latency"]["pingpong_rclpy"]
    lines.append(f"| rclpy <-> rclpy ping-pong round trip (anchor) | {us(base, 'p50'):.0f} | {us(base, 'p99'):.0f} | 1.00 |")
    for key, label in (
        ("rust_rate100", "Rust client, node at 100 Hz"),
        ("rclpy_rate100", "rclpy client, node at 100 Hz"),
        ("rust_rate500", "Rust client, node at 500 Hz"),
        ("rclpy_rate500", "rclpy client, node at 500 Hz"),
    ):
        result = results["latency"][key]
        lines.append(
            f"| {label} | {us(result, 'p50'):.0f} | {us(result, 'p99'):.0f} | {us(result, 'p50') / us(base, 'p50'):.2f} |"
        )
    return bench_common.report(lines, results, args.json)


SUBCOMMAND = Subcommand(
    "so101_sim_node's speed and reaction latency against mujoco-testspeed and rclpy", add_arguments, run, __doc__
)


def main(argv: list[str] | None = None) -> int:
    return run_alone("so101-bench sim", SUBCOMMAND, argv)


if __name__ == "__main__":
    sys.exit(main())
