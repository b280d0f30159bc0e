#!/usr/bin/env python3
"""Camera benchmark of so101_sim_node: milliseconds per frame of the node against a bare MuJoCo
render loop on the same scene (the anchor, `so101_render_bench`), as a ratio, in the same run.

The node runs `--speed max` with its cameras at the control rate, so the physics waits for every
frame and its frame rate is the rate its render pipeline reaches (scene update on the physics
thread, draw + read on the render thread, flip and publish on the publisher thread). The anchor
draws the same cameras at the same size with nothing else: mjv_updateScene, mjr_render,
mjr_readPixels. Runs interleave anchor and node; tables give medians.

Also measured: the node in real time with its default cameras (3 x 640x480 at 30 Hz): frames each
camera gets, frames skipped, and whether the physics kept real time.

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
from pathlib import Path

from so101 import contract
from so101.bench import common as bench_common
from so101.stack import process
from so101.subcommands import Subcommand, run_alone

# (label, lite, cameras, size)
CONFIGS = [
    ("lite visuals, top, 640x480", True, "top", "640x480"),
    ("meshes, top, 640x480", False, "top", "640x480"),
    (f"meshes, {'+'.join(contract.CAMERA_NAMES)}, 640x480", False, ",".join(contract.CAMERA_NAMES), "640x480"),
    ("meshes, top, 320x240", False, "top", "320x240"),
]


def node_env() -> dict:
    return bench_common.node_env("info")


def bare_ms_per_frame(bin_dir: Path, lite: bool, cameras: str, size: str, frames: int) -> float:
    command = [str(bin_dir / "so101_render_bench"), "--cameras", cameras, "--size", size, "--frames", str(frames)]
    if lite:
        command.append("--lite")
    out = subprocess.run(command, check=True, capture_output=True, text=True, env=node_env()).stdout
    return float(json.loads(out.strip().splitlines()[-1])["ms_per_frame"])


SUBSCRIBER = bench_common.counting_subscriber("sensor_msgs", "Image", "/camera/top/image_raw", 10)


def run_node(bin_dir: Path, args: list[str], seconds: float, with_subscriber: bool = False) -> dict:
    """Runs the node for `seconds` of wall time; returns its shutdown report."""
    subscriber = None
    if with_subscriber:
        subscriber = subprocess.Popen([sys.executable, "-c", SUBSCRIBER], stdout=subprocess.PIPE, text=True)
    node = subprocess.Popen(
        [str(bin_dir / "so101_sim_node"), *args, "--duration", str(seconds)], env=node_env(), stderr=subprocess.PIPE, text=True
    )
    _, err = node.communicate(timeout=seconds + 120)
    received = None
    if subscriber is not None:
        received = int(process.interrupt_and_collect(subscriber)[0].strip() or 0)
    if node.returncode != 0:
        raise RuntimeError(f"so101_sim_node {' '.join(args)} exited with {node.returncode}:\n{err[-3000:]}")
    shutdown = re.search(r"shutting down .*sim_seconds_run=([0-9.]+) wall_seconds=([0-9.]+) physics_steps=([0-9]+)", err)
    cameras = re.findall(r"camera frames camera=(\w+) rendered=([0-9]+) skipped=([0-9]+)", err)
    if not shutdown or not cameras:
        raise RuntimeError(f"unexpected node log:\n{err[-3000:]}")
    wall = float(shutdown.group(2))
    # A line per camera (the log may hold it twice: stderr and the /rosout mirror).
    by_camera = {name: {"rendered": int(r), "skipped": int(s)} for name, r, s in cameras}
    rendered = sum(c["rendered"] for c in by_camera.values())
    return {
        "wall_seconds": wall,
        "sim_seconds": float(shutdown.group(1)),
        "physics_steps": int(shutdown.group(3)),
        "frames": rendered,
        "ms_per_frame": 1e3 * wall / rendered,
        "cameras": by_camera,
        "received_by_rclpy": received,
    }


def node_max_speed(bin_dir: Path, lite: bool, cameras: str, size: str, seconds: float, with_subscriber: bool = False) -> dict:
    args = ["--speed", "max", "--cameras", cameras, "--camera-size", size, "--camera-rate", "100"]
    if lite:
        args.append("--lite")
    return run_node(bin_dir, args, seconds, with_subscriber)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--bin-dir", type=Path, required=True)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=8.0, help="wall time of each node run")
    parser.add_argument("--frames", type=int, default=150, help="frames of each anchor run (after 10 of warm-up)")
    parser.add_argument("--json", type=Path, default=None)


def run(args: argparse.Namespace) -> int:
    results: dict = {"configs": {}, "rclpy_subscriber": [], "real_time": None}
    for label, lite, cameras, size in CONFIGS:
        runs = []
        for repeat in range(args.repeats):
            bare = bare_ms_per_frame(args.bin_dir, lite, cameras, size, args.frames)
            node = node_max_speed(args.bin_dir, lite, cameras, size, args.seconds)
            runs.append({"bare_ms_per_frame": bare, "node": node})
            print(
                f"{label} run {repeat + 1}: bare {bare:.2f} ms/frame, node {node['ms_per_frame']:.2f} ms/frame", file=sys.stderr
            )
        results["configs"][label] = runs

    # End to end: the same pipeline with an rclpy process receiving every top frame.
    for repeat in range(args.repeats):
        bare = bare_ms_per_frame(args.bin_dir, False, "top", "640x480", args.frames)
        node = node_max_speed(args.bin_dir, False, "top", "640x480", args.seconds, with_subscriber=True)
        results["rclpy_subscriber"].append({"bare_ms_per_frame": bare, "node": node})
        print(
            f"with rclpy subscriber run {repeat + 1}: bare {bare:.2f}, node {node['ms_per_frame']:.2f} ms/frame, "
            f"received {node['received_by_rclpy']} of {node['frames']}",
            file=sys.stderr,
        )

    # Real time with the defaults.
    results["real_time"] = run_node(args.bin_dir, [], args.seconds * 2)

    lines = [
        "| cameras (scene visuals, cameras, size) | bare loop ms/frame | node ms/frame | ratio bare/node | node frames/s |",
        "|---|---|---|---|---|",
    ]

    def row(label: str, runs: list[dict]) -> str:
        bare = statistics.median(r["bare_ms_per_frame"] for r in runs)
        node = statistics.median(r["node"]["ms_per_frame"] for r in runs)
        ratios = sorted(r["bare_ms_per_frame"] / r["node"]["ms_per_frame"] for r in runs)
        return (
            f"| {label} | {bare:.2f} | {node:.2f} | **{bare / node:.2f}** (runs {', '.join(f'{x:.2f}' for x in ratios)})"
            f" | {1e3 / node:.1f} |"
        )

    for label, runs in results["configs"].items():
        lines.append(row(label, runs))
    lines.append(row("meshes, top, 640x480, rclpy subscriber receiving", results["rclpy_subscriber"]))
    received = [r["node"]["received_by_rclpy"] for r in results["rclpy_subscriber"]]
    published = [r["node"]["frames"] for r in results["rclpy_subscriber"]]
    rt = results["real_time"]
    lines += [
        "",
        f"rclpy received {sum(received)} of {sum(published)} published frames in the subscriber runs.",
        "",
        f"Real time, default cameras (3 x 640x480 @ 30 Hz, meshes), {rt['wall_seconds']:.1f} s: "
        f"sim time / wall time {rt['sim_seconds'] / rt['wall_seconds']:.3f}; "
        + "; ".join(
            f"{name} {c['rendered'] / rt['wall_seconds']:.1f} frames/s ({c['skipped']} skipped)"
            for name, c in rt["cameras"].items()
        ),
    ]
    return bench_common.report(lines, results, args.json)


SUBCOMMAND = Subcommand("so101_sim_node's camera rendering against a bare MuJoCo render loop", add_arguments, run, __doc__)


def main(argv: list[str] | None = None) -> int:
    return run_alone("so101-bench cameras", SUBCOMMAND, argv)


if __name__ == "__main__":
    sys.exit(main())
