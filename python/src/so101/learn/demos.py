"""Recipe `demos`: record N demonstrations of the scripted expert through the stack (so101-launch:
sim node, teleop_node's expert, recorder_node, one bag per episode) and convert the bags into a
LeRobot dataset (so101-bag-to-lerobot) with observation.environment_state, the cube's pose.

Without cameras (the default: state-based policies need none) the sim runs 8x real time and
50 episodes take about a minute to record and one to convert on 2 cores. The expert's noise
(teleop_node --waypoint-noise / --action-noise) makes the demonstrations cover more than one
path per cube placement; failed expert episodes stay out of the dataset unless --keep-failures.

For a camera policy: --cameras top:96x72,front:96x72,wrist:96x72 --lite --no-environment-state
(small cameras of the scene without meshes, rendered at the size the policy sees, and no cube pose:
the policy must find the cube in the pictures). 100 such episodes took 3.6 min to record and 3.4
to convert.

--backend inprocess records the same demonstrations without ROS, straight into the dataset,
--workers N processes in parallel (so101.learn.demos_inprocess); the stack's path stays the default.
In-process only, --perturb SIGMA pushes the arm off the expert's path (so101.learn.perturbation),
--missed-grasps FRACTION keeps that share of episodes from a regrasp after a grasp placed beside the
cube on purpose (so101.learn.missed_grasps),
--driver CKPT lets a trained policy send the arm while the expert's targets are recorded, and
--after DATASET puts a dataset's episodes before the new ones (DAgger: so101.learn.dagger).
"""

from __future__ import annotations

import argparse
import re
import shlex
import subprocess
import sys
import time
from pathlib import Path

from .. import contract, sim_options
from ..paths import repo_root
from ..stack.launch_plan import LOCKSTEP, speed_value
from .dagger import check_share
from .missed_grasps import check_fraction
from .perturbation import check_sigma

REPO_ID = "local/so101_demos"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--episodes", type=int, default=50, help="demonstrations to record")
    p.add_argument("--task", choices=list(contract.TASKS), default="cube_to_bin", help="the task the expert demonstrates")
    p.add_argument(
        "--backend",
        choices=["ros", "inprocess"],
        default="ros",
        help="ros: through the stack (sim node, teleop_node's expert, recorder, bags, conversion); inprocess: the "
        "same simulation and expert in this machine's processes, written straight into the dataset",
    )
    p.add_argument("--workers", type=int, default=1, help="--backend inprocess: processes recording in parallel")
    p.add_argument("--seed", type=int, default=0, help="seed of the sim's cube placements and the expert's noise")
    p.add_argument("--waypoint-noise", type=float, default=0.005, help="expert: noise on each waypoint's position (m)")
    p.add_argument("--action-noise", type=float, default=0.01, help="expert: noise on every joint target (rad)")
    p.add_argument(
        "--perturb",
        type=float,
        default=0.0,
        metavar="SIGMA",
        help="--backend inprocess: push the arm off the expert's path by smooth joint offsets of SIGMA rad while the "
        "jaws are open, recording the expert's own targets (DART: states beside the expert's, and the way back)",
    )
    p.add_argument(
        "--missed-grasps",
        type=float,
        default=0.0,
        metavar="FRACTION",
        help="--backend inprocess: in this share of the episodes the expert is told the cube lies 2-3.5 cm off, "
        "grasps there, and grasps again where it is; those episodes are kept from the regrasp on (recoveries)",
    )
    p.add_argument(
        "--driver",
        default=None,
        metavar="CKPT",
        help="--backend inprocess: a trained policy (a LeRobot checkpoint) sends the arm, the dataset records the "
        "expert's targets from where it goes (DAgger: the states a policy's own errors lead to)",
    )
    p.add_argument(
        "--driver-share",
        type=float,
        default=1.0,
        metavar="A",
        help="--driver: the arm is sent the expert's target moved A of the way to the policy's (default 1: the policy's)",
    )
    p.add_argument(
        "--after",
        type=Path,
        default=None,
        metavar="DATASET",
        help="--backend inprocess: the new dataset holds this dataset's episodes, then the new ones (DAgger's "
        "aggregate; the same cameras, pose and action space)",
    )
    p.add_argument(
        "--cameras",
        default="none",
        help=f'cameras to record, the sim\'s --cameras notation ("none", "top:128x96", "{",".join(contract.CAMERA_NAMES)}")',
    )
    p.add_argument(
        "--no-environment-state",
        action="store_true",
        help="leave the cube's pose out of the dataset (a camera policy must see the cube, as on a real arm)",
    )
    p.add_argument(
        "--lite",
        action="store_true",
        help="the sim's lite scene (no meshes), far faster to render on a CPU; a camera policy trained on it is "
        "evaluated on it too (so101-run-policy --lite, as the recipes do)",
    )
    p.add_argument(
        "--action-space",
        choices=["joint", "ee"],
        default="joint",
        help="the dataset's action: joint targets, or the end-effector targets they reach, with "
        "observation.ee_state (so101-bag-to-lerobot --action-space)",
    )
    sim_options.add_arguments(p)
    p.add_argument(
        "--speed",
        type=speed_value,
        default=None,
        help="sim speed (default 8 without cameras, else 4), or 'lockstep': the sim steps once per command of the "
        "expert, which sees every period's state, so the recording repeats for one seed whatever the machine's load",
    )
    p.add_argument("--keep-failures", action="store_true", help="keep episodes the expert failed")
    p.add_argument("--repo-id", default=REPO_ID, help="the dataset's repo id")
    p.add_argument("--output", default=None, help="directory for bags/, dataset/ and logs/ (default runs/demos-<time>/)")


def launch_command(args, output: Path) -> list[str]:
    """so101-launch with the expert and the recorder (it isolates DDS by itself)."""
    speed = args.speed or (8.0 if args.cameras == "none" else 4.0)
    teleop = f"--waypoint-noise {args.waypoint_noise} --action-noise {args.action_noise}"
    return [
        sys.executable,
        "-m",
        "so101.stack.launch",
        "--robot=sim",
        "--control=expert",
        f"--episodes={args.episodes}",
        f"--task={args.task}",
        f"--seed={args.seed}",
        "--record",
        f"--bags={output / 'bags'}",
        f"--log-dir={output / 'logs'}",
        f"--speed={speed}" if speed == LOCKSTEP else f"--speed={speed:g}",
        f"--sim-args=--cameras {shlex.quote(args.cameras)}"
        + (" --lite" if args.lite else "")
        + f" --servo-params {shlex.quote(args.servo_params)} --randomize {shlex.quote(args.randomize)}"
        + (f" --camera-poses {shlex.quote(args.camera_poses)}" if args.camera_poses else ""),
        f"--teleop-args={teleop}",
    ]


def convert_command(args, output: Path) -> list[str]:
    command = [sys.executable, "-m", "so101.dataset.convert", str(output / "bags"), "--output", str(output / "dataset")]
    command += ["--repo-id", args.repo_id, "--action-space", args.action_space]
    if args.no_environment_state:
        command.append("--no-environment-state")
    return command + ([] if args.keep_failures else ["--successful-only"])


def run(args) -> int:
    if args.episodes <= 0:
        raise SystemExit("so101-learn demos: --episodes must be positive")
    try:
        check_sigma(args.perturb)
        check_fraction(args.missed_grasps)
    except ValueError as error:
        raise SystemExit(f"so101-learn demos: {error}") from None
    in_process_only = (
        (args.perturb > 0, "--perturb"),
        (args.missed_grasps > 0, "--missed-grasps"),
        (args.driver, "--driver"),
        (args.after, "--after"),
    )
    for given, option in in_process_only:
        if given and args.backend != "inprocess":
            raise SystemExit(f"so101-learn demos: {option} works in-process only (--backend inprocess)")
    if args.perturb > 0 and args.driver:
        raise SystemExit("so101-learn demos: --perturb or --driver: the arm is pushed by noise or sent by a policy, not both")
    try:
        check_share(args.driver_share)
    except ValueError as error:
        raise SystemExit(f"so101-learn demos: {error}") from None
    if args.workers <= 0 or (args.workers > 1 and args.backend != "inprocess"):
        raise SystemExit("so101-learn demos: --workers N (N >= 1) records in parallel with --backend inprocess only")
    output = Path(args.output or repo_root() / "runs" / f"demos-{time.strftime('%Y%m%d-%H%M%S')}")
    if (output / "dataset").exists():
        raise SystemExit(f"so101-learn demos: {output / 'dataset'} exists already")
    if args.backend == "inprocess":
        return run_inprocess(args, output)
    output.mkdir(parents=True, exist_ok=True)

    started = time.monotonic()
    print(f"==> recording {args.episodes} expert demonstration(s) into {output / 'bags'}", flush=True)
    launched = subprocess.run(launch_command(args, output), stdout=subprocess.PIPE, text=True)
    # The launcher prints one line per recorded episode: show them as they were, count successes.
    recorded = [line for line in launched.stdout.splitlines() if f"recorded {contract.EPISODE_DEFAULT_PREFIX}_" in line]
    print("\n".join(recorded))
    if launched.returncode != 0:
        print(launched.stdout[-4000:], file=sys.stderr)
        raise SystemExit(f"so101-learn demos: so101-launch failed (exit {launched.returncode}); logs in {output / 'logs'}")
    recorded_s = time.monotonic() - started

    print(f"==> converting into {output / 'dataset'}", flush=True)
    converted = subprocess.run(convert_command(args, output), stdout=subprocess.PIPE, text=True)
    print(converted.stdout, end="")
    if converted.returncode != 0:
        raise SystemExit(f"so101-learn demos: so101-bag-to-lerobot failed (exit {converted.returncode})")
    summary = re.search(r"^\d+ episode\(s\).*$", converted.stdout, re.MULTILINE)
    successes = sum("(success)" in line for line in recorded)
    print(
        f"\nSummary: {len(recorded)} demonstration(s) recorded, {successes} successful, in {recorded_s:.0f} s; "
        f"dataset: {summary.group(0) if summary else '?'}\n"
        f"  dataset: {output / 'dataset'} (repo id {args.repo_id})\n"
        f"Next: so101-learn act --dataset {output / 'dataset'}"
    )
    return 0


def run_inprocess(args, output: Path) -> int:
    from ..dataset.check import run as check_dataset
    from . import demos_inprocess

    try:
        cameras = demos_inprocess.camera_sizes(args.cameras)
    except ValueError as error:
        raise SystemExit(f"so101-learn demos: {error}") from None
    options = demos_inprocess.Options(
        seed=args.seed,
        waypoint_noise=args.waypoint_noise,
        action_noise=args.action_noise,
        cameras=cameras,
        lite=args.lite,
        environment_state=not args.no_environment_state,
        keep_failures=args.keep_failures,
        perturb=args.perturb,
        missed_grasps=args.missed_grasps,
        driver=args.driver,
        driver_share=args.driver_share,
        servo_params=args.servo_params,
        randomize=args.randomize,
        camera_poses=args.camera_poses,
        repo_id=args.repo_id,
        task=args.task,
        action_space=args.action_space,
    )
    if args.after is not None and (problem := demos_inprocess.features_problem(args.after, options)):
        raise SystemExit(f"so101-learn demos: --after {problem}")
    if args.driver:
        from ..evaluate.policy import PolicyError
        from .dagger import load_driver

        try:  # here first, so that a checkpoint that cannot drive is refused before the workers start
            load_driver(args.driver, args.driver_share, cameras)
        except PolicyError as error:
            raise SystemExit(f"so101-learn demos: --driver: {error}") from None
    output.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    workers = min(args.workers, args.episodes)
    print(
        f"==> recording {args.episodes} expert demonstration(s) in-process on {workers} worker(s) into {output / 'dataset'}",
        flush=True,
    )
    results = demos_inprocess.record(options, args.episodes, workers, output / "dataset", after=args.after)
    for result in results:
        verdict = "success" if result.success else "failure"
        kept = "" if result.kept else ", left out"
        print(f"{result.label}: {result.frames} frames ({verdict}{kept}): {result.note}")
    kept = [r for r in results if r.kept]
    after = (demos_inprocess.episode_count(args.after), args.after) if args.after else None
    print("\n" + inprocess_summary(results, time.monotonic() - started, after))
    if not kept:
        raise SystemExit("so101-learn demos: no episode to keep (--keep-failures keeps the failed ones)")
    if check_dataset(output / "dataset"):
        raise SystemExit(f"so101-learn demos: the dataset check found problems in {output / 'dataset'}")
    print(f"  dataset: {output / 'dataset'} (repo id {args.repo_id})\nNext: so101-learn act --dataset {output / 'dataset'}")
    return 0


def inprocess_summary(results, seconds: float, after: tuple[int, Path] | None = None) -> str:
    """The in-process recording's summary line. A regrasp counts beside the success it led to:
    a driven or perturbed episode can regrasp and still fail."""
    successes = [r for r in results if r.success]
    kept = [r for r in results if r.kept]
    regrasped = sum(r.regrasps > 0 for r in results)
    recoveries = sum(r.kept and r.missed_grasp is not None for r in results)
    return (
        f"Summary: {len(results)} demonstration(s) played, {len(successes)} successful "
        f"({sum(r.regrasps > 0 for r in successes)} of them after a regrasp; {regrasped} regrasped in all), "
        f"{len(kept)} kept ({sum(r.frames for r in kept)} frames), in {seconds:.0f} s "
        f"({60 * len(results) / max(seconds, 1e-9):.1f}/min)"
        + (f", after the {after[0]} episode(s) of {after[1]}" if after else "")
        + (f"; {recoveries} kept from a regrasp after a grasp beside the cube" if recoveries else "")
    )
