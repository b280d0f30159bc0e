"""From bags to LeRobot: episodes recorded by recorder_node from the sim and the scripted expert,
converted by so101-bag-to-lerobot, loaded back by LeRobot's own LeRobotDataset; frame counts,
state, action, images, task and success checked against the bags (read here with the `mcap`
reader); a truncated episode is reported and skipped."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
from frame_grid import frame_zero_instants
from harness import best_effort_qos, wait_until

from so101 import contract

JOINTS = ["shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper"]
CONVERTER = Path(sys.executable).parent / "so101-bag-to-lerobot"
REPLAY = Path(sys.executable).parent / "so101-replay"


def bag_messages(episode: Path, topic: str) -> list[tuple[float, object]]:
    """(header stamp in s, message) of a stamped topic, read with mcap's own reader."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    out = []
    for file in sorted(episode.glob("*.mcap")):
        with open(file, "rb") as f:
            for _s, _c, _m, ros in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(topics=[topic]):
                out.append((ros.header.stamp.sec + ros.header.stamp.nanosec * 1e-9, ros))
    return sorted(out, key=lambda pair: pair[0])


def bag_verdict(episode: Path) -> bool:
    """The success the recorder wrote into the episode's metadata.yaml (its custom data)."""
    import yaml

    info = yaml.safe_load((episode / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    return str((info.get("custom_data") or {}).get(contract.CUSTOM_SUCCESS, "")).lower() == "true"


def lerobot_units(radians: list[float]) -> np.ndarray:
    """LeRobot's SO-101 units computed here: degrees, gripper 0-100 over its model range."""
    values = np.degrees(np.asarray(radians, dtype=np.float64))
    values[5] = (radians[5] + 0.1745) / (1.7453 + 0.1745) * 100
    return values


def test_expert_bags_become_a_lerobot_dataset_that_lerobot_loads_and_replays(
    sim_factory, recorder_factory, teleop_factory, ros, tmp_path
):
    sim = sim_factory("--speed", "2", "--seed", "3", "--cameras", "top:64x48,wrist:64x48", "--camera-rate", "30")
    recorder = recorder_factory()
    ros.wait_for_graph(lambda: ros.node.count_subscribers("/episode/events") >= 1, 20.0, "the recorder", sim)
    teleop = teleop_factory("--source", "expert", "--sim-time", "--episodes", "2", "--seed", "2")
    wait_until(lambda: not teleop.alive(), 120.0, "the expert's 2 episodes", sim)
    bags = recorder.output
    wait_until(
        lambda: len([d for d in bags.glob("episode_*") if (d / "metadata.yaml").is_file()]) == 2, 20.0, "2 closed episodes", sim
    )

    # A third episode directory cut short (no metadata.yaml, as after a kill -9).
    broken = bags / "episode_000002"
    shutil.copytree(bags / "episode_000001", broken)
    (broken / "metadata.yaml").unlink()

    output = tmp_path / "dataset"
    done = subprocess.run(
        [str(CONVERTER), str(bags), "--output", str(output), "--repo-id", "local/so101_test", "--quiet"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    # Nothing is lost: the cut episode is read from its MCAP file, and the summary says it was cut.
    assert "3 episode(s)" in done.stdout and "0 skipped" in done.stdout, done.stdout
    assert "episode_000002: no metadata.yaml (the recording was cut short)" in done.stdout, done.stdout

    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    dataset = LeRobotDataset("local/so101_test", root=output)
    assert dataset.meta.info.codebase_version == "v3.0"
    assert dataset.meta.robot_type == "so_follower" and dataset.fps == 30
    assert dataset.num_episodes == 3
    assert dataset.features["observation.state"]["names"] == [f"{j}.pos" for j in JOINTS]
    assert dataset.features["observation.images.top"]["shape"] == (48, 64, 3)
    assert dataset.features["observation.images.top"]["dtype"] == "video"
    assert dataset.features["observation.environment_state"]["shape"] == (7,)

    verdicts = []
    for episode_index, directory in enumerate(sorted(bags.glob("episode_00000[01]"))):
        verdicts.append(bag_verdict(directory))
        states = bag_messages(directory, "/joint_states")
        frames = bag_messages(directory, "/camera/top/image_raw")
        start, stop = (
            dataset.meta.episodes["dataset_from_index"][episode_index],
            dataset.meta.episodes["dataset_to_index"][episode_index],
        )
        count = stop - start
        span = min(states[-1][0], frames[-1][0]) - max(states[0][0], frames[0][0])
        assert abs(count - span * 30) <= 2, f"episode {episode_index}: {count} frames for {span:.2f} s at 30 fps"
        # Every state row is the bag's joint state (in LeRobot units) in force at its frame's
        # instant, the frames 1/30 s apart: the instant of frame 0 fits them all. (At rest the arm
        # publishes one state many times, so a frame alone may match many instants.)
        times = np.array([stamp for stamp, _ in states])
        table = np.stack([lerobot_units([dict(zip(m.name, m.position))[j] for j in JOINTS]) for _, m in states])
        sampled = []
        for k in range(start, stop, 7):
            item = dataset[k]
            sampled.append((k - start, item["observation.state"].numpy().astype(np.float64)))
            assert item["task"] == "put the cube in the bin"
            assert tuple(item["observation.images.top"].shape) == (3, 48, 64)
        allowed = frame_zero_instants(times, table, sampled, 30.0, 1e-3)
        assert allowed, f"episode {episode_index}: no 30 fps grid of the bag's joint states gives the state rows"
        assert allowed[-1][1] - allowed[0][0] < 1 / 30, f"episode {episode_index}: frame 0 not pinned down: {allowed}"
        first_instant = (allowed[0][0] + allowed[-1][1]) / 2
        # The video frame matches the bag's image of that instant.
        k = start + count // 2
        item = dataset[k]
        instant = first_instant + (k - start) / 30
        stamp, image = min(frames, key=lambda pair: abs(pair[0] - instant))
        original = np.frombuffer(bytes(image.data), dtype=np.uint8).reshape(48, 64, 3).astype(np.float64)
        decoded = item["observation.images.top"].numpy().transpose(1, 2, 0) * 255.0
        assert np.abs(decoded - original).mean() < 25, f"video frame {k} far from the bag's image at {stamp}"
        # Actions are commands within the joint limits, in LeRobot units; the bag's verdict shows
        # on the last frame (the expert's, which through the stack is timing's to decide: ~99 %).
        actions = np.stack([dataset[i]["action"].numpy() for i in range(start, stop, 10)])
        assert actions[:, 5].min() < 5 and actions[:, 5].max() > 50, "the gripper never closed and opened in the actions"
        last = dataset[stop - 1]
        assert bool(last["next.success"].item()) is verdicts[-1], f"episode {episode_index}: not the bag's verdict"
        # The environment state is the bag's /cube/pose of the frame's instant: the cube starts on
        # the table and ends in the bin (positions that differ), always a unit quaternion.
        poses = bag_messages(directory, "/cube/pose")
        first, final = dataset[start]["observation.environment_state"].numpy(), last["observation.environment_state"].numpy()
        for row, instant in ((first, first_instant), (final, first_instant + (stop - 1 - start) / 30)):
            _, pose = min(poses, key=lambda pair: abs(pair[0] - instant))
            expected = [pose.pose.position.x, pose.pose.position.y, pose.pose.position.z, pose.pose.orientation.w]
            assert np.allclose(row[:4], expected, atol=2e-3), (row, expected)
            assert abs(np.linalg.norm(row[3:]) - 1.0) < 1e-4, row
        if verdicts[-1]:
            assert np.linalg.norm(final[:3] - first[:3]) > 0.05, "the cube did not move in the environment state"

    # Replayed on a fresh sim with the same seed (its k-th /sim/reset puts the cube where the k-th
    # episode had it), a successful episode's actions put the cube in the bin again. In lockstep,
    # one sim period per frame: in real time, beside a training, a replay once missed the bin.
    from std_msgs.msg import Bool
    from std_srvs.srv import Trigger

    assert any(verdicts), "the expert failed both episodes"
    replayed = verdicts.index(True)
    replay_sim = sim_factory(
        "--seed", "3", "--cameras", "none", "--namespace", "replay", "--lockstep", "--step-on-command", "--rate", "30"
    )  # fmt: skip
    for _ in range(replayed):  # the draws of the episodes before it
        assert ros.call(Trigger, "/replay/sim/reset", sim=replay_sim).success
    success = ros.subscribe("/replay/task/success", Bool, best_effort_qos())
    done = subprocess.run(
        [
            str(REPLAY),
            str(output),
            "--repo-id",
            "local/so101_test",
            "--episode",
            str(replayed),
            "--reset",
            "--namespace",
            "replay",
            "--ramp",
            "1",
            "--lockstep",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0 and "replayed" in done.stdout, done.stdout + done.stderr
    wait_until(lambda: success.count() > 0 and success.latest().data, 5.0, "/task/success after the replay")

    # The same bags for a small vision policy: one camera, scaled, no environment state.
    small = tmp_path / "small"
    done = subprocess.run(
        [
            str(CONVERTER),
            str(bags),
            "--output",
            str(small),
            "--repo-id",
            "local/so101_small",
            "--quiet",
            "--cameras",
            "top",
            "--image-size",
            "32x24",
            "--no-environment-state",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    scaled = LeRobotDataset("local/so101_small", root=small)
    assert scaled.num_episodes == 3 and scaled.num_frames == dataset.num_frames
    assert [k for k in scaled.features if k.startswith("observation.")] == ["observation.state", "observation.images.top"]
    assert scaled.features["observation.images.top"]["shape"] == (24, 32, 3)
    assert tuple(scaled[0]["observation.images.top"].shape) == (3, 24, 32)
