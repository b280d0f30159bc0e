"""Recipes `act` and `diffusion`: train LeRobot's ACT or Diffusion Policy with lerobot-train on
the state (joint positions and the cube's pose, observation.environment_state) or, given a dataset
with cameras, on joints + images (see VISION below), in settings that fit a CPU, then evaluate the
policy through so101-run-policy in lockstep with the sim node (the stack's real interface) over
--eval seeded episodes. Recipe `pose_act`: the state ACT's settings on the joints and the cube's
pose estimated from the cameras (so101.policies.pose_act), on a camera dataset that records the
pose as the estimator's target; the policy itself reads the joints and the cameras only.

Why these settings (LeRobot's defaults are sized for images on a GPU: 28 s a step on 2 cores):
- ACT: no VAE (the scripted expert's demonstrations have one mode per situation, the VAE's reason
  to be is multimodal human data, and it doubles the cost of a step), a 256-wide transformer with
  2 encoder layers and 1 decoder layer (4 encoder layers and 512 wide by default; with three input
  tokens, width and depth buy nothing), chunks of 20 actions executed whole (0.67 s at 30 Hz:
  long enough to carry the arm through a motion, short enough to react to where the cube is),
  no dropout (0.1 by default: on three input tokens it blurs the cube's pose into grasps that
  miss by millimetres), learning rate 1e-4 annealed to zero (cosine) over 1,500 steps.
- Diffusion: a U-Net of (64, 128, 256) channels instead of (512, 1024, 2048) (the state is 13
  numbers, not image features), a horizon of 16 with 8 actions executed, DDIM with 10 inference
  steps (DDPM's 100 steps make each chunk 10x slower to infer on a CPU), 12,000 steps: each step
  trains one noise level of a chunk; on the STS3215 servos success on tuning seeds was 72 % at
  6,000 steps and 91 % at 12,000 (50 demonstrations; docs/benchmarks.md).
- ACT: every input normalised by its dataset mean and std, the cube's pose too (its z of ~0.77 m
  and a quaternion would otherwise dwarf the joints). Diffusion: joints and actions by min-max
  (NORMALIZE_DIFFUSION says why), the cube's pose by mean and std.
- With cameras (VISION): the backbone from scratch and colour augmentation only.
- lerobot-train runs through so101.learn.train_in_memory: each item is read once and kept (with
  cameras its augmentation applied at each read), where reading it each step took twice the
  model's time on the state and decoding the frames took a core beside the camera step; the same
  weights from the same seed (--reread-items: not).
--policy-arg passes anything else to lerobot-train (e.g. --policy-arg=--policy.dim_model=512).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from ..paths import repo_root
from . import augment
from .accelerate_launch import accelerate_command
from .checkpoints import Checkpoint, CheckpointError, init_problem, last_checkpoint
from .dataset_facts import dataset_cameras, dataset_task, has_cameras
from .eval_recipe import run_policy_command

# ACT: every input and the actions by their mean and std (the cube's pose too: its z of ~0.77 m and a
# quaternion would otherwise dwarf the joints).
NORMALIZE_ALL = '{"VISUAL":"MEAN_STD","STATE":"MEAN_STD","ENV":"MEAN_STD","ACTION":"MEAN_STD"}'
# Diffusion: actions (and joints) into [-1, 1] by their min and max, as LeRobot's own default. The
# sampler clips every denoised chunk to [-1, 1] (clip_sample): under mean/std scaling 29-75 % of the
# demonstrations' actions per joint lie outside it (the gripper's 75 %), so the arm could never
# reach them.
NORMALIZE_DIFFUSION = '{"VISUAL":"MEAN_STD","STATE":"MIN_MAX","ENV":"MEAN_STD","ACTION":"MIN_MAX"}'

PRESETS: dict[str, dict] = {
    "act": {
        "normalization": NORMALIZE_ALL,
        "policy": {
            "use_vae": "false",
            "dim_model": 256,
            "dim_feedforward": 1024,
            "n_encoder_layers": 2,
            "n_decoder_layers": 1,
            "chunk_size": 20,
            "n_action_steps": 20,
            "dropout": 0.0,
        },
        # AdamW at 1e-4 (ACT's own values) annealed to zero over the run: the last checkpoint is
        # the settled one (at a constant rate success swung between 72 and 97 % from one
        # checkpoint to the next: docs/benchmarks.md).
        "training": {
            "use_policy_training_preset": "false",
            "optimizer.type": "adamw",
            "optimizer.lr": 1e-4,
            "optimizer.weight_decay": 1e-4,
            "optimizer.grad_clip_norm": 10,
            "scheduler.type": "cosine_annealing_with_warmup",
            "scheduler.num_warmup_steps": 0,
        },
        # About 8 passes over 50 demonstrations.
        "steps": 1500,
        "batch_size": 64,
    },
    # pose_act (so101.policies.pose_act): the state ACT above, acting on the cube's pose that a
    # small CNN estimates from the cameras, both trained in one run on a camera dataset that also
    # records the pose (demos --cameras ... without --no-environment-state) as the estimator's
    # target; VISION_LENGTH gives its length.
    "pose_act": {
        "normalization": NORMALIZE_ALL,
        "policy": {},  # filled from "act" below
        "training": {},
        "steps": 1500,
        "batch_size": 64,
    },
    "diffusion": {
        "normalization": NORMALIZE_DIFFUSION,
        "policy": {
            "down_dims": "[64,128,256]",
            "horizon": 16,
            "n_action_steps": 8,
            "n_obs_steps": 2,
            "noise_scheduler_type": "DDIM",
            "num_inference_steps": 10,
        },
        # About 60 passes over 50 demonstrations (6,000: 72 % on tuning seeds, 12,000: 91 %).
        "steps": 12000,
        "batch_size": 64,
    },
}


PRESETS["pose_act"]["policy"] = dict(PRESETS["act"]["policy"])
PRESETS["pose_act"]["training"] = dict(PRESETS["act"]["training"])


# VISION: a dataset with cameras (observation.images.*) adds to the preset:
# - the ResNet-18 backbone learns from scratch: ImageNet weights cannot be downloaded offline, and
#   pictures of 96x72 pixels are far from ImageNet's anyway;
# - image augmentation, LeRobot's colour transforms by default (so101.learn.augment says why not
#   its shift, and what --augment adds).
def vision_preset(sets: tuple[str, ...] = (augment.DEFAULT,)) -> tuple[dict, dict]:
    """(policy, training) settings added to either preset for a dataset with cameras, augmented
    by `sets` (so101.learn.augment)."""
    policy = {"pretrained_backbone_weights": "null"}  # ACT's and Diffusion's default: ImageNet weights
    return policy, augment.training_settings(sets)


def augment_sets(text: str) -> tuple[str, ...]:
    """--augment's value, checked as argparse reports a wrong one."""
    try:
        return augment.parse_sets(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from error


# ACT with cameras: its length on this CPU (1.2 steps/s, about 55 minutes). Success on tuning
# seeds was 20 / 23 / 93 % at 1,000 / 2,000 / 3,000 steps: the grasp comes with the learning
# rate's annealing, as for the state (docs/benchmarks.md).
VISION_LENGTH = {"act": {"steps": 4000, "batch_size": 32}, "pose_act": {"steps": 3000, "batch_size": 64}}


def resolve_length(args) -> None:
    """Fills --steps and --batch-size left out: the preset's, or its camera length for a dataset
    with cameras."""
    vision = VISION_LENGTH.get(args.policy_type, {}) if has_cameras(Path(args.dataset)) else {}
    length = {**PRESETS[args.policy_type], **vision}
    args.steps = length["steps"] if args.steps is None else args.steps
    args.batch_size = length["batch_size"] if args.batch_size is None else args.batch_size


def dataset_problem(policy_type: str, dataset: Path) -> str | None:
    """Why the recipe cannot train on `dataset`, or None: pose_act learns the cube's pose from the
    cameras, so its dataset needs both."""
    if policy_type != "pose_act":
        return None
    features = json.loads((dataset / "meta" / "info.json").read_text())["features"]
    if not dataset_cameras(dataset) or "observation.environment_state" not in features:
        return (
            f"{dataset} lacks cameras or the cube's pose: pose_act learns the pose from the cameras, so record the "
            "demos with --cameras and without --no-environment-state (e.g. so101-learn demos --lite --cameras "
            "top:96x72,front:96x72,wrist:96x72 --randomize)"
        )
    return None


def summary(name: str) -> str:
    """The recipe's line in so101-learn --help."""
    if name == "pose_act":
        return (
            "train ACT on the joints and the cube's pose estimated from the cameras (a camera dataset that records the "
            "pose), then evaluate it"
        )
    policy = "ACT" if name == "act" else "Diffusion Policy"
    return f"train LeRobot's {policy} on the state with lerobot-train (CPU-sized), then evaluate it"


def add_arguments(p: argparse.ArgumentParser, name: str) -> None:
    """The options of the recipe `name` (act or diffusion: PRESETS' keys)."""
    preset = PRESETS[name]
    p.add_argument("--dataset", help="a LeRobot dataset directory (so101-learn demos, so101-bag-to-lerobot)")
    vision = VISION_LENGTH.get(name)
    with_cameras = f"; {vision['steps']:,} with cameras" if vision else ""
    p.add_argument("--steps", type=int, default=None, help=f"training steps (default {preset['steps']:,}{with_cameras})")
    with_cameras = f"; {vision['batch_size']} with cameras" if vision else ""
    p.add_argument("--batch-size", type=int, default=None, help=f"batch size (default {preset['batch_size']}{with_cameras})")
    p.add_argument("--save-every", type=int, default=None, help="checkpoint every this many steps (default 1,000)")
    p.add_argument("--device", default=None, help="torch device (cpu, cuda; default cpu, or a resumed run's)")
    p.add_argument(
        "--num-processes",
        type=int,
        default=None,
        help="training processes through LeRobot's multi-GPU path (accelerate launch): one per GPU with --device "
        "cuda; on the CPU, processes sharing the cores (each takes the whole batch: the effective batch is N times it); "
        "default 1, or as many as a resumed run had",
    )
    p.add_argument(
        "--loader-workers",
        type=int,
        default=None,
        help="dataset loader processes per training process (default: none for a dataset without cameras, whose "
        "items stay in memory; with cameras 1 on the CPU, which keeps the frames and applies the augmentation beside "
        "the step, and with --device cuda up to 8, as the CPU's cores allow: a GPU waits on decoding otherwise)",
    )
    p.add_argument(
        "--reread-items",
        action="store_true",
        help="read (and decode) each item from the dataset at every step, as lerobot-train does; by default the "
        "items are kept in memory after their first read, a camera dataset's when its frames fit in half of the "
        "memory available (so101.learn.train_in_memory)",
    )
    p.add_argument("--seed", type=int, default=None, help="training seed (default 1000)")
    p.add_argument(
        "--torch-threads",
        type=int,
        default=None,
        help="torch's CPU threads for training and evaluation (OMP_NUM_THREADS; 1 keeps a shared machine responsive)",
    )
    p.add_argument(
        "--augment",
        type=augment_sets,
        default=None,
        metavar="SETS",
        help=f"image augmentation of a dataset with cameras: a comma list of {', '.join(augment.SETS)}, or none "
        f"(default {augment.DEFAULT}; so101.learn.augment describes each)",
    )
    p.add_argument(
        "--init",
        metavar="CKPT",
        default=None,
        help=f"start from the weights of this {name} checkpoint (.../pretrained_model) instead of from scratch: "
        "fine-tuning on a dataset that grew (so101-learn demos --driver ... --after ...); the settings, optimizer "
        "and learning-rate schedule are a new run's",
    )
    p.add_argument(
        "--bf16",
        action="store_true",
        help="train under bfloat16 autocast (LeRobot's --policy.use_amp=true, kept in the run's config), a camera "
        "policy's convolutions in channels_last: the camera ACT's model step 0.63x on a CPU with AVX512-BF16 and AMX, "
        "but many times slower on one without, which emulates it (docs/benchmarks.md); on a GPU, its autocast",
    )
    p.add_argument("--policy-arg", action="append", default=[], help="one more lerobot-train argument (repeatable)")
    p.add_argument("--output", default=None, help=f"lerobot-train's output directory (default outputs/{name}-<time>/)")
    p.add_argument(
        "--resume",
        metavar="OUTPUT",
        default=None,
        help="continue the interrupted run in OUTPUT from its last checkpoint (LeRobot's resume: weights, optimizer, "
        "learning-rate schedule, data order) instead of starting one; its dataset, batch size, seed, loading of items, "
        "loader processes, device and processes are the run's (--steps lengthens it, --device, --num-processes and "
        "--loader-workers override), then the evaluation as asked",
    )
    p.add_argument("--eval", type=int, default=20, metavar="M", help="then evaluate over M seeded episodes (0: no evaluation)")
    p.add_argument("--eval-seed", type=int, default=1000, help="seed of the first evaluation episode (demos start at 0)")
    p.add_argument(
        "--eval-backend",
        choices=["ros", "inprocess"],
        default="ros",
        help="ros: so101_sim_node in lockstep over DDS (the stack's interface); inprocess: the same core, faster",
    )
    p.add_argument("--eval-videos", type=int, default=10, metavar="K", help="an MP4 of each of the first K episodes")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(policy_type=name)


# A new run's settings left out of its command line (None there: a resumed run takes the run's own).
NEW_RUN_DEFAULTS = {"device": "cpu", "num_processes": 1, "save_every": 1000, "seed": 1000, "augment": (augment.DEFAULT,)}


def fill_new_run_defaults(args) -> None:
    for key, value in NEW_RUN_DEFAULTS.items():
        if getattr(args, key) is None:
            setattr(args, key, value)


def train_command(args, output: Path) -> list[str]:
    """lerobot-train with the preset, every setting spelled out so the command reproduces the run."""
    fill_new_run_defaults(args)
    resolve_length(args)
    dataset = Path(args.dataset).resolve()
    command = [
        f"--dataset.repo_id=local/{dataset.name}",
        f"--dataset.root={dataset}",
        f"--policy.type={args.policy_type}",
        f"--policy.device={args.device}",
        "--policy.push_to_hub=false",
    ]
    preset = PRESETS[args.policy_type]
    command.append(f"--policy.normalization_mapping={preset['normalization']}")
    policy, training = dict(preset["policy"]), dict(preset.get("training", {}))
    if has_cameras(dataset):
        vision_policy, vision_training = vision_preset(args.augment)
        policy.update(vision_policy)
        training.update(vision_training)
    command += [f"--policy.{key}={value}" for key, value in policy.items()]
    command += [f"--{key}={value}" for key, value in training.items()]
    if args.init:
        command.append(f"--policy.pretrained_path={Path(args.init).resolve()}")
    return with_run_settings(command, args, output)


def with_run_settings(command: list[str], args, output: Path) -> list[str]:
    """lerobot-train's arguments completed with the run's length, checkpoints, seed, loaders,
    output and the user's --policy-arg, launched (every recipe that trains with lerobot-train)."""
    command = command + [
        f"--steps={args.steps}",
        f"--batch_size={args.batch_size}",
        f"--save_freq={min(args.save_every, args.steps)}",
        f"--log_freq={max(1, min(100, args.steps // 10))}",
        f"--seed={args.seed}",
        f"--num_workers={loader_workers(args)}",
        "--wandb.enable=false",
        f"--output_dir={output}",
        *precision_settings(args),
        *args.policy_arg,
    ]
    return launched(command, args)


def precision_settings(args) -> list[str]:
    """--bf16 as lerobot-train takes it: LeRobot's mixed precision (accelerate's bf16 autocast on a
    CPU, torch's default autocast type on a GPU), saved in the run's config, so --resume keeps it."""
    # A VLA's recipe (so101.learn.vla) has no --bf16: it sets the policy's own dtype.
    return ["--policy.use_amp=true"] if getattr(args, "bf16", False) else []


def cpu_bf16_problem(device: str, cpu_flags: str) -> str | None:
    """Why --bf16 may slow this run down, or None where it paid (a GPU, or a CPU with AMX-BF16).
    From the flags of /proc/cpuinfo: without AVX512-BF16 bfloat16 is emulated (the camera ACT's
    model step 24 times slower on an AVX2-only host); with AVX512-BF16 but no AMX the step was
    1.44 times slower than float32 on an Intel host (docs/benchmarks.md): a warning, not a refusal,
    since another CPU may differ and so101-bench model_step tells in 20 s."""
    if not device.startswith("cpu"):
        return None
    flags = set(cpu_flags.split())
    if "amx_bf16" in flags:
        return None
    if "avx512_bf16" in flags:
        return (
            "--bf16 on a CPU with AVX512-BF16 but no AMX-BF16: the camera ACT's step was 1.44 times slower than "
            "float32 on such a CPU (docs/benchmarks.md); compare the two on this one with `so101-bench model_step "
            "--dataset D --variant recipe --variant bf16-channels-last` and keep --bf16 only if it is faster"
        )
    return (
        "--bf16 on a CPU without AVX512-BF16 or AMX-BF16: bfloat16 is emulated there, and a camera ACT step took 24 "
        "times as long on such a CPU (docs/benchmarks.md); leave --bf16 out unless a GPU trains"
    )


def cpu_flags() -> str:
    """This CPU's feature flags (/proc/cpuinfo's first `flags` line; empty where there is none)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("flags"):
                return line.partition(":")[2]
    except OSError:
        pass
    return ""


LEROBOT_TRAIN = "lerobot.scripts.lerobot_train"
IN_MEMORY_TRAIN = "so101.learn.train_in_memory"


def can_keep_items(args) -> bool:
    """Whether the run's items may stay in memory (so101.learn.train_in_memory): ACT's or
    Diffusion's (a VLA's is lerobot-train's own; so101.learn.vla). A camera dataset's frames must
    also fit, which the training process checks."""
    return args.policy_type in PRESETS


def items_in_memory(args) -> bool:
    """Whether the run keeps its dataset's items in memory: it can, and --reread-items is not given."""
    return can_keep_items(args) and not args.reread_items


def trainer_module(args) -> str:
    """The module that trains: lerobot-train's own, or the same keeping the dataset's items in
    memory (a Diffusion step on 50 demonstrations: 3x faster on this CPU, docs/benchmarks.md)."""
    return IN_MEMORY_TRAIN if items_in_memory(args) else LEROBOT_TRAIN


def launched(arguments: list[str], args) -> list[str]:
    """lerobot-train's arguments as they run: after lerobot-train (or the in-memory module), or
    after the module in each process accelerate launches for several processes."""
    module = trainer_module(args)
    if args.num_processes > 1:
        return accelerate_command(args.num_processes, module) + arguments
    if module == LEROBOT_TRAIN:
        return [str(Path(sys.executable).with_name("lerobot-train")), *arguments]
    return [sys.executable, "-m", module, *arguments]


def loader_workers(args) -> int:
    """On the CPU one loader process beside the training overlaps reading the next batch with the
    step; a GPU's step is short enough that decoding is the bottleneck (measured on an H100: 14.7
    steps/s bound by loading, 34 ms for the model step), so it gets as many as the cores allow.
    State items kept in memory need none: each is read once, then costs nothing (a loader process
    would keep copies of its own). A camera dataset's kept items keep their loader process: it
    applies the augmentation beside the step, and the same loaders give the same weights."""
    if args.loader_workers is not None:
        return args.loader_workers
    if items_in_memory(args) and not has_cameras(Path(args.dataset)):
        return 0
    if args.device.startswith("cuda"):
        return max(1, min(8, (os.cpu_count() or 2) // max(1, args.num_processes) - 1))
    # Several CPU processes share the cores already, and a loader forked from a process whose
    # gloo group is up can deadlock it (a 3-step run hung for 5 min in the suite).
    return 0 if args.num_processes > 1 else 1


def eval_command(args, checkpoint: Path, eval_dir: Path) -> list[str]:
    # MP4s of the first episodes only: filming costs more than the rest of an episode.
    return run_policy_command(
        str(checkpoint),
        episodes=args.eval,
        seed=args.eval_seed,
        output=str(eval_dir),
        backend=args.eval_backend,
        sim_task=dataset_task(args.dataset),
        videos=min(args.eval, args.eval_videos),
        lite=True,
        device=args.device,
        quiet=args.quiet,
    )


def resume_settings(args) -> tuple[Path, Checkpoint]:
    """For --resume: the run's output directory and last checkpoint, with args' dataset, length,
    batch, device and processes those of the run (--steps, --device, --num-processes override)."""
    name = f"so101-learn {args.policy_type}"
    own = {
        "--dataset": args.dataset,
        "--output": args.output,
        "--batch-size": args.batch_size,
        "--seed": args.seed,
        "--augment": args.augment,
        "--reread-items": True if args.reread_items else None,
    }
    given = [flag for flag, value in own.items() if value is not None]
    if given:
        raise SystemExit(
            f"{name}: --resume continues the run with its own dataset, output, batch size, seed and loading: "
            f"leave out {', '.join(given)}"
        )
    output = Path(args.resume).resolve()
    try:
        checkpoint = last_checkpoint(output)
    except CheckpointError as error:
        raise SystemExit(f"{name}: {error}") from error
    config = checkpoint.config
    if config["policy"]["type"] != args.policy_type:
        trains = config["policy"]["type"]
        raise SystemExit(f"{name}: {output} trains a {trains} policy: resume it with so101-learn {trains}")
    args.dataset, args.batch_size = config["dataset"]["root"], config["batch_size"]
    args.steps = config["steps"] if args.steps is None else args.steps
    if args.device is None:
        args.device = config["policy"]["device"]
    if args.num_processes is None:
        args.num_processes = checkpoint.num_processes or 1
    resume_loading(args, checkpoint)
    if checkpoint.step >= args.steps:
        raise SystemExit(
            f"{name}: {output} has trained {checkpoint.step} steps of {args.steps} already: --steps N, over "
            f"{checkpoint.step}, lengthens it; so101-run-policy {checkpoint.config_file.parent} --eval M evaluates it"
        )
    return output, checkpoint


def resume_loading(args, checkpoint: Checkpoint) -> None:
    """The run's own loading, since another gives weights the uninterrupted run would not reach:
    items kept in memory or read at every step, and its loader processes, unless the run moves to
    another device or number of processes (or --loader-workers says otherwise)."""
    args.reread_items = not checkpoint.items_in_memory
    if args.reread_items and can_keep_items(args):
        print(
            f"so101-learn {args.policy_type}: the checkpoint does not say its run kept its items in memory (a run with "
            "--reread-items, one whose frames did not fit, one started before 2026-11-29, 04:36 UTC, or a camera run "
            "started before 2026-11-29, 12:15 UTC): it resumes with lerobot-train's loading",
            flush=True,
        )
    same_place = args.device == checkpoint.config["policy"]["device"] and args.num_processes == (checkpoint.num_processes or 1)
    if args.loader_workers is None and same_place:
        args.loader_workers = checkpoint.config.get("num_workers")


def resume_command(args, checkpoint: Checkpoint, output: Path) -> list[str]:
    """lerobot-train resuming `checkpoint` into the run's own directory, with the settings a run
    takes on each start given again (length, device, loaders, processes, --policy-arg)."""
    command = [
        f"--config_path={checkpoint.config_file}",
        "--resume=true",
        f"--output_dir={output}",
        f"--steps={args.steps}",
        f"--policy.device={args.device}",
        f"--num_workers={loader_workers(args)}",
    ]
    if args.save_every is not None:
        command.append(f"--save_freq={args.save_every}")
    return launched(command + precision_settings(args) + args.policy_arg, args)


def run(args) -> int:
    name = f"so101-learn {args.policy_type}"
    if args.resume and args.init:
        raise SystemExit(f"{name}: --resume continues a run from its own weights; --init starts a new one from others'")
    if args.resume:
        output, last = resume_settings(args)
        resumed_from = last.step
    else:
        resumed_from = 0
        fill_new_run_defaults(args)
        if not args.dataset:
            raise SystemExit(f"{name}: --dataset is required (or --resume OUTPUT to continue a run)")
        if not (Path(args.dataset) / "meta" / "info.json").is_file():
            raise SystemExit(f"{name}: {args.dataset} is not a LeRobot dataset (no meta/info.json)")
        if problem := dataset_problem(args.policy_type, Path(args.dataset)):
            raise SystemExit(f"{name}: {problem}")
        if args.init and (problem := init_problem(args.policy_type, Path(args.init))):
            raise SystemExit(f"{name}: {problem}")
        resolve_length(args)
        output = Path(args.output or repo_root() / "outputs" / f"{args.policy_type}-{time.strftime('%Y%m%d-%H%M%S')}").resolve()
        if output.exists():
            raise SystemExit(f"{name}: {output} exists already (lerobot-train starts a new run there; --resume continues it)")
    if args.steps <= 0 or args.batch_size <= 0:
        raise SystemExit(f"{name}: --steps and --batch-size must be positive")
    if args.num_processes <= 0 or (args.loader_workers is not None and args.loader_workers < 0):
        raise SystemExit(f"{name}: --num-processes must be positive, --loader-workers not negative")

    if args.bf16 and (problem := cpu_bf16_problem(args.device, cpu_flags())):
        print(f"{name}: warning: {problem}", file=sys.stderr, flush=True)
    environment = dict(os.environ)
    if args.torch_threads:
        environment["OMP_NUM_THREADS"] = str(args.torch_threads)
    command = resume_command(args, last, output) if args.resume else train_command(args, output)
    print("==> " + " ".join(command), flush=True)
    started = time.monotonic()
    if subprocess.run(command, env=environment).returncode != 0:
        raise SystemExit(f"{name}: lerobot-train failed")
    train_s = time.monotonic() - started
    checkpoint = output / "checkpoints" / "last" / "pretrained_model"

    result = None
    if args.eval > 0:
        eval_dir = output / "eval"
        command = eval_command(args, checkpoint, eval_dir)
        print("==> " + " ".join(command), flush=True)
        if subprocess.run(command, env=environment).returncode != 0:
            raise SystemExit(f"{name}: so101-run-policy --eval failed")
        result = json.loads((eval_dir / "eval_info.json").read_text())["aggregated"]

    if args.resume:
        trained = f"trained to step {args.steps} (batch {args.batch_size}), resumed from step {resumed_from}: {args.steps - resumed_from} steps"
    else:
        trained = f"trained {args.steps} steps (batch {args.batch_size})" + (f" from {args.init}" if args.init else "")
    print(f"\nSummary: {args.policy_type} {trained} in {train_s / 60:.1f} min on {args.device}")
    print(f"  policy:  {checkpoint}")
    if result:
        low, high = result["pc_success_ci95"]
        print(
            f"  success: {result['pc_success']:.0f} % over {result['episodes']} episodes (95 % interval {low:.0f}-{high:.0f} %), "
            f"mean reward {result['avg_sum_reward']:.2f}, best {result['best_sum_reward']:.2f}; videos in {output / 'eval'}"
        )
    print(
        f"Evaluate again: scripts/isolated .venv/bin/so101-run-policy {checkpoint} --eval 100 --seed {args.eval_seed} "
        f"--sim-task {dataset_task(args.dataset)}"
    )
    return 0
