"""Real backgrounds' cost per frame: MuJoCo's offscreen render loop on the node's scene
(`so101_render_bench`, the anchor) against the same loop with each frame keyed and composited
over a picture (`--background`, what the camera rig does for the randomization's `backgrounds`),
as a ratio, in the same run. Runs interleave the two; the table gives medians. The picture is
fitted to the frame once (the rig does it once per episode), so what is measured per frame is the
keyed scene (scenery unlit, a key sphere for the sky) and the pixel swap. Opens no DDS participant.
Prints a Markdown report on stdout and writes the raw numbers as JSON to --json.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np

from so101.bench import common as bench_common
from so101.subcommands import Subcommand, run_alone

SIZES = ["96x72", "640x480"]
CAMERAS = "top,front"


def picture(path: Path) -> Path:
    """A 640x480 photo-like JPEG: smooth gradients with fine noise (its content does not change the
    cost, only its size once per episode)."""
    from PIL import Image

    rng = np.random.default_rng(0)
    y, x = np.mgrid[0:480, 0:640]
    rgb = np.stack([x * 255 // 639, y * 255 // 479, (x + y) * 255 // 1118], axis=-1).astype(np.int16)
    rgb += rng.integers(-8, 9, size=rgb.shape, dtype=np.int16)
    Image.fromarray(np.clip(rgb, 0, 255).astype(np.uint8)).save(path, quality=90)
    return path


def ms_per_frame(bin_dir: Path, size: str, frames: int, background: Path | None) -> float:
    import subprocess

    command = [str(bin_dir / "so101_render_bench"), "--cameras", CAMERAS, "--size", size, "--frames", str(frames)]
    if background is not None:
        command += ["--background", str(background)]
    out = subprocess.run(command, check=True, capture_output=True, text=True, env=bench_common.node_env("info")).stdout
    return float(json.loads(out.strip().splitlines()[-1])["ms_per_frame"])


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--bin-dir", type=Path, required=True)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--frames", type=int, default=300, help="frames of each run (after 10 of warm-up)")
    parser.add_argument("--json", type=Path, default=None)


def run(args: argparse.Namespace) -> int:
    results: dict = {}
    with tempfile.TemporaryDirectory() as folder:
        background = picture(Path(folder) / "background.jpg")
        for size in SIZES:
            runs = []
            for repeat in range(args.repeats):
                plain = ms_per_frame(args.bin_dir, size, args.frames, None)
                composited = ms_per_frame(args.bin_dir, size, args.frames, background)
                runs.append({"plain_ms": plain, "composited_ms": composited})
                print(f"{size} run {repeat + 1}: plain {plain:.2f} ms, composited {composited:.2f} ms", file=sys.stderr)
            results[size] = runs
    lines = [
        f"| frame size (cameras {CAMERAS.replace(',', ' + ')}, meshes) | plain render ms/frame | with background ms/frame "
        "| ratio with/plain (runs) |",
        "|---|---|---|---|",
    ]
    for size, runs in results.items():
        plain = statistics.median(r["plain_ms"] for r in runs)
        composited = statistics.median(r["composited_ms"] for r in runs)
        ratios = sorted(r["composited_ms"] / r["plain_ms"] for r in runs)
        lines.append(
            f"| {size} | {plain:.2f} | {composited:.2f} | **{composited / plain:.3f}** "
            f"({', '.join(f'{ratio:.3f}' for ratio in ratios)}) |"
        )
    return bench_common.report(lines, results, args.json)


SUBCOMMAND = Subcommand("real backgrounds' cost per frame against the plain render", add_arguments, run, __doc__)


def main(argv: list[str] | None = None) -> int:
    return run_alone("so101-bench backgrounds", SUBCOMMAND, argv)


if __name__ == "__main__":
    sys.exit(main())
