"""The converter on synthetic bags (tests/bag_writer.py, no DDS): actions are the targets the robot
obeyed, episodes are split at gaps, bad episodes are skipped with the reason and the good ones
make a dataset LeRobot loads."""

from __future__ import annotations

import math

import numpy as np
import pytest
from bag_writer import EpisodeBag

from so101.contract import JOINT_LIMITS
from so101.dataset.convert import main
from so101.units import lerobot_from_radians

FPS = 30
MEASURED = [0.1, -0.2, 0.3, 0.0, 0.5, 0.2]
PAN_MIN, GRIPPER_MAX = JOINT_LIMITS[0][0], JOINT_LIMITS[5][1]
# (receive time, the full target in force from then on) of the good episode's accepted commands.
OBEYED = [
    (0.10, [0.1, -0.2, 0.5, 0.0, 0.5, GRIPPER_MAX]),  # partial, from the measured state; clamped
    (1.02, [PAN_MIN, 0.1, 0.2, 0.3, 0.4, 0.5]),  # the array topic; clamped
    (1.52, [PAN_MIN, 0.1, 0.2, 0.7, 0.4, 0.5]),  # partial, merged
]


def observed(bag: EpisodeBag, start: float, end: float, width=16, height=12, skip=None, resize_at=None) -> None:
    """Joint states, a camera and the cube pose at 30 Hz over [start, end] (less `skip`, a
    (stream, from, to) silence), the camera changing to 20x12 from `resize_at`."""
    for k in range(int(round((end - start) * FPS)) + 1):
        t = start + k / FPS
        silent = skip and skip[1] < t < skip[2]
        if not (silent and skip[0] == "joint_states"):
            bag.joint_state(t, MEASURED)
        if not (silent and skip[0] == "camera"):
            big = resize_at is not None and t >= resize_at
            bag.image(t, "top", width + 4 if big else width, height, value=k)
        bag.cube(t)


def good_episode(directory):
    bag = EpisodeBag(directory)
    observed(bag, 0.0, 2.0)
    bag.command(0.10, ["elbow_flex", "gripper"], [0.5, 9.0])
    bag.command(0.52, ["shoulder_pan", "nose"], [0.0, 0.0])  # unknown name
    bag.command(0.72, ["wrist_roll"], [math.nan])  # not finite
    bag.command(0.92, ["gripper", "gripper"], [0.1, 0.2])  # named twice
    bag.array_command(1.02, [-5.0, 0.1, 0.2, 0.3, 0.4, 0.5])
    bag.array_command(1.22, [0.0] * 5)  # five values
    bag.array_command(1.32, [0.0, 0.0, math.inf, 0.0, 0.0, 0.0])  # not finite
    bag.command(1.42, ["wrist_flex"], [0.7, 0.1])  # counts differ
    bag.command(1.52, ["wrist_flex"], [0.7])
    bag.reward(0.0, 0.0)
    bag.success(0.0, False)
    return bag.close()


def simple_episode(directory, **observe) -> EpisodeBag:
    bag = EpisodeBag(directory)
    observed(bag, 0.0, observe.pop("end", 2.0), **observe)
    bag.array_command(0.05, [0.0, 0.0, 0.0, 0.0, 0.0, 0.5])
    return bag


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    """Good and bad episodes in one directory, converted once."""
    import io
    from contextlib import redirect_stdout

    bags = tmp_path_factory.mktemp("bags")
    good_episode(bags / "episode_000000")
    simple_episode(bags / "episode_000001", resize_at=1.0).close()  # camera size changes inside
    simple_episode(bags / "episode_000002").close(metadata="rosbag2_bagfile_information: [1, 2\n")  # YAML error
    simple_episode(bags / "episode_000003").close(metadata="rosbag2_bagfile_information:\n  relative_file_paths: 3\n")
    simple_episode(bags / "episode_000004", end=3.0, skip=("joint_states", 1.0, 2.0)).close()  # a 1 s gap: 2 parts
    simple_episode(bags / "episode_000005", width=24).close()  # another camera size than the dataset's
    late = simple_episode(bags / "episode_000006", skip=("camera", 0.03, 5.0))  # one frame, then one after the rest
    late.image(2.1, "top", 16, 12)
    late.close()  # both parts too short
    output = tmp_path_factory.mktemp("out") / "dataset"
    out = io.StringIO()
    with redirect_stdout(out):
        status = main([str(bags), "--output", str(output), "--no-videos", "--quiet", "--repo-id", "local/checks"])
    return status, out.getvalue(), output


def test_bad_episodes_are_skipped_with_the_reason(converted):
    status, summary, _ = converted
    assert status == 0, summary
    skipped = [line for line in summary.splitlines() if line.startswith("  skipped: ")]
    assert len(skipped) == 5, summary
    assert "episode_000001: camera 'top' changed size from 16x12 to 20x12" in skipped[0]
    assert skipped[1].startswith("  skipped: episode_000002: unreadable metadata.yaml")
    assert "episode_000003: malformed metadata.yaml (relative_file_paths" in skipped[2]
    assert "episode_000005: cameras {'top': (12, 24)} differ" in skipped[3]
    assert "episode_000006: no part of it long enough" in skipped[4]
    assert summary.startswith("3 episode(s)"), summary


def test_rejections_and_gaps_are_reported(converted):
    _, summary, _ = converted
    assert "episode_000000: 6 command(s) rejected" in summary
    assert "episode_000004: gap(s) longer than 0.5 s (/joint_states 1.00 s at t=1.00 s): split into 2 parts" in summary
    assert "episode_000006: gap(s) longer than 0.5 s (/camera/top/image_raw" in summary


def test_the_dataset_holds_exactly_the_good_episodes_with_the_obeyed_actions(converted):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    _, _, output = converted
    dataset = LeRobotDataset("local/checks", root=output)
    assert dataset.meta.total_episodes == 3
    episodes = dataset.meta.episodes
    spans = [(episodes["dataset_from_index"][i], episodes["dataset_to_index"][i]) for i in range(3)]
    frames = dataset.hf_dataset.with_format("numpy")
    # Episode 0: frame k at 0.10 + k / 30 s (the first command is the last stream to start).
    first, last = spans[0]
    assert last - first >= 55
    times = 0.10 + np.asarray(frames["timestamp"][first:last], dtype=np.float64)
    expected = np.stack([lerobot_from_radians(np.array([t for s, t in OBEYED if s <= when + 1e-6][-1])) for when in times])
    np.testing.assert_allclose(np.stack(frames["action"][first:last]), expected, atol=1e-4)
    np.testing.assert_allclose(
        np.stack(frames["observation.state"][first:last]), [lerobot_from_radians(np.array(MEASURED))] * (last - first), atol=1e-4
    )
    # Episode 4's two parts: about 0.95 s each, the second part still holds the one command.
    for first, last in spans[1:]:
        assert 28 <= last - first <= 32
        np.testing.assert_allclose(
            np.stack(frames["action"][first:last])[:, 5], lerobot_from_radians(np.array([0, 0, 0, 0, 0, 0.5]))[5], atol=1e-4
        )
    # The verdict from metadata.yaml ends the last part only.
    success = np.asarray(frames["next.success"]).reshape(-1)
    assert not success[spans[1][1] - 1] and success[spans[2][1] - 1]


def test_only_bad_episodes_fail_without_a_dataset(tmp_path, capsys):
    bag = simple_episode(tmp_path / "bags" / "episode_000000")
    bag.command(0.5, ["gripper"], [math.nan])
    bag.close(metadata="rosbag2_bagfile_information: 5\n")
    commands_only_rejected = EpisodeBag(tmp_path / "bags" / "episode_000001")
    observed(commands_only_rejected, 0.0, 1.0)
    commands_only_rejected.array_command(0.1, [0.0] * 7)
    commands_only_rejected.close()
    output = tmp_path / "dataset"
    assert main([str(tmp_path / "bags"), "--output", str(output), "--no-videos", "--quiet"]) == 1
    summary = capsys.readouterr().out
    assert "episode_000000: malformed metadata.yaml (rosbag2_bagfile_information is not a mapping)" in summary
    assert "episode_000001: no valid /joint_commands or /forward_position_controller/commands (action) (1 rejected" in summary
    assert not output.exists()


def test_a_camera_too_narrow_for_the_video_encoder_is_skipped_not_a_crash(tmp_path):
    import io
    from contextlib import redirect_stdout

    bags = tmp_path / "bags"
    simple_episode(bags / "episode_000000", width=16).close()  # SVT-AV1 crashes on 16 px wide frames
    out = io.StringIO()
    with redirect_stdout(out):
        status = main([str(bags), "--output", str(tmp_path / "dataset"), "--quiet", "--repo-id", "local/narrow"])
    assert status == 1, out.getvalue()
    assert "narrower than 32 px" in out.getvalue() and "--image-size or --no-videos" in out.getvalue()
    with pytest.raises(SystemExit):
        main([str(bags), "--output", str(tmp_path / "other"), "--image-size", "16x12"])
