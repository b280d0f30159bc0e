"""The default recording path keeps compressed camera frames: so101-launch with the expert and the
recorder (as scripts/record_dataset.sh runs it) records each camera's JPEG frames
(sensor_msgs/CompressedImage on image_raw/compressed) and not its raw images; rosbags, an
independent reader, opens the bag and decodes them; so101-bag-to-lerobot converts it into a
dataset whose video frames are those frames."""

from __future__ import annotations

import io
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import yaml
from harness import node_binary, node_environment, rrd_entities

VENV_BIN = Path(sys.executable).parent


def test_the_default_recording_keeps_jpeg_frames_that_rosbags_reads_and_the_converter_converts(tmp_path):
    from PIL import Image
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    bags = tmp_path / "bags"
    done = subprocess.run(
        [
            str(VENV_BIN / "so101-launch"),
            "--control",
            "expert",
            "--episodes",
            "1",
            "--record",
            "--bags",
            str(bags),
            "--lite",
            "--sim-args=--cameras top:64x48,wrist:64x48",
            "--seed",
            "5",
            "--log-dir",
            str(tmp_path / "logs"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    episode = bags / "episode_000000"
    info = yaml.safe_load((episode / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    types = {t["topic_metadata"]["name"]: t["topic_metadata"]["type"] for t in info["topics_with_message_count"]}
    for camera in ("top", "wrist"):
        assert types.get(f"/camera/{camera}/image_raw/compressed") == "sensor_msgs/msg/CompressedImage", types
        assert f"/camera/{camera}/image_raw" not in types, types
        assert types.get(f"/camera/{camera}/camera_info") == "sensor_msgs/msg/CameraInfo", types
    assert {"/joint_states", "/joint_commands", "/cube/pose", "/task/success"} <= set(types), types

    # rosbags: its own metadata.yaml parser, MCAP storage and Jazzy CDR definitions.
    store = get_typestore(Stores.ROS2_JAZZY)
    frames: list[tuple[float, np.ndarray]] = []
    with Reader(episode) as bag:
        connections = [c for c in bag.connections if c.topic == "/camera/top/image_raw/compressed"]
        for connection, _, raw in bag.messages(connections=connections):
            message = store.deserialize_cdr(raw, connection.msgtype)
            assert message.format == "rgb8; jpeg compressed bgr8", message.format
            image = Image.open(io.BytesIO(message.data.tobytes()))
            assert (image.format, image.size) == ("JPEG", (64, 48))
            frames.append((message.header.stamp.sec + message.header.stamp.nanosec * 1e-9, np.asarray(image.convert("RGB"))))
    # An expert episode is about 8 s of sim time: its frames cover it at their 30 Hz sim-time instants
    # (about 240 on a quiet machine; a busy one's renderer may skip some), never more: frame k at the
    # first 10 ms control-period end at or after k/30 s, so never two in one 3-period gap.
    stamps = np.array([stamp for stamp, _ in frames])
    span = stamps[-1] - stamps[0]
    assert len(frames) > 30 and span > 5.0, (len(frames), span)
    assert np.all(np.diff(stamps) > 0.025), sorted(set(np.round(np.diff(stamps), 3)))
    assert len(frames) - 1 <= (span + 0.01) * 30, f"{len(frames)} frames in {span:.2f} s of sim time at 30 Hz"

    # so101_rerun logs every compressed frame (as the encoded JPEG) from the bag.
    rrd = tmp_path / "rrd"
    done = subprocess.run(
        [str(node_binary("so101_rerun")), "bag", str(bags), "--output", str(rrd), "--image-rate", "0"],
        capture_output=True,
        text=True,
        timeout=120,
        env=node_environment(),
    )
    assert done.returncode == 0, done.stdout + done.stderr
    rows = rrd_entities(rrd / "episode_000000.rrd")
    assert rows.get("/cameras/top") == len(frames), (rows.get("/cameras/top"), len(frames))

    output = tmp_path / "dataset"
    done = subprocess.run(
        [str(VENV_BIN / "so101-bag-to-lerobot"), str(bags), "--output", str(output), "--repo-id", "local/jpeg", "--quiet"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    # Whether the expert succeeded in real time is not this test's concern (on a busy machine its
    # grasp can come late and slip; test_teleop checks the expert): the episode is
    # converted either way, with nothing skipped, and the dataset reads back clean.
    assert re.search(r"1 episode\(s\) \([01] successful\)", done.stdout), done.stdout
    assert "0 skipped" in done.stdout and "clean" in done.stdout, done.stdout

    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    dataset = LeRobotDataset("local/jpeg", root=output)
    assert dataset.features["observation.images.top"]["shape"] == (48, 64, 3)
    # Nothing is lost: the dataset holds every frame of the span all streams cover (which starts
    # later than the camera's first frame when a busy machine delays the expert's first command).
    expected = frames_in_overlap(episode, store)
    assert dataset.num_frames == expected, (dataset.num_frames, expected, len(frames))
    # A video frame is one of the recorded JPEG frames (AV1 on top of JPEG: close, not equal).
    item = dataset[dataset.num_frames // 2]
    video = item["observation.images.top"].numpy().transpose(1, 2, 0) * 255.0
    errors = [np.abs(video - image).mean() for _, image in frames]
    assert min(errors) < 8, f"the video frame is none of the recorded frames (closest off by {min(errors):.1f})"


def frames_in_overlap(episode: Path, store) -> int:
    """The frame count docs/lerobot.md's alignment gives for the episode's bag, read with rosbags:
    frames every 1/30 s from half a frame after every stream has begun (the commands, which carry
    no stamp, placed on the sim clock through the joint states' receive times) to one frame after
    the first stamped stream ends (a command stays in force after the last one)."""
    from rosbags.rosbag2 import Reader

    stamped: dict[str, list[float]] = {}
    states_received, states_sim, commands_received = [], [], []
    with Reader(episode) as bag:
        for connection, received, raw in bag.messages():
            topic = connection.topic
            if topic == "/joint_commands":
                commands_received.append(received * 1e-9)
                continue
            if topic not in ("/joint_states", "/cube/pose") and not topic.endswith("/image_raw/compressed"):
                continue
            header = store.deserialize_cdr(raw, connection.msgtype).header
            stamp = header.stamp.sec + header.stamp.nanosec * 1e-9
            stamped.setdefault(topic, []).append(stamp)
            if topic == "/joint_states":
                states_received.append(received * 1e-9)
                states_sim.append(stamp)
    order = np.argsort(states_received)
    sim_clock = np.maximum.accumulate(np.asarray(states_sim)[order])
    first_command = float(np.interp(min(commands_received), np.asarray(states_received)[order], sim_clock))
    start = max([first_command] + [min(times) for times in stamped.values()]) + 0.5 / 30
    end = min(max(times) + 1 / 30 for times in stamped.values())
    return int(np.floor((end - start) * 30 + 1e-9)) + 1
