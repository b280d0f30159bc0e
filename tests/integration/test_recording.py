"""recorder_node end to end: bags read back by an independent reader (Python mcap +
mcap-ros2-support) field by field, rosbag2 metadata, lossless recording at the stack's load,
episodes from events and services, compression and splitting, kill -9 and a full disk."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import time
from pathlib import Path

import yaml

from harness import JOINT_NAMES, node_binary, node_environment, reliable_qos, wait_until
from recording_harness import (
    LOAD_PUBLISHER,
    RECORDER,
    episode_dirs,
    expected_image,
    mcap_files,
    metadata,
    read_bag,
    run_load_publisher,
    stream_messages,
    topic_counts,
)


def wait_recording(recorder, timeout: float = 15.0) -> None:
    wait_until(lambda: "recording into" in recorder.log(), timeout, "the recorder to start its episode", recorder)


def test_a_sim_episode_reads_back_as_a_rosbag2_bag(sim_factory, recorder_factory):
    sim = sim_factory()
    recorder = recorder_factory("--start", "--task", "watch the arm")
    wait_recording(recorder)
    time.sleep(2.5)
    assert recorder.stop() == 0, recorder.log_tail()

    [episode] = episode_dirs(recorder.output)
    assert episode.name == "episode_000000"
    meta = metadata(episode)
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap" and meta["ros_distro"] == "jazzy"
    counts = topic_counts(meta)
    assert counts["/joint_states"] >= 150, counts
    for topic in ("/task/reward", "/task/success", "/cube/pose"):
        assert counts[topic] >= 150, counts
    assert meta["message_count"] == sum(counts.values())
    custom = meta["custom_data"]
    assert custom["task"] == "watch the arm" and custom["episode_index"] == "0" and custom["dropped_messages"] == "0"
    assert custom["success"] in ("true", "false")  # from /task/success: the sim publishes it
    for topic in meta["topics_with_message_count"]:
        [qos] = topic["topic_metadata"]["offered_qos_profiles"]
        assert qos["reliability"] == "reliable" and qos["history"] == "keep_last"
        assert topic["topic_metadata"]["serialization_format"] == "cdr"

    [path] = mcap_files(episode)
    assert [f["path"] for f in meta["files"]] == [path.name]
    header, summary, messages, records = read_bag(path)
    assert header.profile == "ros2"
    schemas = {s.name: s for s in summary.schemas.values()}
    assert all(s.encoding == "ros2msg" for s in schemas.values())
    assert "MSG: std_msgs/Header" in schemas["sensor_msgs/msg/JointState"].data.decode()
    by_topic = {c.topic: c for c in summary.channels.values()}
    for topic, count in counts.items():
        channel = by_topic[topic]
        assert channel.message_encoding == "cdr"
        assert yaml.safe_load(channel.metadata["offered_qos_profiles"])[0]["reliability"] == "reliable"
        assert summary.statistics.channel_message_counts[channel.id] == count
        assert sum(1 for t, _, _ in messages if t == topic) == count

    joints = [(m, ros) for t, m, ros in messages if t == "/joint_states"]
    stamps = []
    for record, ros in joints:
        assert list(ros.name) == JOINT_NAMES
        assert len(ros.position) == 6 and all(math.isfinite(p) for p in ros.position)
        assert record.publish_time <= record.log_time + 50_000_000
        stamps.append(ros.header.stamp.sec + ros.header.stamp.nanosec * 1e-9)
    assert stamps == sorted(stamps) and stamps[-1] > stamps[0]

    assert set(records) == {"rosbag2", "episode"}
    embedded = yaml.safe_load(records["rosbag2"]["serialized_metadata"])["rosbag2_bagfile_information"]
    assert topic_counts(embedded) == counts
    assert records["episode"]["task"] == "watch the arm"
    assert sim.alive()


def test_nothing_is_lost_at_the_stacks_load_and_images_survive_byte_for_byte(recorder_factory):
    recorder = recorder_factory("--start")
    wait_recording(recorder)
    report = run_load_publisher("--cameras", "top,front", "--camera-rate", "30", "--joint-rate", "500", "--duration", "5")
    time.sleep(1.0)
    assert recorder.stop() == 0, recorder.log_tail()
    assert all(count == 0 for count in report["failed"].values()), report

    [episode] = episode_dirs(recorder.output)
    meta = metadata(episode)
    assert topic_counts(meta) == report["published"], (topic_counts(meta), report)
    assert meta["custom_data"]["dropped_messages"] == "0"

    [path] = mcap_files(episode)
    _, _, messages, _ = read_bag(path)
    import numpy as np

    for camera in ("top", "front"):
        frames = [ros for t, _, ros in messages if t == f"/camera/{camera}/image_raw"]
        assert len(frames) == report["published"][f"/camera/{camera}/image_raw"]
        for k, image in enumerate(frames):
            assert (image.height, image.width, image.encoding, image.step) == (480, 640, "rgb8", 1920)
            assert image.header.frame_id == f"camera_{camera}"
            data = np.frombuffer(bytes(image.data), dtype=np.uint8)
            assert data.size == 640 * 480 * 3
            assert data[0] == k % 256 and data[1] == (7 + k) % 256, f"{camera} frame {k} out of order"
            if k in (0, len(frames) // 2, len(frames) - 1):
                assert np.array_equal(data, expected_image(k, data.size)), f"{camera} frame {k} differs"
    joints = [ros for t, _, ros in messages if t == "/joint_states"]
    for k, state in enumerate(joints):
        assert list(state.position) == [k * 0.001 + j for j in range(6)], f"joint state {k}"


def publish_event(pub, text: str) -> None:
    from std_msgs.msg import String

    pub.publish(String(data=text))
    time.sleep(0.4)


def test_episodes_follow_the_events(recorder_factory, ros):
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String

    recorder = recorder_factory("--task", "default task")
    events = ros.publisher("/episode/events", String, sim=recorder)
    commands = ros.publisher("/joint_commands", JointState, sim=recorder)
    # rclpy sees the recorder's readers a moment before they have matched its writers; a sample
    # sent in between arrives only with the next heartbeat repair, after the episode.
    time.sleep(1.5)
    publish_event(events, 'start {"task": "pick the cube", "seed": 7}')
    for k in range(10):
        commands.publish(JointState(name=["gripper"], position=[k * 0.1]))
        time.sleep(0.02)
    publish_event(events, "success")
    publish_event(events, "stop")
    publish_event(events, "start")
    publish_event(events, "discard")
    publish_event(events, "start")
    publish_event(events, "failure")
    publish_event(events, "not an event")
    publish_event(events, "stop")

    episodes = episode_dirs(recorder.output)
    assert [e.name for e in episodes] == ["episode_000000", "episode_000001"], episodes
    first, second = (metadata(e) for e in episodes)
    assert first["custom_data"]["task"] == "pick the cube"
    assert first["custom_data"]["seed"] == "7"
    assert first["custom_data"]["success"] == "true"
    assert second["custom_data"]["success"] == "false"
    assert second["custom_data"]["task"] == "default task"
    _, _, messages, _ = read_bag(mcap_files(episodes[0])[0])
    sent = [ros.position[0] for t, _, ros in messages if t == "/joint_commands"]
    assert sent == [k * 0.1 for k in range(10)]
    texts = [ros.data for t, _, ros in messages if t == "/episode/events"]
    assert "success" in texts and "stop" in texts
    assert "episode event ignored" in recorder.log()


def test_services_drive_episodes_and_refuse_what_makes_no_sense(recorder_factory, ros):
    from std_srvs.srv import SetBool, Trigger

    recorder = recorder_factory()
    answer = ros.call(Trigger, "/recorder/stop", sim=recorder)
    assert not answer.success and "no episode" in answer.message
    answer = ros.call(Trigger, "/recorder/start", sim=recorder)
    assert answer.success, answer.message
    answer = ros.call(SetBool, "/recorder/mark_success", SetBool.Request(data=True), sim=recorder)
    assert answer.success, answer.message
    answer = ros.call(Trigger, "/recorder/stop", sim=recorder)
    assert answer.success and "success: true" in answer.message, answer.message
    answer = ros.call(Trigger, "/recorder/discard", sim=recorder)
    assert not answer.success
    [episode] = episode_dirs(recorder.output)
    assert metadata(episode)["custom_data"]["success"] == "true"


def test_zstd_chunks_and_split_files(sim_factory, recorder_factory):
    from mcap.reader import make_reader

    sim_factory("--rate", "200")
    recorder = recorder_factory("--start", "--compression", "zstd", "--split-duration", "1", "--chunk-size", "16384")
    wait_recording(recorder)
    time.sleep(3.6)
    assert recorder.stop() == 0
    [episode] = episode_dirs(recorder.output)
    meta = metadata(episode)
    files = mcap_files(episode)
    assert len(files) >= 3 and [f["path"] for f in meta["files"]] == [f.name for f in files]
    total = 0
    for path, entry in zip(files, meta["files"]):
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
        assert summary.chunk_indexes and all(c.compression == "zstd" for c in summary.chunk_indexes)
        assert summary.statistics.message_count == entry["message_count"]
        total += entry["message_count"]
    assert total == meta["message_count"]


def test_a_killed_recorder_leaves_every_closed_chunk_readable(sim_factory, recorder_factory):
    sim_factory("--rate", "100")
    recorder = recorder_factory("--start", "--chunk-size", "65536", "--max-chunk-age", "0.3")
    wait_recording(recorder)
    time.sleep(3.0)
    recorder.proc.send_signal(signal.SIGKILL)
    recorder.proc.wait(timeout=10)
    recorder.exit_expected = True
    [episode] = episode_dirs(recorder.output)
    assert not (episode / "metadata.yaml").exists()
    [path] = mcap_files(episode)
    messages, error = stream_messages(path)
    assert error is not None, "a killed writer's file has no footer"
    joints = [ros for topic, ros in messages if topic == "/joint_states"]
    # 3 s at 100 Hz, less the chunk that was open (at most 0.3 s) and start-up.
    assert len(joints) >= 200, f"only {len(joints)} joint states recovered"
    assert all(list(j.name) == JOINT_NAMES for j in joints)


def test_a_full_disk_is_reported_and_leaves_a_readable_file(tmp_path):
    script = tmp_path / "full_disk.sh"
    disk = tmp_path / "disk"
    disk.mkdir()
    script.write_text(
        f"""set -e
mount -t tmpfs -o size=4m tmpfs {disk}
{node_binary(RECORDER)} --output {disk}/bags --start --duration 6 > {tmp_path}/recorder.log 2>&1 &
recorder=$!
sleep 0.5
{node_binary(LOAD_PUBLISHER)} --duration 2 --wait-subscribers 2 > /dev/null
set +e
wait $recorder
echo "recorder exit $?"
cp -r {disk}/bags {tmp_path}/bags
"""
    )
    done = subprocess.run(
        ["unshare", "--mount", "--propagation", "private", "bash", str(script)],
        env=node_environment(), capture_output=True, text=True, timeout=60,
    )
    assert done.returncode == 0, f"could not run in a mount namespace with a small tmpfs: {done.stderr}"
    assert "recorder exit 0" in done.stdout, done.stdout + (tmp_path / "recorder.log").read_text()[-3000:]
    log = (tmp_path / "recorder.log").read_text()
    assert "No space left on device" in log, log[-3000:]
    [episode] = episode_dirs(tmp_path / "bags")
    assert not (episode / "metadata.yaml.tmp").exists()
    [path] = mcap_files(episode)
    messages, _ = stream_messages(path)
    assert len(messages) > 0, "nothing readable before the disk filled"


def test_bad_options_are_clear_errors(tmp_path):
    recorder = str(node_binary(RECORDER))
    done = subprocess.run([recorder, "--regex", "("], env=node_environment(), capture_output=True, text=True, timeout=30)
    assert done.returncode != 0 and "bad topic pattern" in done.stderr, done.stderr
    not_a_dir = tmp_path / "file"
    not_a_dir.write_text("x")
    done = subprocess.run([recorder, "--output", str(not_a_dir)], env=node_environment(), capture_output=True, text=True, timeout=30)
    assert done.returncode != 0 and str(not_a_dir) in done.stderr, done.stderr
    done = subprocess.run([recorder, "--compression", "gzip"], env=node_environment(), capture_output=True, text=True, timeout=30)
    assert done.returncode != 0
