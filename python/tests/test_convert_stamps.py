"""Where the converter puts a command (so101.dataset.resample.command_times): by its stamp when that
is the stamp of a recorded joint state near its arrival, as teleop_node's lockstep commands have
it, else by its arrival. A lockstep period's command that comes in late in its period still
lands on the frame of the state it answers; a stamp from another clock, or a publisher's own
publish time, is ignored. Synthetic bags (tests/bag_writer.py), no DDS."""

from __future__ import annotations

import io
from contextlib import redirect_stdout

import numpy as np
import pytest
from bag_writer import EpisodeBag

from so101.contract import JOINT_NAMES
from so101.dataset.convert import main
from so101.dataset.resample import command_times
from so101.units import radians_from_lerobot

FPS = 30
PERIODS = 60
# What each command adds to the state it answers (rad, every joint): the pair is found again in
# the dataset only if the command lands on its state's frame.
AHEAD = 0.2
# Each command comes in this long after the state it answers: after the middle of its period
# (half a frame, where the converter's frames lie), as on a loaded machine.
LATE = 0.025


def lockstep_episode(directory, stamp_of) -> None:
    """States at k/30 s whose joints read 0.01 k rad; the command answering state k asks for
    0.01 k + AHEAD, received at k/30 + LATE, stamped stamp_of(k / 30)."""
    bag = EpisodeBag(directory)
    for k in range(PERIODS):
        t = k / FPS
        bag.joint_state(t, [0.01 * k] * 6)
        bag.command(t + LATE, JOINT_NAMES, [0.01 * k + AHEAD] * 6, stamp=stamp_of(t))
    bag.close()


def converted(tmp_path, stamp_of) -> tuple[np.ndarray, np.ndarray]:
    """(observation.state, action) of the one episode, in radians."""
    import pandas as pd

    lockstep_episode(tmp_path / "bags" / "episode_000000", stamp_of)
    out = io.StringIO()
    with redirect_stdout(out):
        status = main([str(tmp_path / "bags"), "--output", str(tmp_path / "dataset"), "--quiet", "--repo-id", "local/stamps"])
    assert status == 0, out.getvalue()
    frames = pd.concat(pd.read_parquet(path) for path in sorted((tmp_path / "dataset" / "data").rglob("*.parquet")))
    state = radians_from_lerobot(np.stack(frames["observation.state"].to_numpy()).astype(np.float64))
    action = radians_from_lerobot(np.stack(frames["action"].to_numpy()).astype(np.float64))
    return state[:, :5], action[:, :5]  # the gripper's percent scale clamps: the arm's joints say it


def test_a_lockstep_command_lands_on_the_frame_of_the_state_it_answers(tmp_path):
    state, action = converted(tmp_path, stamp_of=lambda t: t)
    assert len(state) >= PERIODS - 3
    np.testing.assert_allclose(action - state, AHEAD, atol=1e-4)


@pytest.mark.parametrize(
    "stamp_of",
    [lambda t: 0.0, lambda t: 1_795_640_370.0 + t, lambda t: t + LATE - 0.005],
    ids=["unstamped", "wall-clock", "publish-time"],
)
def test_a_command_without_a_stamp_of_the_sim_s_clock_is_placed_by_its_arrival(tmp_path, stamp_of):
    state, action = converted(tmp_path, stamp_of)
    # Received after the next frame's instant: each frame holds the command of the state before
    # (but the last: an arrival after the last state maps to that state's sim time).
    np.testing.assert_allclose((action - state)[:-1], AHEAD - 0.01, atol=1e-4)


def test_a_stamp_is_trusted_only_when_it_is_a_state_s_near_the_arrival():
    states = [8.5, 9.2, 9.95, 10.05, 10.5]
    arrivals = np.full(7, 10.0)
    stamps = np.array([9.95, 9.2, 10.05, 0.0, 8.5, 10.5, 9.97])
    # a state's, 1 s before to 0.1 s after the arrival; none; too early; too late; not a state's
    expected = [9.95, 9.2, 10.05, 10.0, 10.0, 10.0, 10.0]
    for index, (arrival, stamp, placed) in enumerate(zip(arrivals, stamps, expected)):
        assert command_times([arrival], [stamp], states)[0] == placed, index


def test_a_command_is_never_placed_before_one_that_came_in_earlier():
    # An unstamped command, then a partial one stamped with a state 0.5 s before its arrival: the
    # robot obeyed them in that order, so the second does not move ahead of the first.
    placed = command_times([9.9, 10.0], [0.0, 9.5], [9.5, 9.9])
    np.testing.assert_allclose(placed, [9.9, 9.9])
