"""Recipes `smolvla` and `pi0`: fine-tune a pretrained vision-language-action model (LeRobot's
SmolVLA or pi0) on a dataset with cameras, language-conditioned on each episode's task text, with
lerobot-train --policy.path, then evaluate it through so101-run-policy on each task the dataset
holds.

The weights are the user's to name (--pretrained): a Hub id (lerobot/smolvla_base, lerobot/pi0_base;
downloaded by lerobot-train, which needs the Hub) or a local checkpoint directory (offline). The
pretrained model keeps its own image inputs (smolvla_base: observation.images.camera1..3); the
dataset's cameras are mapped onto them in order (--camera-map to choose), a pretrained input no
camera feeds is left out by the model, and the map travels in the checkpoint, where so101-run-policy
reads it. pi0 starts as LeRobot's documentation has it: a pi0 on the dataset's own cameras with the
pretrained weights, in bfloat16 with gradient checkpointing. Frames go in at the dataset's size
(each checkpoint keeps the dataset's features, dataset_features.json): the model resizes and pads
them itself.

Sizes: both fine-tune on a GPU (LeRobot's reference: SmolVLA 20,000 steps at batch 64 in about 4 h
on an A100). On a CPU only a smoke run is practical (a few steps); docs/learning.md has the numbers.
--policy-arg passes anything else to lerobot-train (e.g. --policy-arg=--policy.freeze_vision_encoder=false).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import time
from pathlib import Path

from .. import contract
from ..evaluate.policy import DATASET_FEATURES_FILE, vla_packages_missing
from ..paths import repo_root
from .dataset_facts import dataset_cameras, dataset_tasks
from .eval_recipe import run_policy_command
from .lerobot_train import with_run_settings

# What each recipe fine-tunes from by default, LeRobot's documented length for it, and how LeRobot's
# documentation starts it: SmolVLA from the pretrained policy whole (--policy.path: its config and
# inputs, the dataset's cameras renamed onto them), pi0 as a new pi0 on the dataset's features
# with the pretrained weights (--policy.type=pi0 --policy.pretrained_path), in bfloat16 with
# gradient checkpointing, vision encoder and backbone trained too.
VLAS: dict[str, dict] = {
    "smolvla": {
        "pretrained": "lerobot/smolvla_base",
        "policy": "SmolVLA",
        "start": "path",
        "steps": 20000,
        "batch_size": 64,
        "settings": {},
    },
    "pi0": {
        "pretrained": "lerobot/pi0_base",
        "policy": "pi0",
        "start": "type",
        "steps": 3000,
        "batch_size": 32,
        "settings": {
            "dtype": "bfloat16",
            "gradient_checkpointing": "true",
            "freeze_vision_encoder": "false",
            "train_expert_only": "false",
        },
    },
}


def summary(name: str) -> str:
    """The recipe's line in so101-learn --help."""
    return f"fine-tune {VLAS[name]['policy']} ({VLAS[name]['pretrained']} or local weights) on a camera dataset's tasks"


def add_arguments(p: argparse.ArgumentParser, name: str) -> None:
    vla = VLAS[name]
    p.add_argument("--dataset", required=True, help="a LeRobot dataset with cameras (so101-learn demos --cameras ...)")
    p.add_argument(
        "--pretrained",
        default=vla["pretrained"],
        help=f"the weights to fine-tune: a Hub id or a local checkpoint directory (default {vla['pretrained']})",
    )
    p.add_argument(
        "--camera-map",
        default=None,
        metavar="CAMERA=INPUT,...",
        help="which pretrained image input each dataset camera feeds, e.g. top=camera1,wrist=camera2 "
        "(default: the dataset's cameras in order onto the inputs no camera shares a name with)",
    )
    p.add_argument("--steps", type=int, default=vla["steps"], help=f"training steps (default {vla['steps']:,}: LeRobot's)")
    p.add_argument("--batch-size", type=int, default=vla["batch_size"], help=f"batch size (default {vla['batch_size']})")
    p.add_argument("--save-every", type=int, default=5000, help="checkpoint every this many steps")
    p.add_argument("--device", default=None, help="torch device (default cuda where there is one, else cpu)")
    p.add_argument("--num-processes", type=int, default=1, help="training processes (accelerate launch): one per GPU")
    p.add_argument("--loader-workers", type=int, default=None, help="dataset loader processes per training process")
    p.add_argument("--seed", type=int, default=1000, help="training seed")
    p.add_argument("--policy-arg", action="append", default=[], help="one more lerobot-train argument (repeatable)")
    p.add_argument("--output", default=None, help=f"lerobot-train's output directory (default outputs/{name}-<time>/)")
    p.add_argument("--eval", type=int, default=10, metavar="M", help="then evaluate over M seeded episodes per task (0: none)")
    p.add_argument("--eval-seed", type=int, default=1000, help="seed of the first evaluation episode")
    p.add_argument("--eval-backend", choices=["ros", "inprocess"], default="inprocess", help="as so101-run-policy --backend")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(policy_type=name)


def pretrained_images(pretrained: str) -> list[str]:
    """The pretrained model's image inputs (observation.images.*), in its config's order."""
    import lerobot.policies  # noqa: F401 - registers the policy types' configs
    from lerobot.configs import FeatureType, PreTrainedConfig

    try:
        config = PreTrainedConfig.from_pretrained(pretrained)
    except Exception as error:  # noqa: BLE001 - a missing directory and an unreachable Hub read the same to a user
        raise SystemExit(
            f"so101-learn: cannot read the pretrained config of {pretrained!r} ({type(error).__name__}: {error})"
        ) from None
    return [key for key, feature in config.input_features.items() if feature.type is FeatureType.VISUAL]


def rename_map(cameras: list[str], inputs: list[str], camera_map: str | None) -> dict[str, str]:
    """Dataset camera key -> pretrained image input (lerobot-train --rename_map). By default a camera
    named as an input keeps it, the others take the free inputs in order; every camera must feed one."""
    if camera_map:
        pairs = [item.split("=", 1) for item in camera_map.split(",") if item]
        if any(len(pair) != 2 for pair in pairs):
            raise SystemExit(f"so101-learn: --camera-map {camera_map!r}: CAMERA=INPUT,... expected")
        mapping = {f"observation.images.{camera}": f"observation.images.{target}" for camera, target in pairs}
        if unknown := sorted(set(mapping) - set(cameras)):
            raise SystemExit(f"so101-learn: --camera-map names cameras the dataset lacks: {unknown} (it has {cameras})")
        if foreign := sorted(set(mapping.values()) - set(inputs)):
            raise SystemExit(f"so101-learn: --camera-map names inputs the pretrained model lacks: {foreign} (it has {inputs})")
        return mapping
    free = [key for key in inputs if key not in cameras]
    unmatched = [camera for camera in cameras if camera not in inputs]
    if len(unmatched) > len(free):
        raise SystemExit(
            f"so101-learn: the dataset's cameras {cameras} outnumber the pretrained model's image inputs {inputs}: "
            "keep fewer (so101-bag-to-lerobot --cameras) or map them (--camera-map)"
        )
    return dict(zip(unmatched, free))


def train_command(args, output: Path, renames: dict[str, str]) -> list[str]:
    """lerobot-train from the pretrained weights, every setting spelled out."""
    dataset = Path(args.dataset).resolve()
    vla = VLAS[args.policy_type]
    if vla["start"] == "path":
        start = [f"--policy.path={args.pretrained}", f"--rename_map={json.dumps(renames)}"]
    else:
        start = [f"--policy.type={args.policy_type}", f"--policy.pretrained_path={args.pretrained}"]
    command = [
        *start,
        f"--dataset.repo_id=local/{dataset.name}",
        f"--dataset.root={dataset}",
        f"--policy.device={args.device}",
        "--policy.push_to_hub=false",
        *(f"--policy.{key}={value}" for key, value in vla["settings"].items()),
    ]
    return with_run_settings(command, args, output)


def keep_dataset_features(dataset: Path, output: Path) -> None:
    """Each checkpoint gets the dataset's features beside its weights (so101-run-policy's frame
    sizes wherever the checkpoint goes: the pretrained inputs say 256x256)."""
    features = json.loads((dataset / "meta" / "info.json").read_text())["features"]
    for checkpoint in (output / "checkpoints").glob("*/pretrained_model"):
        (checkpoint / DATASET_FEATURES_FILE).write_text(json.dumps(features, indent=1))


def run(args) -> int:
    name = args.policy_type
    if missing := vla_packages_missing(name, f"so101-learn {name}"):
        raise SystemExit(f"so101-learn {name}: {missing}")
    if args.steps <= 0 or args.batch_size <= 0 or args.num_processes <= 0:
        raise SystemExit(f"so101-learn {name}: --steps, --batch-size and --num-processes must be positive")
    dataset = Path(args.dataset)
    if not (dataset / "meta" / "info.json").is_file():
        raise SystemExit(f"so101-learn {name}: {dataset} is not a LeRobot dataset (no meta/info.json)")
    cameras = dataset_cameras(dataset)
    if not cameras:
        raise SystemExit(f"so101-learn {name}: {dataset} has no cameras; a VLA sees (so101-learn demos --cameras ...)")
    if args.device is None:
        import torch

        args.device = "cuda" if torch.cuda.is_available() else "cpu"
    if VLAS[name]["start"] == "path":
        renames = rename_map(cameras, pretrained_images(args.pretrained), args.camera_map)
    elif args.camera_map:
        raise SystemExit(f"so101-learn {name}: --camera-map is for SmolVLA; {name} takes the dataset's cameras as named")
    else:
        renames = {}
    output = Path(args.output or repo_root() / "outputs" / f"{name}-{time.strftime('%Y%m%d-%H%M%S')}")
    if output.exists():
        raise SystemExit(f"so101-learn {name}: {output} exists already (lerobot-train starts a new run there)")

    command = train_command(args, output, renames)
    print("==> " + " ".join(command), flush=True)
    started = time.monotonic()
    if subprocess.run(command, env=dict(os.environ)).returncode != 0:
        raise SystemExit(f"so101-learn {name}: lerobot-train failed")
    train_s = time.monotonic() - started
    checkpoint = output / "checkpoints" / "last" / "pretrained_model"
    keep_dataset_features(dataset, output)

    results = {}
    tasks = dataset_tasks(dataset) or ["cube_to_bin"]
    for task in tasks if args.eval > 0 else []:
        eval_dir = output / "eval" / task
        command = run_policy_command(
            str(checkpoint),
            episodes=args.eval,
            seed=args.eval_seed,
            output=str(eval_dir),
            backend=args.eval_backend,
            sim_task=task,
            videos=min(args.eval, 2),
            lite=True,
            device=args.device,
            quiet=args.quiet,
        )
        print("==> " + " ".join(command), flush=True)
        if subprocess.run(command).returncode != 0:
            raise SystemExit(f"so101-learn {name}: so101-run-policy --eval failed on {task}")
        results[task] = json.loads((eval_dir / "eval_info.json").read_text())["aggregated"]

    print(
        f"\nSummary: {name} from {args.pretrained}, {args.steps} steps (batch {args.batch_size}) in {train_s / 60:.1f} min on {args.device}"
    )
    print(f"  cameras: {', '.join(f'{k} -> {v}' for k, v in renames.items()) or 'as named'}")
    print(f"  policy:  {checkpoint}")
    for task, result in results.items():
        low, high = result["pc_success_ci95"]
        print(
            f"  {task} ({contract.TASKS[task].description!r}): {result['pc_success']:.0f} % over "
            f"{result['episodes']} episodes (95 % interval {low:.0f}-{high:.0f} %)"
        )
    return 0
