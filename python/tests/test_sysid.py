"""so101-sysid's pure parts: the excitation a joint gets, and how recorded goals are timed and
rounded before the fit."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from so101 import contract
from so101.dataset.bags import Stream, simulation_settings
from so101.sysid.excitation import Excitation, held_out
from so101.sysid.fit import joint_series, on_the_encoder_grid

TICK = 2 * math.pi / contract.ENCODER_TICKS_PER_REVOLUTION
MAX_STEP = 0.1  # the driver's default --max-step


def test_the_excitation_steps_and_sweeps_within_the_drivers_max_step():
    excitation = Excitation()
    rows = excitation.offsets()
    times, offsets = rows[:, 0], rows[:, 1]
    assert np.allclose(np.diff(times), 1 / excitation.rate)
    assert abs(times[-1] + 1 / excitation.rate - excitation.seconds) < 1e-6
    assert offsets[0] == 0.0 and offsets[-1] == 0.0
    assert np.abs(offsets).max() <= excitation.amplitude + 1e-12
    # No goal jumps further than the driver lets one go from where the joint is.
    assert np.abs(np.diff(offsets)).max() < MAX_STEP
    # The steps are held: +a, 0, -a each for `hold` seconds after the settle.
    start = int(excitation.settle * excitation.rate)
    held = int(excitation.hold * excitation.rate)
    assert np.all(offsets[start : start + held] == excitation.amplitude)
    assert np.all(offsets[start + 2 * held : start + 3 * held] == -excitation.amplitude)
    # The chirp's zero crossings come closer together as its frequency rises.
    chirp = offsets[start + 7 * held : -int(excitation.settle * excitation.rate)]
    crossings = np.flatnonzero(np.diff(np.sign(chirp)) != 0)
    gaps = np.diff(crossings)
    assert gaps[0] > 3 * gaps[-1]


def test_the_held_out_motion_starts_and_ends_at_rest_and_differs_per_seed():
    one, other = held_out(seed=0), held_out(seed=1)
    assert abs(one[0, 1]) < 1e-12 and abs(one[-1, 1]) < 1e-3
    assert np.abs(one[:, 1]).max() <= 0.05
    assert not np.allclose(one[:, 1], other[:, 1])


def test_goals_are_rounded_to_the_ticks_the_positions_lie_on():
    offset = 0.3 * TICK  # the calibration's middle lies between two ticks
    positions = offset + TICK * np.array([3, 4, 4, 5, -2])
    goals = on_the_encoder_grid([(0.0, offset + 7.4 * TICK), (0.1, offset - 2.6 * TICK)], positions)
    assert np.allclose([g for _, g in goals], [offset + 7 * TICK, offset - 3 * TICK])


def test_a_goal_takes_the_stamp_of_the_driver_cycle_after_it_arrived():
    stamps = 100.0 + 0.005 * np.arange(6)  # the driver's cycles (its joint states' stamps)
    episode = SimpleNamespace(
        joint_states=Stream(times=list(stamps), values=[np.zeros(6)] * 6),
        # Received 2 ms after the first cycle and 1 ms after the fourth.
        joint_commands=Stream(times=[100.002, 100.016], values=[np.full(6, 10 * TICK), np.full(6, 20 * TICK)]),
    )
    goals, samples = joint_series(episode, joint=1)
    assert np.allclose(goals[:, 0], [0.0, 0.005, 0.020])  # the hold at the start, then the next cycles
    assert np.allclose(goals[1:, 1], [10 * TICK, 20 * TICK])
    assert samples.shape == (6, 2) and samples[0, 0] == 0.0


def test_a_bags_simulation_settings_are_read_and_a_bad_one_is_left_out(tmp_path, caplog):
    good = {contract.CUSTOM_SIMULATION: '{"servo_model": "sts3215", "draw": null}'}
    assert simulation_settings(tmp_path, good) == {"servo_model": "sts3215", "draw": None}
    assert simulation_settings(tmp_path, {}) is None
    assert simulation_settings(tmp_path, {contract.CUSTOM_SIMULATION: "{not json"}) is None
    assert "not JSON" in caplog.text
