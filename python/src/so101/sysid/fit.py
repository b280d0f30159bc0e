"""`so101-sysid fit`: per joint, the servo model's gain, damping, dry friction, armature, latency
and dead zone that make its replay of the goals `record` sent match the positions it read
(so101_core::servo::identify, through so101_native); written as a parameter file."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from .. import contract
from ..dataset.bags import BagError, episode_dirs, read_episode
from ..sim_options import DEFAULT_SERVO_MODEL, servo_params_argument
from .record import HELD_OUT_SUFFIX, TASK_PREFIX


def add_arguments(p) -> None:
    p.add_argument("bags", help="the bags of so101-sysid record")
    p.add_argument("--output", required=True, help="the parameter file to write (.json)")
    p.add_argument(
        "--base",
        type=servo_params_argument,
        default=DEFAULT_SERVO_MODEL,
        help=f"start from these parameters: {DEFAULT_SERVO_MODEL} or a parameter file",
    )
    p.add_argument("--iterations", type=int, default=400, help="Nelder-Mead iterations per round")


def joint_series(episode, joint: int) -> tuple[np.ndarray, np.ndarray]:
    """(goals, positions) of one joint as (time s, rad) rows from the first position read: the
    goal in force at that instant first.

    A goal reaches the servo in the driver's next cycle, which reads the positions and then
    writes the goals (record sends each goal just after a cycle ended, so which cycle is never in
    doubt): its time is that cycle's stamp. Its value is rounded to whole encoder ticks, as the
    driver writes it."""
    states = episode.joint_states
    start = states.times[0]
    state_times = np.asarray(states.times)
    samples = np.array([(t - start, values[joint]) for t, values in zip(states.times, states.values)])
    written = np.searchsorted(state_times, np.asarray(episode.joint_commands.times), side="left")
    goals = [
        (state_times[min(index, len(state_times) - 1)] - start, values[joint])
        for index, values in zip(written, episode.joint_commands.values)
    ]
    goals = on_the_encoder_grid(goals, samples[:, 1])
    before = [goal for goal in goals if goal[0] <= 0.0]
    after = [goal for goal in goals if goal[0] > 0.0]
    first = [(0.0, before[-1][1])] if before else [(0.0, samples[0, 1])]
    return np.array(first + after), samples


def on_the_encoder_grid(goals: list[tuple[float, float]], positions: np.ndarray) -> list[tuple[float, float]]:
    """Goals rounded to whole encoder ticks, as the driver writes them: on the grid the
    positions it reads lie on (whole ticks from the calibration's middle)."""
    tick = 2 * np.pi / contract.ENCODER_TICKS_PER_REVOLUTION
    offset = float(np.median(np.mod(positions, tick)))
    return [(t, offset + round((goal - offset) / tick) * tick) for t, goal in goals]


def sysid_episodes(bags: Path, held_out: bool = False) -> dict[str, object]:
    """joint name -> the episode `record` made for it (its held-out run with `held_out`)."""
    found = {}
    for path in episode_dirs([bags]):
        try:
            episode = read_episode(path, cameras=[])
        except BagError as error:
            print(f"so101-sysid: skipped {error}")
            continue
        task = episode.task or ""
        if not task.startswith(TASK_PREFIX) or task.endswith(HELD_OUT_SUFFIX) != held_out:
            continue
        joint = task[len(TASK_PREFIX) :].removesuffix(HELD_OUT_SUFFIX)
        if joint in contract.JOINT_NAMES:
            found[joint] = episode
    return found


def run(args) -> int:
    import so101_native

    episodes = sysid_episodes(Path(args.bags))
    if not episodes:
        raise SystemExit(f"so101-sysid fit: no so101-sysid episodes in {args.bags} (so101-sysid record makes them)")
    recordings = []
    for name, episode in episodes.items():
        goals, samples = joint_series(episode, contract.JOINT_NAMES.index(name))
        recordings.append((name, goals, samples))
    started = time.monotonic()
    params, report = so101_native.fit_servos(args.base, recordings, iterations=args.iterations)
    seconds = time.monotonic() - started
    output = Path(args.output)
    output.parent.mkdir(parents=True, exist_ok=True)
    output.write_text(params + "\n")
    fitted = json.loads(params)["joints"]
    print(f"so101-sysid fit: {len(report)} joint(s) in {seconds:.1f} s -> {output}")
    print(
        "| joint | RMS before (mrad) | RMS after (mrad) | gain_per_p | damping | friction | armature | latency (ms) | dead zone (ticks) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name, before, after, _ in report:
        m, r = fitted[name]["mechanics"], fitted[name]["registers"]
        print(
            f"| {name} | {1000 * before:.2f} | {1000 * after:.2f} | {m['gain_per_p']:.2f} | {m['damping']:.3f} | "
            f"{m['friction']:.4f} | {m['armature']:.4f} | {1000 * m['latency']:.1f} | {r['cw_dead_zone']:.2f} |"
        )
    return 0
