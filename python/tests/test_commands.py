"""so101.dataset.commands: the rules of so101_core::command (crates/so101_core/src/command.rs), mirrored."""

import math

import numpy as np
import pytest

from so101.contract import JOINT_LIMITS, JOINT_NAMES
from so101.dataset.commands import CommandError, obeyed_targets, targets_from_array, targets_from_joint_state
from so101.dataset.resample import gaps, parts_between


def test_partial_command_moves_only_named_joints():
    targets = targets_from_joint_state(["elbow_flex", "gripper"], [0.5, 1.0])
    assert list(targets.apply_clamped(np.full(6, 0.1))) == [0.1, 0.1, 0.5, 0.1, 0.1, 1.0]


def test_out_of_range_targets_are_clamped_to_the_limits():
    targets = targets_from_joint_state(["shoulder_pan", "gripper"], [1e9, -1e9])
    current = targets.apply_clamped(np.zeros(6))
    assert current[0] == JOINT_LIMITS[0][1]
    assert current[5] == JOINT_LIMITS[5][0]


@pytest.mark.parametrize(
    ("names", "positions", "reason"),
    [
        (["gripper"], [], "names 1 joints but carries 0 positions"),
        ([], [], "no positions"),
        (["gripper", "nose"], [0.0, 0.0], "unknown joint name 'nose'"),
        (["gripper", "gripper"], [0.0, 0.1], "'gripper' is named twice"),
        (["shoulder_pan", "wrist_roll"], [0.2, math.nan], "wrist_roll is not finite"),
        (["shoulder_pan", "wrist_roll"], [0.2, math.inf], "wrist_roll is not finite"),
        (["shoulder_pan", "wrist_roll"], [0.2, -math.inf], "wrist_roll is not finite"),
    ],
)
def test_malformed_joint_state_commands_are_rejected_whole(names, positions, reason):
    with pytest.raises(CommandError, match=reason):
        targets_from_joint_state(names, positions)


def test_array_commands_need_six_finite_values():
    for count in (5, 7):
        with pytest.raises(CommandError, match=f"has {count} values"):
            targets_from_array([0.0] * count)
    with pytest.raises(CommandError, match="wrist_flex is not finite"):
        targets_from_array([0.0, 0.0, 0.0, math.nan, 0.0, 0.0])
    assert targets_from_array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6]).targets == (0.1, 0.2, 0.3, 0.4, 0.5, 0.6)


def test_obeyed_targets_start_from_the_held_position_and_merge_partial_commands():
    measured = np.array([0.1, -0.2, 0.3, 0.0, 0.5, 5.0])  # gripper beyond its limit: held clamped
    commands = [
        targets_from_joint_state(["elbow_flex"], [0.5]),
        targets_from_array([-5.0, 0.1, 0.2, 0.3, 0.4, 0.5]),
        targets_from_joint_state(["wrist_flex", "shoulder_lift"], [0.7, 0.0]),
    ]
    out = obeyed_targets(commands, measured)
    gripper_max = JOINT_LIMITS[JOINT_NAMES.index("gripper")][1]
    np.testing.assert_array_equal(out[0], [0.1, -0.2, 0.5, 0.0, 0.5, gripper_max])
    np.testing.assert_array_equal(out[1], [JOINT_LIMITS[0][0], 0.1, 0.2, 0.3, 0.4, 0.5])
    np.testing.assert_array_equal(out[2], [JOINT_LIMITS[0][0], 0.0, 0.2, 0.7, 0.4, 0.5])


def test_gaps_split_the_time_into_parts():
    streams = {"a": [0.0, 0.1, 0.2, 1.0, 1.1], "b": [0.0, 0.3, 0.6, 0.9, 1.2], "c": [0.0, 0.15, 0.9, 1.2]}
    found = gaps(streams, 0.5)
    assert found == [("c", 0.15, 0.9), ("a", 0.2, 1.0)]
    # The overlapping gaps make one break, from the first's start to the last's end.
    assert parts_between(found) == [(-math.inf, 0.15), (1.0, math.inf)]
    assert parts_between(gaps(streams, 1.0)) == [(-math.inf, math.inf)]
    assert parts_between([("a", 1.0, 2.0), ("b", 3.0, 4.0)]) == [(-math.inf, 1.0), (2.0, 3.0), (4.0, math.inf)]
