#!/usr/bin/env python3
"""The camera ACT's model step in this process, under the levers lerobot-train has no option for:
the recipe's policy (so101-learn act's preset with the dataset's cameras, so101.learn.lerobot_train)
built by LeRobot, one forward, backward and AdamW step on a batch of the recipe's size, timed over
--steps after two warm-up steps. The anchor, in the same run: the recipe as lerobot-train runs it
(float32, contiguous images). The inputs are random: the step's cost does not depend on the pixels.

Variants:
- channels-last: the model and images in channels_last memory format (oneDNN's preferred layout);
- compile: torch.compile of the policy's forward (the default inductor backend);
- bf16-autocast: the step under CPU autocast to bfloat16 (emulated without AVX512-BF16/AMX);
- bf16-channels-last: both of the above (oneDNN's bf16 convolutions, AMX's where the CPU has it, prefer
  channels_last);
- small-images: every camera at two thirds of the dataset's size (96x72 -> 64x48);
- two-cameras: the dataset's first and last camera only (top and wrist for the recipe's three).
The last two change what the policy sees: their success is a training's question, not this one's.
Every variant steps as lerobot-train's update_policy does (AdamW with the recipe's rate and weight
decay, gradients clipped to the recipe's norm).

No DDS, no dataset reading (its meta/info.json gives the shapes). Prints a Markdown report; --json
writes the numbers. so101-bench train_step measures the whole step as lerobot-train runs it.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ..subcommands import Subcommand, run_alone
from . import common as bench_common

VARIANTS = ("recipe", "channels-last", "compile", "bf16-autocast", "bf16-channels-last", "small-images", "two-cameras")
CHANNELS_LAST = ("channels-last", "bf16-channels-last")
BF16_AUTOCAST = ("bf16-autocast", "bf16-channels-last")


def setting(value):
    """A preset's value as lerobot-train's command line spells it ("false", "[64,128,256]",
    "null", 256), as the Python value the config takes."""
    try:
        return json.loads(str(value))
    except json.JSONDecodeError:
        return value


def camera_shapes(dataset: Path) -> dict[str, tuple[int, int, int]]:
    """The dataset's cameras and their (channels, height, width), from its meta/info.json."""
    from ..learn.dataset_facts import dataset_cameras

    cameras = dataset_cameras(dataset)
    if not cameras:
        raise SystemExit(f"so101-bench model_step: {dataset} has no cameras: the levers measured here are the images'")
    features = json.loads((dataset / "meta" / "info.json").read_text())["features"]
    shapes = {}
    for key in cameras:
        height, width, channels = features[key]["shape"]
        shapes[key] = (channels, height, width)
    return shapes


def variant_shapes(name: str, shapes: dict[str, tuple[int, int, int]]) -> dict[str, tuple[int, int, int]]:
    """The cameras a variant's policy sees (two-cameras: only for a dataset of more than two)."""
    if name == "small-images":
        return {key: (c, h * 2 // 3, w * 2 // 3) for key, (c, h, w) in shapes.items()}
    if name == "two-cameras":
        if len(shapes) <= 2:
            raise ValueError(f"the dataset has {len(shapes)} camera(s): two-cameras would measure the recipe again")
        keys = list(shapes)
        return {key: shapes[key] for key in (keys[0], keys[-1])}
    return dict(shapes)


def build_policy(shapes: dict[str, tuple[int, int, int]]):
    """so101-learn act's policy for a dataset with these cameras and the arm's joints."""
    from lerobot.configs.types import FeatureType, PolicyFeature
    from lerobot.policies.act.configuration_act import ACTConfig
    from lerobot.policies.act.modeling_act import ACTPolicy

    from .. import contract
    from ..learn.lerobot_train import PRESETS, vision_preset

    joints = len(contract.JOINT_NAMES)
    inputs = {"observation.state": PolicyFeature(type=FeatureType.STATE, shape=(joints,))}
    inputs |= {key: PolicyFeature(type=FeatureType.VISUAL, shape=shape) for key, shape in shapes.items()}
    outputs = {"action": PolicyFeature(type=FeatureType.ACTION, shape=(joints,))}
    options = {**PRESETS["act"]["policy"], **vision_preset()[0]}
    config = ACTConfig(
        input_features=inputs, output_features=outputs, device="cpu", **{k: setting(v) for k, v in options.items()}
    )
    return ACTPolicy(config)


@dataclass
class TrainingStep:
    """One variant's training step, ready to run: the policy, a batch, and how the step calls it."""

    policy: object
    batch: dict
    forward: Callable
    autocast: contextlib.AbstractContextManager
    optimizer: object
    grad_clip_norm: float

    def __call__(self) -> None:
        import torch

        with self.autocast:
            loss, _ = self.forward(self.batch)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(self.policy.parameters(), self.grad_clip_norm)
        self.optimizer.step()
        self.optimizer.zero_grad()


def prepare(name: str, shapes: dict[str, tuple[int, int, int]], batch_size: int) -> TrainingStep:
    """The variant's step: the recipe's policy, a random batch of its inputs, and AdamW with the
    recipe's rate, weight decay and gradient clipping (as lerobot-train's update_policy steps)."""
    import torch

    from ..learn.lerobot_train import PRESETS

    torch.manual_seed(0)
    seen = variant_shapes(name, shapes)
    policy = build_policy(seen)
    policy.train()
    chunk, joints = policy.config.chunk_size, policy.config.output_features["action"].shape[0]
    batch = {
        "observation.state": torch.randn(batch_size, joints),
        "action": torch.randn(batch_size, chunk, joints),
        "action_is_pad": torch.zeros(batch_size, chunk, dtype=torch.bool),
    }
    batch |= {key: torch.rand(batch_size, *shape) for key, shape in seen.items()}
    if name in CHANNELS_LAST:
        policy = policy.to(memory_format=torch.channels_last)
        batch |= {key: batch[key].contiguous(memory_format=torch.channels_last) for key in seen}
    training = PRESETS["act"]["training"]
    optimizer = torch.optim.AdamW(
        policy.parameters(), lr=training["optimizer.lr"], weight_decay=training["optimizer.weight_decay"]
    )
    return TrainingStep(
        policy=policy,
        batch=batch,
        forward=torch.compile(policy.forward) if name == "compile" else policy.forward,
        autocast=torch.autocast("cpu", dtype=torch.bfloat16) if name in BF16_AUTOCAST else contextlib.nullcontext(),
        optimizer=optimizer,
        grad_clip_norm=training["optimizer.grad_clip_norm"],
    )


def measure(name: str, shapes: dict[str, tuple[int, int, int]], batch_size: int, steps: int) -> float:
    """Mean seconds of one training step of the variant, after two warm-up steps."""
    step = prepare(name, shapes, batch_size)
    for _ in range(2):
        step()
    started = time.perf_counter()
    for _ in range(steps):
        step()
    return (time.perf_counter() - started) / steps


def run(args) -> int:
    import torch

    if not (args.dataset / "meta" / "info.json").is_file():
        raise SystemExit(f"so101-bench model_step: {args.dataset} is not a LeRobot dataset (no meta/info.json)")
    if args.steps <= 0 or args.batch_size <= 0:
        raise SystemExit("so101-bench model_step: --steps and --batch-size must be positive")
    shapes = camera_shapes(args.dataset)
    chosen = args.variant or list(VARIANTS)
    results = {}
    for name in chosen:
        try:
            variant_shapes(name, shapes)
        except ValueError as why:
            print(f"==> {name}: left out ({why})", file=sys.stderr, flush=True)
            continue
        print(f"==> {name}", file=sys.stderr, flush=True)
        results[name] = {"step_s": measure(name, shapes, args.batch_size, args.steps), "cameras": variant_shapes(name, shapes)}
        print(f"    {results[name]['step_s']:.3f} s", file=sys.stderr, flush=True)
    anchor = results.get("recipe")
    sizes = ", ".join(f"{key.rsplit('.', 1)[-1]} {w}x{h}" for key, (_, h, w) in shapes.items())
    lines = [
        f"## The camera ACT's model step: batch {args.batch_size}, {sizes}, {args.steps} steps per variant, "
        f"{torch.get_num_threads()} torch threads\n",
        "| variant | model step | step / recipe's |",
        "|---|---|---|",
    ]
    for name, r in results.items():
        ratio = f"{r['step_s'] / anchor['step_s']:.2f}" if anchor else "-"
        lines.append(f"| {name} | {r['step_s']:.3f} s | {ratio} |")
    numbers = {"batch_size": args.batch_size, "steps": args.steps, "variants": results}
    return bench_common.report(lines, numbers, args.json)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--bin-dir", type=Path, default=None, help="the built binaries (scripts/bench.sh passes it; unused)")
    p.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    p.add_argument("--dataset", type=Path, required=True, help="a LeRobot dataset with cameras (its shapes only)")
    p.add_argument("--batch-size", type=int, default=32, help="the batch (default 32: the camera recipe's)")
    p.add_argument("--steps", type=int, default=5, help="timed steps per variant, after two warm-up steps")
    p.add_argument("--variant", action="append", choices=list(VARIANTS), help="measure only these (repeatable; default: all)")


SUBCOMMAND = Subcommand("the camera ACT's model step under levers lerobot-train cannot reach", add_arguments, run, __doc__)


def main(argv: list[str] | None = None) -> int:
    return run_alone("so101-bench model_step", SUBCOMMAND, argv)


if __name__ == "__main__":
    raise SystemExit(main())
