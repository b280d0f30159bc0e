"""The real arm's recording path, emulated end to end: so101-launch on the servo-bus emulator
(follower and leader arms) with two fake cameras (MJPEG and YUYV) records two timed episodes as
lerobot-record would; so101-bag-to-lerobot converts the bags; LeRobotDataset loads the dataset, and
its video frames are the frames the cameras served (PSNR), one camera frame after the other at
30 frames per second. The session's keys (right arrow, left arrow, Esc) drive the recorder through
the launcher's terminal (a pty)."""

from __future__ import annotations

import os
import pty
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml
from fake_camera import picture

from so101 import contract

LAUNCH = Path(sys.executable).parent / "so101-launch"
SIZE = (64, 48)
EPISODE_S = 3.0


def episode_dirs(bags: Path) -> list[Path]:
    return sorted(p for p in bags.glob(f"{contract.EPISODE_DEFAULT_PREFIX}_*") if (p / contract.EPISODE_METADATA_FILE).is_file())


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return 10 * np.log10(255.0**2 / max(mse, 1e-12))


def test_two_timed_episodes_with_two_cameras_become_a_dataset_of_the_frames_they_served(tmp_path):
    bags, logs, dataset_root = tmp_path / "bags", tmp_path / "logs", tmp_path / "dataset"
    width, height = SIZE
    argv = [str(LAUNCH), "--robot", "real", "--emulate", "--control", "teleop", "--teleop-source", "leader"]
    argv += ["--camera", f"top=fake:{width}x{height}@30", "--camera", f"wrist=fake:yuyv,{width}x{height}@30"]
    argv += ["--record", "--bags", str(bags), "--episodes", "2", "--episode-time", str(EPISODE_S), "--reset-time", "1"]
    argv += ["--task", "pick the cube", "--log-dir", str(logs)]
    done = subprocess.run(argv, stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=180)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "the recording session is over" in done.stdout, done.stdout
    started = re.findall(r"started (\S+) \(pid", done.stdout)
    assert started[:5] == ["so101_servo_emulator", "so101_feetech_driver", "leader_emulator", "leader_arm", "so101_camera_node"]
    episodes = episode_dirs(bags)
    assert [p.name for p in episodes] == ["episode_000000", "episode_000001"]
    for episode in episodes:
        info = yaml.safe_load((episode / contract.EPISODE_METADATA_FILE).read_text())["rosbag2_bagfile_information"]
        assert info["custom_data"][contract.CUSTOM_TASK] == "pick the cube"
        seconds = info["duration"]["nanoseconds"] * 1e-9
        assert abs(seconds - EPISODE_S) < 0.5, f"{episode.name} lasted {seconds:.2f} s"
        topics = {t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]}
        for camera in ("top", "wrist"):
            frames = topics.get(f"/camera/{camera}/image_raw/compressed", 0)
            assert abs(frames - 30 * EPISODE_S) <= 6, f"{episode.name}: {frames} {camera} frames in {EPISODE_S} s"

    convert = subprocess.run(
        [
            str(LAUNCH.parent / "so101-bag-to-lerobot"),
            str(bags),
            "--output",
            str(dataset_root),
            "--repo-id",
            "local/real_path",
            "--quiet",
        ],
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert convert.returncode == 0, convert.stdout + convert.stderr
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    dataset = LeRobotDataset("local/real_path", root=dataset_root)
    assert dataset.num_episodes == 2 and dataset.fps == 30
    for camera in ("top", "wrist"):
        feature = dataset.features[f"observation.images.{camera}"]
        assert feature["dtype"] == "video" and tuple(feature["shape"]) == (height, width, 3), feature
    assert dataset[0]["task"] == "pick the cube"
    start, stop = dataset.meta.episodes["dataset_from_index"][1], dataset.meta.episodes["dataset_to_index"][1]
    assert abs((stop - start) - 30 * EPISODE_S) <= 3, stop - start
    pictures = [picture(width, height, k) for k in range(32)]
    for camera, bound in (("top", 30.0), ("wrist", 28.0)):
        sequences, qualities = [], []
        for index in range(start + 5, start + 35):
            video = dataset[index][f"observation.images.{camera}"].numpy().transpose(1, 2, 0) * 255.0
            # The fake's 32 pictures differ in blue (8k for frame k): which one this is (the closest:
            # the blue mean alone is off by one now and then after YUYV's chroma subsampling, JPEG
            # and AV1), then how close.
            quality, sequence = max((psnr(video, pictures[k]), k) for k in range(32))
            sequences.append(sequence)
            qualities.append(quality)
        assert min(qualities) > bound, f"{camera}: PSNR {min(qualities):.1f} dB against the served frames"
        steps = np.diff(sequences) % 32
        # One camera frame after the other at the dataset's 30 fps: each row holds the next frame.
        assert np.all(steps == 1), f"{camera}: frames of rows {start + 5}.. are {sequences}"


def read_until(fd: int, text: str, seen: list[str], timeout: float = 30.0) -> None:
    """Reads the launcher's output (a pty) until `text` has appeared once more than before."""
    count = "".join(seen).count(text)
    deadline = time.monotonic() + timeout
    while "".join(seen).count(text) <= count:
        assert time.monotonic() < deadline, f"no {text!r} within {timeout} s:\n{''.join(seen)}"
        try:
            seen.append(os.read(fd, 4096).decode(errors="replace"))
        except OSError:
            raise AssertionError(f"the launcher ended before {text!r}:\n{''.join(seen)}") from None


def test_the_session_keys_end_drop_and_stop_episodes_from_the_launcher_s_terminal(tmp_path):
    bags = tmp_path / "bags"
    argv = [str(LAUNCH), "--robot", "real", "--emulate", "--control", "none", "--camera", "top=fake:32x24@30"]
    argv += ["--record", "--bags", str(bags), "--episodes", "2", "--episode-time", "60", "--reset-time", "60"]
    argv += ["--log-dir", str(tmp_path / "logs")]
    controller, terminal = pty.openpty()
    launcher = subprocess.Popen(argv, stdin=terminal, stdout=terminal, stderr=terminal, close_fds=True)
    os.close(terminal)
    seen: list[str] = []
    right, left, esc = b"\x1b[C", b"\x1b[D", b"\x1b"
    try:
        read_until(controller, "recording episode 1 of 2", seen)
        time.sleep(0.5)
        os.write(controller, right)  # end episode 1 now: kept
        read_until(controller, "episode 1 kept", seen)
        time.sleep(0.5)
        assert [p.name for p in episode_dirs(bags)] == ["episode_000000"]
        os.write(controller, left)  # in the reset period: drop the episode just kept
        read_until(controller, "it is recorded again next", seen)
        deadline = time.monotonic() + 10
        while episode_dirs(bags) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert episode_dirs(bags) == [], "the dropped episode's bag is still there"
        os.write(controller, right)  # end the reset period: episode 1 again
        read_until(controller, "recording episode 1 of 2", seen)
        time.sleep(0.5)
        os.write(controller, left)  # drop the running episode
        read_until(controller, "episode 1 dropped; reset the scene", seen)
        os.write(controller, right)
        read_until(controller, "recording episode 1 of 2", seen)
        kept_from = time.time()
        time.sleep(1.0)
        os.write(controller, esc)  # stop: the running episode is kept
        read_until(controller, "stopped: 1 episodes recorded", seen)
        assert launcher.wait(timeout=60) == 0, "".join(seen)
    finally:
        if launcher.poll() is None:
            launcher.kill()
            launcher.wait()
        os.close(controller)
    episodes = episode_dirs(bags)
    assert [p.name for p in episodes] == ["episode_000000"], "numbering stays contiguous over the dropped episodes"
    info = yaml.safe_load((episodes[0] / contract.EPISODE_METADATA_FILE).read_text())["rosbag2_bagfile_information"]
    began = info["starting_time"]["nanoseconds_since_epoch"] * 1e-9
    assert began > kept_from - 2.0, "the kept episode is not the last one recorded"
    assert 0.5 < info["duration"]["nanoseconds"] * 1e-9 < 5.0, info["duration"]
