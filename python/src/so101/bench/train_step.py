#!/usr/bin/env python3
"""Where a training step's time goes: the recipe (`so101-learn act|pose_act|diffusion`, exactly as a
user runs it) for a few steps per variant, read from LeRobot's own log of each window of steps:
data_s, the wait for the batch (the loader's reading, video decoding and augmentation, then the
preprocessor), against updt_s, the model's step (forward, backward, optimizer). The first
window is left out (start-up; --skip leaves out more, e.g. a first pass through a dataset whose
items stay in memory after it). The anchor, in the same run: the recipe's own settings, as a ratio
of the step time.

Variants, each a lever of the recipe reachable from its command line:
- one-thread: one torch thread (--torch-threads 1) instead of torch's default (every core);
- inline-loading: the batch loaded in the step (--loader-workers 0): no loader process, so data_s is the whole cost of
  reading and decoding a batch (a dataset with cameras: without them the recipe loads in the step already);
- reread-items: every item read (and its frames decoded) from the dataset at every step, with a loader process beside
  the step (--reread-items: lerobot-train's own loading; by default the items stay in memory after their first read);
- bf16-autocast: bf16 autocast (--bf16: LeRobot's --policy.use_amp=true, its mixed precision through accelerate).
channels_last and torch.compile are not among them: lerobot-train has no option for either.

No DDS. Prints a Markdown report; --json writes the numbers.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ..subcommands import Subcommand, run_alone
from . import common as bench_common

VARIANTS = {
    "recipe": [],
    "one-thread": ["--torch-threads", "1"],
    "inline-loading": ["--loader-workers", "0"],
    "bf16-autocast": ["--bf16"],
    "reread-items": ["--reread-items"],
}
# LeRobot's MetricsTracker line, e.g. "... updt_s:2.871 data_s:0.012".
WINDOW = re.compile(r"updt_s:([0-9.]+) data_s:([0-9.]+)")


def windows(log: str) -> list[tuple[float, float]]:
    """(updt_s, data_s) of every logged window of steps, in order."""
    return [(float(update), float(data)) for update, data in WINDOW.findall(log)]


def profile(log: str, skip: int = 1) -> dict:
    """The mean model step and batch wait (s) over the windows after the first `skip`."""
    measured = windows(log)[skip:]
    if not measured:
        raise ValueError(f"lerobot-train logged no more than {skip} window(s) of steps: raise --steps")
    update = sum(u for u, _ in measured) / len(measured)
    data = sum(d for _, d in measured) / len(measured)
    return {"windows": len(measured), "update_s": update, "data_s": data, "step_s": update + data}


def run_variant(args, extra: list[str], output: Path) -> tuple[dict, float]:
    """One short run of the recipe; its profile and wall seconds."""
    command = [str(Path(sys.executable).with_name("so101-learn")), args.policy, "--dataset", str(args.dataset)]
    command += ["--steps", str(args.steps), "--save-every", str(args.steps), "--eval", "0", "--output", str(output)]
    started = time.monotonic()
    done = subprocess.run(command + extra, capture_output=True, text=True)
    wall = time.monotonic() - started
    log = done.stdout + done.stderr
    if done.returncode != 0:
        raise SystemExit(f"so101-bench train_step: {' '.join(command + extra)} failed:\n{log[-3000:]}")
    return profile(log, args.skip), wall


def run(args) -> int:
    if not (args.dataset / "meta" / "info.json").is_file():
        raise SystemExit(f"so101-bench train_step: {args.dataset} is not a LeRobot dataset (no meta/info.json)")
    chosen = args.variant or list(VARIANTS)
    results = {}
    with tempfile.TemporaryDirectory(prefix="so101-train-step-") as scratch:
        for index, name in enumerate(chosen):
            print(f"==> {name}", file=sys.stderr, flush=True)
            numbers, wall = run_variant(args, VARIANTS[name], Path(scratch) / f"run{index}")
            results[name] = {**numbers, "wall_s": wall}
            # As it comes: a slow variant (bf16 without the CPU's support) may be cut short.
            print(f"    {json.dumps(results[name])}", file=sys.stderr, flush=True)
    anchor = results.get("recipe")
    lines = [
        f"## A training step: so101-learn {args.policy} on {args.dataset.name}, {args.steps} steps per variant\n",
        "| variant | model step (updt_s) | batch wait (data_s) | step | steps/s | step / recipe's |",
        "|---|---|---|---|---|---|",
    ]
    for name, r in results.items():
        ratio = f"{r['step_s'] / anchor['step_s']:.2f}" if anchor else "-"
        lines.append(
            f"| {name} | {r['update_s']:.3f} s | {r['data_s']:.3f} s | {r['step_s']:.3f} s | {1 / r['step_s']:.2f} | {ratio} |"
        )
    return bench_common.report(lines, {"policy": args.policy, "steps": args.steps, "variants": results}, args.json)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--bin-dir", type=Path, default=None, help="the built binaries (scripts/bench.sh passes it; unused)")
    p.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    p.add_argument("--dataset", type=Path, required=True, help="the LeRobot dataset the recipe trains on")
    p.add_argument("--policy", choices=["act", "pose_act", "diffusion"], default="act", help="the recipe")
    p.add_argument("--steps", type=int, default=40, help="steps per variant (logged in windows of a tenth)")
    p.add_argument("--skip", type=int, default=1, help="windows left out at the start (default 1: start-up)")
    p.add_argument("--variant", action="append", choices=list(VARIANTS), help="measure only these (repeatable; default: all)")


SUBCOMMAND = Subcommand("a training step's time: model step against batch loading, per lever", add_arguments, run, __doc__)


def main(argv: list[str] | None = None) -> int:
    return run_alone("so101-bench train_step", SUBCOMMAND, argv)


if __name__ == "__main__":
    raise SystemExit(main())
