#!/usr/bin/env python3
"""Conversion speed of so101-bag-to-lerobot: frames per second from episode bags to a LeRobot
dataset, and the share of that time spent encoding video (LeRobot's encode_video_frames, timed
in-process with one camera encoded at a time).

The bags are made first: so101_sim_node (--lite, --speed 2, three cameras at the chosen size and
30 Hz), recorder_node and the scripted expert, N episodes. Must run inside one private network
namespace (scripts/bench.sh does that). Prints a Markdown report; --json keeps the numbers.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from so101 import contract
from so101.bench import common as bench_common
from so101.subcommands import Subcommand, run_alone


def node_env() -> dict:
    return bench_common.node_env("warn", keep_callers_level=True)


def record(bin_dir: Path, bags: Path, episodes: int, size: str) -> float:
    """Records `episodes` expert episodes into `bags`; returns the wall seconds it took."""
    started = time.monotonic()
    sim = subprocess.Popen(
        [
            str(bin_dir / "so101_sim_node"),
            "--lite",
            "--speed",
            "2",
            "--seed",
            "1",
            "--cameras",
            ",".join(contract.CAMERA_NAMES),
            "--camera-size",
            size,
            "--camera-rate",
            f"{contract.CONTROL_RATE:g}",
        ],
        env=node_env(),
        stderr=subprocess.DEVNULL,
    )
    recorder = subprocess.Popen(
        [str(bin_dir / "recorder_node"), "--output", str(bags)], env=node_env(), stderr=subprocess.DEVNULL
    )
    try:
        subprocess.run(
            [str(bin_dir / "teleop_node"), "--source", "expert", "--sim-time", "--episodes", str(episodes)],
            env=node_env(),
            check=True,
            stderr=subprocess.DEVNULL,
            timeout=60 * episodes + 120,
        )
        time.sleep(1.0)
    finally:
        for process in (recorder, sim):
            process.send_signal(2)
            process.wait(timeout=30)
    return time.monotonic() - started


def convert(bags: Path, output: Path) -> dict:
    """Runs the converter in this process with encode_video_frames timed."""
    import lerobot.datasets.dataset_writer as writer

    from so101.dataset import convert as converter

    spent = {"encode": 0.0, "videos": 0}
    original = writer.encode_video_frames

    def timed(*args, **kwargs):
        begun = time.monotonic()
        try:
            return original(*args, **kwargs)
        finally:
            spent["encode"] += time.monotonic() - begun
            spent["videos"] += 1

    writer.encode_video_frames = timed
    begun = time.monotonic()
    code = converter.main([str(bags), "--output", str(output), "--sequential-encoding", "--quiet"])
    total = time.monotonic() - begun
    writer.encode_video_frames = original
    if code != 0:
        raise RuntimeError("the conversion failed")
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    frames = LeRobotDataset("local/so101_cube_to_bin", root=output).num_frames
    return {"seconds": total, "frames": frames, "encode_seconds": spent["encode"], "videos": spent["videos"]}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--bin-dir", type=Path, required=True)
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--sizes", default="320x240,640x480", help="camera sizes to measure, comma-separated")
    parser.add_argument("--json", type=Path, default=None)


def run(args: argparse.Namespace) -> int:
    results = {}
    for size in args.sizes.split(","):
        with tempfile.TemporaryDirectory() as work:
            bags, output = Path(work) / "bags", Path(work) / "dataset"
            record_seconds = record(args.bin_dir, bags, args.episodes, size)
            result = convert(bags, output)
            result["record_seconds"] = record_seconds
            results[size] = result
            print(f"{size}: {result}", file=sys.stderr)
    lines = ["| cameras | episodes | frames | conversion s | frames/s | share in video encoding |", "|---|---|---|---|---|---|"]
    for size, r in results.items():
        lines.append(
            f"| 3 x {size} rgb8 @ 30 Hz | {args.episodes} | {r['frames']} | {r['seconds']:.1f} | "
            f"**{r['frames'] / r['seconds']:.1f}** | **{100 * r['encode_seconds'] / r['seconds']:.0f} %** "
            f"({r['videos']} videos, {r['encode_seconds']:.1f} s) |"
        )
    return bench_common.report(lines, results, args.json)


SUBCOMMAND = Subcommand("so101-bag-to-lerobot's frames/s and its share in video encoding", add_arguments, run, __doc__)


def main(argv: list[str] | None = None) -> int:
    return run_alone("so101-bench convert", SUBCOMMAND, argv)


if __name__ == "__main__":
    sys.exit(main())
