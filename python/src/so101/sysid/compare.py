"""`so101-sysid compare`: any recorded episode's commands replayed in the simulation (from where
the arm started), and how far the simulated joints and gripper land from the recorded ones: per
joint RMS and max (rad), at the gripper (mm), for each servo model asked for (the preset before a
fit, the fitted file after)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .. import contract
from ..dataset.bags import BagError, episode_dirs, read_episode
from ..envs.inprocess import default_scene
from ..sim_options import DEFAULT_SERVO_MODEL, servo_params_argument

REPLAY_RATE = 100.0  # control periods per second of the replay


def add_arguments(p) -> None:
    p.add_argument("bags", help="an episode bag, or a directory of them (any recording of the arm)")
    p.add_argument(
        "--servo-params",
        action="append",
        type=servo_params_argument,
        default=None,
        help=f"a servo model to replay with (repeatable): sts3215, gain80 or a parameter file (default: {DEFAULT_SERVO_MODEL})",
    )
    p.add_argument("--tasks", default=None, help="only episodes whose task starts with this")
    p.add_argument("--json", default=None, help="also write the numbers to this file")


def replay(episode, servo_params: str) -> dict:
    """The gap of one episode replayed with `servo_params`."""
    import so101_native

    states = episode.joint_states
    times = np.asarray(states.times)
    recorded = np.asarray(states.values, dtype=np.float64)
    goal_times = np.asarray(episode.joint_commands.times)
    goals = np.asarray(episode.joint_commands.values, dtype=np.float64)
    world = so101_native.World(default_scene(), lite=True, control_rate=REPLAY_RATE, servo_params=servo_params)
    world.reset(0)
    world.place_arm(recorded[0])
    steps = int((times[-1] - times[0]) * REPLAY_RATE)
    simulated = np.empty((steps, 6))
    at = times[0] + (np.arange(steps) + 1) / REPLAY_RATE
    for k in range(steps):
        sent = np.searchsorted(goal_times, at[k] - 1.0 / REPLAY_RATE, side="right") - 1
        target = goals[sent] if sent >= 0 else recorded[0]
        world.step(target)
        simulated[k] = world.observe()[0][:6]
    real = np.column_stack([np.interp(at, times, recorded[:, j]) for j in range(6)])
    gap = simulated - real
    tip = so101_native.grasp_positions(simulated) - so101_native.grasp_positions(real)
    tip_mm = 1000 * np.linalg.norm(tip, axis=1)
    return {
        "rms_rad": np.sqrt(np.mean(gap**2, axis=0)).tolist(),
        "max_rad": np.abs(gap).max(axis=0).tolist(),
        "gripper_rms_mm": float(np.sqrt(np.mean(tip_mm**2))),
        "gripper_max_mm": float(tip_mm.max()),
        "seconds": float(steps / REPLAY_RATE),
    }


def run(args) -> int:
    models = args.servo_params or [DEFAULT_SERVO_MODEL]
    results = {}
    for path in episode_dirs([Path(args.bags)]):
        try:
            episode = read_episode(path, cameras=[])
        except BagError as error:
            print(f"so101-sysid compare: skipped {error}")
            continue
        if args.tasks and not (episode.task or "").startswith(args.tasks):
            continue
        results[path.name] = {"task": episode.task, **{model: replay(episode, model) for model in models}}
    if not results:
        raise SystemExit(f"so101-sysid compare: no episode to replay in {args.bags}")
    header = " | ".join(f"{Path(m).name}: RMS / max (mrad), gripper RMS / max (mm)" for m in models)
    print(f"| episode | task | {header} |")
    print("|---|---|" + "---|" * len(models))
    for name, result in results.items():
        cells = []
        for model in models:
            r = result[model]
            joints = ", ".join(f"{1000 * rms:.1f}/{1000 * peak:.1f}" for rms, peak in zip(r["rms_rad"], r["max_rad"]))
            cells.append(f"{joints}; {r['gripper_rms_mm']:.2f}/{r['gripper_max_mm']:.2f}")
        print(f"| {name} | {result['task']} | " + " | ".join(cells) + " |")
    print("(joints in the order " + ", ".join(contract.JOINT_NAMES) + ")")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
    return 0
