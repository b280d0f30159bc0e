"""so101-dataset-check on a dataset the converter makes from synthetic bags (tests/bag_writer.py,
no DDS), with a small camera stored as video: the good dataset is clean, and each corruption of a
copy of it on disk (a NaN in action, a shifted timestamp, a truncated or garbled video, stats
missing a feature, a wrong episode length) is reported with the episode and the reason."""

from __future__ import annotations

import io
import json
import shutil
from contextlib import redirect_stdout

import numpy as np
import pandas as pd
import pytest
from bag_writer import EpisodeBag

from so101.dataset.check import Finding, check_dataset
from so101.dataset.check import main as check_main
from so101.dataset.convert import main as convert_main

FPS = 30
SECONDS = 1.0  # per episode: 31 frames (from half a frame after the start; the last messages held one frame)
DATA = "data/chunk-000/file-000.parquet"
VIDEO = "videos/observation.images.top/chunk-000/file-000.mp4"


def episode_bag(directory) -> None:
    bag = EpisodeBag(directory)
    for k in range(int(SECONDS * FPS) + 1):
        t = k / FPS
        bag.joint_state(t, [0.1, -0.2, 0.3, 0.0, 0.5, 0.2])
        bag.image(t, "top", 32, 32, value=8 * k)
        bag.cube(t)
    bag.array_command(0.0, [0.0, 0.0, 0.0, 0.0, 0.0, 0.5])
    bag.close()


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    """Two episodes converted with video, the check run at the converter's end."""
    bags = tmp_path_factory.mktemp("bags")
    for k in range(2):
        episode_bag(bags / f"episode_{k:06d}")
    output = tmp_path_factory.mktemp("out") / "dataset"
    out = io.StringIO()
    with redirect_stdout(out):
        status = convert_main([str(bags), "--output", str(output), "--quiet", "--repo-id", "local/check"])
    return status, out.getvalue(), output


@pytest.fixture
def copy(converted, tmp_path):
    _, _, output = converted
    target = tmp_path / "dataset"
    shutil.copytree(output, target)
    return target


def findings_of(root) -> list[Finding]:
    findings, _ = check_dataset(root)
    return findings


def test_the_converter_checks_its_dataset_and_it_is_clean(converted):
    status, summary, output = converted
    assert status == 0, summary
    assert "check: " not in summary, summary
    assert f"check {output}: 2 episode(s), 62 frames, 62 video frames decoded: clean" in summary, summary
    assert findings_of(output) == []


def test_the_cli_passes_a_good_dataset(converted, capsys):
    _, _, output = converted
    assert check_main([str(output), "--quiet", "--repo-id", "local/check"]) == 0
    assert capsys.readouterr().out.strip().endswith("clean")


def write_data(root, change) -> None:
    path = root / DATA
    data = pd.read_parquet(path)
    change(data)
    data.to_parquet(path)


def test_a_nan_in_action_is_reported(copy, capsys):
    def nan(data):
        row = data.index[(data["episode_index"] == 1) & (data["frame_index"] == 5)][0]
        action = np.array(data.at[row, "action"], dtype=np.float32)
        action[2] = np.nan
        data.at[row, "action"] = action

    write_data(copy, nan)
    assert findings_of(copy) == [Finding(1, "non-finite", "action: NaN/inf in 1 frame(s) (first: frame 5)")]
    assert check_main([str(copy), "--quiet"]) == 1
    out = capsys.readouterr().out
    assert "  check: episode 1: non-finite: action: NaN/inf in 1 frame(s) (first: frame 5)" in out
    assert out.strip().endswith("1 finding(s), 1 episode(s) affected")


def test_a_timestamp_shifted_beyond_the_tolerance_is_reported(copy):
    def shift(data):
        row = data.index[(data["episode_index"] == 0) & (data["frame_index"] == 10)][0]
        data.at[row, "timestamp"] += 0.0005  # 5 x LeRobot's tolerance

    write_data(copy, shift)
    findings = findings_of(copy)
    timing = [f for f in findings if f.what == "timestamps"]
    assert len(timing) == 1 and timing[0].episode == 0, findings
    assert "2 step(s) off 1/fps" in timing[0].details and "frame 9 -> 10" in timing[0].details
    # The shifted frame has no video frame at its time either.
    video = [f for f in findings if f.what == "video"]
    assert len(video) == 1 and video[0].episode == 0 and "1 of 31 frame(s) have no decoded frame" in video[0].details
    assert {f.episode for f in findings} == {0}


def test_a_shift_within_the_tolerance_passes(copy):
    def shift(data):
        row = data.index[(data["episode_index"] == 0) & (data["frame_index"] == 10)][0]
        data.at[row, "timestamp"] += 0.00004

    write_data(copy, shift)
    assert findings_of(copy) == []


def test_a_truncated_video_is_reported_for_the_episodes_it_lost(copy):
    path = copy / VIDEO
    content = path.read_bytes()
    path.write_bytes(content[: len(content) // 2])
    findings = findings_of(copy)
    assert findings, "a video cut in half passed"
    assert all(f.what == "video" and "observation.images.top" in f.details for f in findings), findings
    assert 1 in {f.episode for f in findings}  # the second episode lies in the lost half
    assert any("frame(s) decoded in" in f.details and "expected 31" in f.details for f in findings), findings


def test_a_garbled_video_is_reported_for_every_episode(copy):
    path = copy / VIDEO
    path.write_bytes(bytes(path.stat().st_size))
    findings = findings_of(copy)
    assert {f.episode for f in findings} == {0, 1}, findings
    assert all(f.what == "video" and "decoding stopped" in f.details for f in findings), findings


def test_stats_missing_a_feature_are_reported(copy):
    path = copy / "meta" / "stats.json"
    stats = json.loads(path.read_text())
    del stats["action"]
    stats["observation.state"]["mean"][0] = float("nan")
    path.write_text(json.dumps(stats))
    assert set(findings_of(copy)) == {
        Finding(None, "stats", "meta/stats.json has no action"),
        Finding(None, "stats", "meta/stats.json observation.state/mean is not finite"),
    }


def test_an_episode_missing_frames_is_reported(copy):
    def drop_last(data):
        last = data.index[(data["episode_index"] == 0) & (data["frame_index"] == 30)][0]
        data.drop(index=last, inplace=True)

    write_data(copy, drop_last)
    findings = findings_of(copy)
    assert Finding(0, "length", "meta length 31, dataset_from/to_index span 31, 30 rows in data/") in findings, findings
    # The video still holds 31 frames for it, the data 30: reported as well.
    assert all(f.episode == 0 for f in findings), findings


def test_the_cli_answers_help_and_refuses_a_missing_directory(tmp_path, capsys):
    with pytest.raises(SystemExit) as done:
        check_main(["--help"])
    assert done.value.code == 0 and "so101-dataset-check" in capsys.readouterr().out
    with pytest.raises(SystemExit) as done:
        check_main([str(tmp_path / "nothing")])
    assert done.value.code == 2


def test_the_converter_skips_the_check_with_no_check(tmp_path):
    episode_bag(tmp_path / "bags" / "episode_000000")
    out = io.StringIO()
    with redirect_stdout(out):
        status = convert_main([str(tmp_path / "bags"), "--output", str(tmp_path / "ds"), "--quiet", "--no-videos", "--no-check"])
    assert status == 0, out.getvalue()
    assert "check " not in out.getvalue() and out.getvalue().startswith("1 episode(s)")
    # A dataset of images, not videos, is checked clean too.
    assert findings_of(tmp_path / "ds") == []
