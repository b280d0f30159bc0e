"""recorder_node end to end, read back with an independent reader (Python mcap + mcap-ros2-support):
the sim's topics recorded by default and checked field by field against rosbag2's metadata.yaml,
lossless recording of the stack's camera + joint load, episodes driven by /episode/events and by the
recorder's services, kill -9 (closed chunks survive), zstd + split files, a full disk, bad options.

Run inside the private network namespace (see conftest.py):
    SO101_BIN_DIR=$CARGO_TARGET_DIR/release scripts/isolated .venv/bin/python -m pytest -q tests/integration/test_recorder.py
"""

from __future__ import annotations

import json
import math
import shlex
import signal
import subprocess
import time
from pathlib import Path

import pytest
import yaml
from harness import JOINT_NAMES, node_binary, node_environment, reliable_qos, wait_until
from recorder_harness import (
    LOAD_PUBLISHER,
    RECORDER,
    SIM_RECORDED_TOPICS,
    ImagePattern,
    RecorderServices,
    all_finite,
    check_metadata_fields,
    check_qos_profiles,
    ends_with_magic,
    episode_dirs,
    load_metadata,
    mcap_files,
    read_bag,
    recover,
    run_load_publisher,
    stamp_ns,
    topic_counts,
    topic_types,
    wait_episode,
    wait_gone,
    wait_metadata,
)

# publish_time (the writer's DDS source timestamp) may not be after log_time (the recorder's
# receive time) by more than this: both are this machine's wall clock.
CLOCK_TOLERANCE_NS = 10_000_000
SIM_PERIOD_NS = 10_000_000  # so101_sim_node --rate 100
PHYSICS_STEP_NS = 2_000_000


def start_sim_and_wait(sim_factory, ros, rate: int = 100):
    """so101_sim_node --lite at `rate`, once its first /joint_states has arrived."""
    from sensor_msgs.msg import JointState

    sim = sim_factory("--rate", str(rate))
    ros.subscribe("/joint_states", JointState, reliable_qos(depth=100)).wait_count(1, 30.0, sim)
    return sim


def check_sim_joint_states(joints, minimum: int) -> None:
    """Recorded /joint_states of the sim at 100 Hz: names, finite positions, and sim-time stamps
    stepping by exactly one control period (a missing message shows as a double step)."""
    assert len(joints) >= minimum, f"only {len(joints)} /joint_states recorded (expected >= {minimum})"
    stamps = []
    for index, m in enumerate(joints):
        assert list(m.ros.name) == JOINT_NAMES, f"joint_states #{index} names {list(m.ros.name)}"
        assert len(m.ros.position) == 6 and all_finite(m.ros.position), f"joint_states #{index} positions {list(m.ros.position)}"
        assert len(m.ros.velocity) in (0, 6) and all_finite(m.ros.velocity), f"joint_states #{index} velocities"
        assert len(m.ros.effort) in (0, 6) and all_finite(m.ros.effort), f"joint_states #{index} efforts"
        stamps.append(stamp_ns(m.ros.header.stamp))
    steps = [b - a for a, b in zip(stamps, stamps[1:])]
    bad = [(i, s) for i, s in enumerate(steps) if abs(s - SIM_PERIOD_NS) > PHYSICS_STEP_NS]
    assert not bad, f"joint_states header stamps do not step by {SIM_PERIOD_NS} ns (lost or reordered messages): {bad[:10]}"


def check_times(messages, start_ns: int, stop_ns: int) -> None:
    """log_time (receive) within the episode, per topic in order; publish_time (source timestamp)
    before log_time, and really the writer's time, not a copy of log_time."""
    last: dict[str, int] = {}
    earlier = 0
    for m in messages:
        log, pub = m.record.log_time, m.record.publish_time
        assert start_ns - 500_000_000 <= log <= stop_ns, f"{m.topic}: log_time {log} outside the episode {start_ns}..{stop_ns}"
        assert 0 < pub <= log + CLOCK_TOLERANCE_NS, f"{m.topic}: publish_time {pub} vs log_time {log}"
        assert log >= last.get(m.topic, 0), f"{m.topic}: log_time goes backwards ({last[m.topic]} -> {log})"
        last[m.topic] = log
        earlier += pub < log
    assert earlier >= 0.9 * len(messages), (
        f"publish_time < log_time for only {earlier} of {len(messages)} messages: not the source timestamp?"
    )


# =========================================================================== 1. the sim, by default
def test_default_recording_of_the_sim_reads_back_as_a_rosbag2_bag(sim_factory, recorder_factory, ros):
    sim = start_sim_and_wait(sim_factory, ros)
    launched_ns = time.time_ns()
    recorder = recorder_factory("--start")
    episode = wait_episode(recorder.output, 0, recorder)
    time.sleep(2.0)
    before_stop_ns = time.time_ns()
    assert recorder.stop() == 0, f"SIGINT -> exit {recorder.proc.returncode}\n{recorder.log_tail()}"
    after_stop_ns = time.time_ns()
    sim.assert_alive()

    assert episode_dirs(recorder.output) == [episode] and episode.name == "episode_000000"
    assert sorted(p.name for p in episode.iterdir()) == ["episode_000000_0.mcap", "metadata.yaml"]
    info = load_metadata(episode)
    check_metadata_fields(info, episode)
    counts = topic_counts(info)
    types = topic_types(info)
    for topic, type_name in SIM_RECORDED_TOPICS.items():
        assert counts.get(topic, 0) > 0, f"{topic} not recorded: {counts}"
        assert types[topic] == type_name, (topic, types[topic])
    for topic in ("/clock", "/rosout", "/parameter_events"):
        assert topic not in counts, f"{topic} is not in the default set but was recorded: {counts}"
    assert info["compression_format"] == "" and info["compression_mode"] == ""
    custom = info["custom_data"]
    assert custom["episode_index"] == "0" and custom["task"] == "" and custom["seed"] == ""
    assert custom["dropped_messages"] == "0", custom
    assert launched_ns <= int(custom["start_time_ns"]) <= before_stop_ns, custom
    assert before_stop_ns <= int(custom["stop_time_ns"]) <= after_stop_ns, custom
    [file_entry] = info["files"]
    assert file_entry["path"] == "episode_000000_0.mcap" and file_entry["message_count"] == info["message_count"]

    bag = read_bag(episode / "episode_000000_0.mcap")
    assert bag.header.profile == "ros2", bag.header.profile
    stats = bag.summary.statistics
    assert stats.message_count == info["message_count"] == len(bag.messages), (
        stats.message_count,
        info["message_count"],
        len(bag.messages),
    )
    assert bag.channel_counts() == counts, (bag.channel_counts(), counts)
    decoded = {}
    for m in bag.messages:
        decoded[m.topic] = decoded.get(m.topic, 0) + 1
    assert decoded == counts, (decoded, counts)
    # rosbag2: starting_time is the earliest message, duration reaches the latest.
    start = info["starting_time"]["nanoseconds_since_epoch"]
    earliest = min(m.record.log_time for m in bag.messages)
    latest = max(m.record.log_time for m in bag.messages)
    assert stats.message_start_time == earliest and stats.message_end_time == latest
    first_written = bag.messages[0]
    assert start == earliest, (
        f"metadata.yaml starting_time {start} is not the earliest message ({earliest}, {(start - earliest) / 1e6:.3f} ms earlier); "
        f"it is the log_time of the first message in the file ({first_written.topic} @ {first_written.record.log_time})"
    )
    assert start + info["duration"]["nanoseconds"] == latest, "starting_time + duration is not the latest message"
    assert file_entry["starting_time"]["nanoseconds_since_epoch"] == start
    assert file_entry["duration"]["nanoseconds"] == info["duration"]["nanoseconds"]

    # Schemas: ros2msg, full names, the definitions of nested types included.
    schema_names = [s.name for s in bag.summary.schemas.values()]
    assert len(schema_names) == len(set(schema_names)), f"a schema written twice: {schema_names}"
    nested = {
        "sensor_msgs/msg/JointState": ["MSG: std_msgs/Header", "MSG: builtin_interfaces/Time"],
        "geometry_msgs/msg/PoseStamped": ["MSG: geometry_msgs/Pose", "MSG: geometry_msgs/Point", "MSG: geometry_msgs/Quaternion"],
        "diagnostic_msgs/msg/DiagnosticArray": ["MSG: diagnostic_msgs/DiagnosticStatus", "MSG: diagnostic_msgs/KeyValue"],
    }
    qos_by_topic = {
        t["topic_metadata"]["name"]: t["topic_metadata"]["offered_qos_profiles"] for t in info["topics_with_message_count"]
    }
    assert len(bag.summary.channels) == len(counts), [c.topic for c in bag.summary.channels.values()]
    for channel in bag.summary.channels.values():
        schema = bag.summary.schemas[channel.schema_id]
        assert schema.encoding == "ros2msg", (channel.topic, schema.encoding)
        assert schema.name == types[channel.topic], (channel.topic, schema.name)
        text = schema.data.decode()
        for needle in nested.get(schema.name, []):
            assert needle in text, f"schema {schema.name} lacks {needle!r}:\n{text}"
        assert channel.message_encoding == "cdr", (channel.topic, channel.message_encoding)
        assert set(channel.metadata) == {"offered_qos_profiles", "topic_type_hash"}, (channel.topic, dict(channel.metadata))
        profiles = check_qos_profiles(channel.metadata["offered_qos_profiles"], f"channel {channel.topic}")
        assert all(p["reliability"] == "reliable" for p in profiles), (channel.topic, profiles)
        assert profiles == qos_by_topic[channel.topic], f"{channel.topic}: channel QoS differs from metadata.yaml"

    check_times(bag.messages, int(custom["start_time_ns"]), int(custom["stop_time_ns"]))
    # ~2 s at 100 Hz, less the subscription's match at the start; nothing lost in between.
    check_sim_joint_states(bag.on("/joint_states"), minimum=150)
    assert all(math.isfinite(m.ros.data) for m in bag.on("/task/reward"))
    for m in bag.on("/cube/pose"):
        q = m.ros.pose.orientation
        assert abs(q.w**2 + q.x**2 + q.y**2 + q.z**2 - 1.0) < 1e-3, f"/cube/pose orientation {q} is not a unit quaternion"
    assert any(s.name for m in bag.on("/diagnostics") for s in m.ros.status), "empty DiagnosticArrays"
    # An unmarked episode takes the last /task/success seen during it.
    last_success = bag.on("/task/success")[-1].ros.data
    assert custom["success"] == ("true" if last_success else "false"), (custom["success"], last_success)

    # Metadata records written when the file was closed.
    assert sorted(bag.record_names) == ["episode", "rosbag2"], bag.record_names
    assert set(bag.records["rosbag2"]) == {"serialized_metadata"}, list(bag.records["rosbag2"])
    embedded = yaml.safe_load(bag.records["rosbag2"]["serialized_metadata"])
    assert embedded == yaml.safe_load((episode / "metadata.yaml").read_text()), "the rosbag2 record differs from metadata.yaml"
    assert bag.records["episode"] == custom, (bag.records["episode"], custom)


# =========================================================================== 2. the stack's load
def test_nothing_is_lost_at_the_stacks_load_and_every_byte_survives(recorder_factory, tmp_path):
    recorder = recorder_factory("--start")
    episode = wait_episode(recorder.output, 0, recorder)
    report = run_load_publisher(
        "--cameras", "top,front", "--width", "640", "--height", "480", "--camera-rate", "30",
        "--joint-rate", "500", "--duration", "5", log_path=tmp_path / "load_publisher.log",
    )  # fmt: skip
    time.sleep(1.0)
    assert recorder.stop() == 0, recorder.log_tail()
    published = report["published"]
    cameras = {"/camera/top/image_raw": "camera_top", "/camera/front/image_raw": "camera_front"}
    assert set(published) == {"/joint_states", *cameras}, report
    assert all(v == 0 for v in report.get("failed", {}).values()), f"the publisher itself failed to publish: {report}"
    assert published["/joint_states"] >= 0.9 * 500 * 5 and all(published[c] >= 0.9 * 30 * 5 for c in cameras), report

    info = load_metadata(episode)
    check_metadata_fields(info, episode)
    assert topic_counts(info) == published, f"recorded {topic_counts(info)}, published {published}"
    assert info["custom_data"]["dropped_messages"] == "0", info["custom_data"]
    types = topic_types(info)
    assert types["/joint_states"] == "sensor_msgs/msg/JointState" and all(types[c] == "sensor_msgs/msg/Image" for c in cameras), (
        types
    )

    paths = mcap_files(episode)
    assert len(paths) == 1
    bag = read_bag(paths[0])
    assert bag.channel_counts() == published
    pattern = ImagePattern(640 * 480 * 3)
    for topic, frame_id in cameras.items():
        frames = bag.on(topic)
        assert len(frames) == published[topic]
        previous_stamp = 0
        for k, m in enumerate(frames):
            image = m.ros
            fields = (image.height, image.width, image.encoding, image.is_bigendian, image.step, image.header.frame_id)
            assert fields == (480, 640, "rgb8", 0, 1920, frame_id), f"{topic} #{k}: {fields}"
            data = bytes(image.data)
            assert len(data) == 640 * 480 * 3, f"{topic} #{k}: {len(data)} bytes"
            assert (data[0], data[1]) == (k % 256, (7 + k) % 256), f"{topic} #{k} is frame {data[0]} (mod 256): lost or reordered"
            assert pattern.matches(data, k), f"{topic} frame {k}: {pattern.first_mismatch(data, k)}"
            stamp = stamp_ns(image.header.stamp)
            assert stamp > previous_stamp, f"{topic} #{k}: header stamps not increasing"
            previous_stamp = stamp
            # The source timestamp is taken just after the header's wall-clock stamp.
            assert -5_000_000 <= m.record.publish_time - stamp <= 200_000_000, (
                f"{topic} #{k}: publish_time - stamp = {m.record.publish_time - stamp} ns"
            )
    joints = bag.on("/joint_states")
    assert len(joints) == published["/joint_states"]
    for k, m in enumerate(joints):
        assert list(m.ros.name) == JOINT_NAMES, f"joint_states #{k}: {list(m.ros.name)}"
        expected = [k * 0.001 + j for j in range(6)]
        assert list(m.ros.position) == expected, f"joint_states #{k}: {list(m.ros.position)} != {expected}"
        assert len(m.ros.velocity) == 0 and len(m.ros.effort) == 0
    custom = info["custom_data"]
    check_times(bag.messages, int(custom["start_time_ns"]), int(custom["stop_time_ns"]))


# =========================================================================== 3. /episode/events
def test_the_bag_directory_opens_in_rosbags_as_a_rosbag2_bag(recorder_factory, tmp_path):
    """A second, independent reader: rosbags parses metadata.yaml and the MCAP storage the way
    rosbag2 does, and decodes the CDR with its own Jazzy type definitions."""
    import numpy as np
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    recorder = recorder_factory("--start")
    episode = wait_episode(recorder.output, 0, recorder)
    report = run_load_publisher(
        "--cameras", "wrist", "--camera-rate", "30", "--joint-rate", "100", "--duration", "2",
        "--wait-subscribers", "2", log_path=tmp_path / "load_publisher.log",
    )  # fmt: skip
    time.sleep(1.0)
    assert recorder.stop() == 0, recorder.log_tail()
    info = load_metadata(episode)
    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(episode) as bag:
        assert bag.message_count == info["message_count"] == sum(report["published"].values())
        assert bag.duration > 1_500_000_000, bag.duration
        counts = {c.topic: c.msgcount for c in bag.connections}
        assert counts == report["published"], counts
        assert {c.topic: c.msgtype for c in bag.connections} == {
            "/joint_states": "sensor_msgs/msg/JointState",
            "/camera/wrist/image_raw": "sensor_msgs/msg/Image",
        }
        joints, images = 0, 0
        for connection, _, raw in bag.messages():
            message = store.deserialize_cdr(raw, connection.msgtype)
            if connection.topic == "/joint_states":
                assert list(message.position) == [joints * 0.001 + j for j in range(6)]
                joints += 1
            else:
                assert (message.height, message.width, message.encoding) == (480, 640, "rgb8")
                expected = ((np.arange(16) * 7 + images) % 256).astype(np.uint8)
                assert np.array_equal(message.data[:16], expected), f"image {images}"
                images += 1
    assert (joints, images) == (report["published"]["/joint_states"], report["published"]["/camera/wrist/image_raw"])


def test_episodes_follow_the_events_topic(recorder_factory, ros):
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String

    recorder = recorder_factory("--task", "default task")
    output = recorder.output
    events = ros.publisher("/episode/events", String, wait_for_subscriber=None)
    commands = ros.publisher("/joint_commands", JointState, wait_for_subscriber=None)
    # The recorder reads /episode/events twice: to act on it, and to record it.
    wait_until(lambda: events.get_subscription_count() >= 2, 20.0, "the recorder's two readers of /episode/events", recorder)
    wait_until(lambda: commands.get_subscription_count() >= 1, 20.0, "the recorder's reader of /joint_commands", recorder)
    # rclpy sees the readers before the recorder's side has matched this writer; a sample sent in
    # between would only arrive with a later reliable repair.
    time.sleep(1.5)
    assert episode_dirs(output) == [], "an episode started without --start or a start event"

    def send(text: str) -> None:
        events.publish(String(data=text))

    send('start {"task": "pick the cube", "seed": 7}')
    first = wait_episode(output, 0, recorder)
    sent = []
    for k in range(20):
        msg = JointState(name=list(JOINT_NAMES), position=[k * 0.01 + j for j in range(6)])
        msg.header.frame_id = f"command {k}"
        commands.publish(msg)
        sent.append(msg)
        time.sleep(0.01)
    time.sleep(0.5)
    send("success")
    time.sleep(0.4)  # let the success event be recorded too before the episode ends
    send("stop")
    first_info = wait_metadata(first, recorder)

    send("start")
    second = wait_episode(output, 1, recorder)
    send("discard")
    wait_gone(second, recorder)
    send("start")
    assert wait_episode(output, 1, recorder) == second, "a discarded episode's number is used again"
    time.sleep(0.3)
    send("failure")
    time.sleep(0.4)
    send("stop")
    second_info = wait_metadata(second, recorder)
    time.sleep(0.5)
    assert [e.name for e in episode_dirs(output)] == ["episode_000000", "episode_000001"], episode_dirs(output)
    recorder.assert_alive()

    check_metadata_fields(first_info, first)
    custom = first_info["custom_data"]
    assert (custom["episode_index"], custom["task"], custom["seed"], custom["success"]) == ("0", "pick the cube", "7", "true"), (
        custom
    )
    bag = read_bag(mcap_files(first)[0])
    assert bag.records["episode"] == custom
    recorded = bag.on("/joint_commands")
    assert [m.ros.header.frame_id for m in recorded] == [f"command {k}" for k in range(20)], (
        "joint_commands lost, added or reordered"
    )
    for m, msg in zip(recorded, sent):
        assert list(m.ros.name) == JOINT_NAMES and list(m.ros.position) == list(msg.position)
        # The CDR bytes as received: rclpy's own decoder gives the sent message back (no byte
        # comparison with serialize_message: rclpy leaves junk in alignment padding and pads the end).
        raw = bytes(m.record.data)
        assert raw[:4] == b"\x00\x01\x00\x00", f"{m.ros.header.frame_id}: not little-endian CDR: {raw[:4]!r}"
        assert deserialize_message(raw, JointState) == msg, f"{m.ros.header.frame_id}: rclpy decodes something else"
    texts = [m.ros.data for m in bag.on("/episode/events")]
    assert "success" in texts, f"events recorded in episode 0: {texts}"
    assert set(texts) <= {'start {"task": "pick the cube", "seed": 7}', "success", "stop"}, texts
    if 'start {"task": "pick the cube", "seed": 7}' in texts:
        assert texts[0].startswith("start"), texts

    check_metadata_fields(second_info, second)
    custom = second_info["custom_data"]
    assert (custom["episode_index"], custom["task"], custom["seed"], custom["success"]) == ("1", "default task", "", "false"), (
        custom
    )
    bag = read_bag(mcap_files(second)[0])
    assert not bag.on("/joint_commands"), "joint_commands of episode 0 leaked into episode 1"
    texts = [m.ros.data for m in bag.on("/episode/events")]
    assert "failure" in texts and "discard" not in texts, f"events recorded in episode 1: {texts}"


# =========================================================================== 4. services
def test_services_drive_episodes_and_refuse_when_nothing_is_recorded(recorder_factory, ros):
    recorder = recorder_factory()
    output = recorder.output
    services = RecorderServices(ros, recorder)
    call = services.call

    answer = call("start")
    assert answer.success, answer.message
    first = wait_episode(output, 0, recorder)
    answer = call("mark_success", True)
    assert answer.success, answer.message
    answer = call("stop")
    assert answer.success, answer.message
    info = wait_metadata(first, recorder)
    check_metadata_fields(info, first)
    assert info["custom_data"]["success"] == "true", info["custom_data"]

    answer = call("stop")
    assert not answer.success and answer.message.strip(), f"a second stop answered {answer}"
    answer = call("discard")
    assert not answer.success and answer.message.strip(), f"discard with nothing recorded answered {answer}"
    answer = call("mark_success", False)
    assert not answer.success and answer.message.strip(), f"mark_success with nothing recorded answered {answer}"
    assert episode_dirs(output) == [first], "a refused call changed the bags"
    assert load_metadata(first)["custom_data"]["success"] == "true", "a refused mark_success changed a closed episode"

    # Discard a running episode: its directory goes and its number is used again.
    assert call("start").success
    second = wait_episode(output, 1, recorder)
    answer = call("discard")
    assert answer.success, answer.message
    wait_gone(second, recorder)
    assert call("start").success
    assert wait_episode(output, 1, recorder) == second
    answer = call("mark_success", False)
    assert answer.success, answer.message
    assert call("stop").success
    info = wait_metadata(second, recorder)
    assert info["custom_data"]["success"] == "false" and info["custom_data"]["episode_index"] == "1", info["custom_data"]
    assert [e.name for e in episode_dirs(output)] == ["episode_000000", "episode_000001"]
    services.close()


def test_once_ready_answers_yes_an_episode_holds_a_new_stream_from_its_first_period(recorder_factory, ros):
    """/recorder/ready, as a timed session asks it before its first episode: yes with nothing
    published; while a new publisher's samples would not reach the recorder, no, naming its topic;
    then yes, and an episode started at once holds the stream from its first period on, none lost."""
    from std_msgs.msg import String

    recorder = recorder_factory("--topics", "/ready_probe")
    services = RecorderServices(ros, recorder)
    answer = services.call("ready")
    assert answer.success, f"nothing is published, yet: {answer.message}"

    published = []
    publisher = ros.node.create_publisher(String, "/ready_probe", reliable_qos(100))

    def publish() -> None:
        publisher.publish(String(data=str(len(published))))
        published.append(time.time_ns())

    timer = ros.node.create_timer(0.01, publish)
    waiting = []
    deadline = time.monotonic() + 10.0
    while not (answer := services.call("ready")).success:
        waiting.append(answer.message)
        assert time.monotonic() < deadline, f"still not ready after 10 s: {answer.message}"
    assert set(waiting) <= {"not receiving yet: /ready_probe"}, waiting

    assert services.call("start").success
    episode = wait_episode(recorder.output, 0, recorder)
    time.sleep(0.5)
    assert services.call("stop").success
    ros.node.destroy_timer(timer)
    info = wait_metadata(episode, recorder)
    began = int(info["custom_data"]["start_time_ns"])
    stream = read_bag(mcap_files(episode)[0]).on("/ready_probe")
    # The publisher's 100 Hz, and a loaded machine's delay of its timer, are not measured here: only
    # that the first sample published after the start is in, and none after it is missing.
    after_start = [k for k, stamp in enumerate(published) if stamp > began + 5_000_000]
    counters = [int(m.ros.data) for m in stream]
    assert counters and counters[0] <= after_start[0], (
        f"the episode's first sample is #{counters[:1]}; #{after_start[0]} was published after its start"
    )
    assert counters == list(range(counters[0], counters[0] + len(counters))), f"samples lost: {counters}"
    services.close()


# =========================================================================== 5. kill -9
def test_after_kill_9_every_closed_chunk_is_readable(sim_factory, recorder_factory, ros):
    start_sim_and_wait(sim_factory, ros)
    recorder = recorder_factory("--start", "--chunk-size", "65536", "--max-chunk-age", "0.3")
    episode = wait_episode(recorder.output, 0, recorder)
    time.sleep(3.0)
    recorder.exit_expected = True
    killed_ns = time.time_ns()
    recorder.proc.kill()
    recorder.proc.wait(timeout=10)
    assert recorder.proc.returncode == -signal.SIGKILL

    assert not (episode / "metadata.yaml").exists(), "a killed recorder cannot have closed the episode"
    [path] = mcap_files(episode)
    assert not ends_with_magic(path), "a killed writer's file cannot have its footer"
    got = recover(path)
    assert not got.footer
    joints = got.on("/joint_states")
    # 3 s at 100 Hz, less at most one open chunk (0.3 s) and the subscription's match at the start.
    assert len(joints) >= (3.0 - 0.8) * 100, f"only {len(joints)} /joint_states recovered (reader stopped by {got.error!r})"
    check_sim_joint_states(joints, minimum=1)
    last_log = max(m.record.log_time for m in got.messages)
    assert killed_ns - last_log <= 800_000_000, (
        f"the newest recovered message is {(killed_ns - last_log) / 1e9:.2f} s older than the kill (--max-chunk-age 0.3)"
    )
    for topic in ("/task/reward", "/task/success", "/cube/pose"):
        assert got.on(topic), f"nothing of {topic} recovered"


# =========================================================================== 6. zstd + split
def test_zstd_chunks_and_split_by_duration(sim_factory, recorder_factory, ros):
    start_sim_and_wait(sim_factory, ros)
    recorder = recorder_factory("--start", "--compression", "zstd", "--split-duration", "1")
    episode = wait_episode(recorder.output, 0, recorder)
    time.sleep(3.5)
    recorder.proc.send_signal(signal.SIGTERM)  # SIGTERM ends an episode like SIGINT
    try:
        recorder.proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        pytest.fail(f"the recorder did not exit on SIGTERM:\n{recorder.log_tail()}", pytrace=False)
    assert recorder.stop() == 0, f"SIGTERM -> exit {recorder.proc.returncode}\n{recorder.log_tail()}"

    info = load_metadata(episode)
    check_metadata_fields(info, episode)
    paths = mcap_files(episode)
    assert len(info["files"]) >= 3 and len(paths) == len(info["files"]), (info["files"], paths)
    totals: dict[str, int] = {}
    for path, entry in zip(paths, info["files"]):
        bag = read_bag(path)
        assert bag.header.profile == "ros2"
        chunks = bag.summary.chunk_indexes
        assert chunks and all(c.compression == "zstd" for c in chunks), f"{path.name}: {[c.compression for c in chunks]}"
        assert all(c.compressed_size < c.uncompressed_size for c in chunks), f"{path.name}: chunks not smaller compressed"
        assert bag.summary.statistics.message_count == entry["message_count"] == len(bag.messages), path.name
        logs = [m.record.log_time for m in bag.messages]
        assert entry["starting_time"]["nanoseconds_since_epoch"] == min(logs), (
            f"{path.name}: files[].starting_time {entry['starting_time']['nanoseconds_since_epoch']} is not its earliest message "
            f"({min(logs)}, {(entry['starting_time']['nanoseconds_since_epoch'] - min(logs)) / 1e6:.3f} ms earlier) "
            f"but its first written one ({bag.messages[0].topic} @ {logs[0]})"
        )
        assert entry["duration"]["nanoseconds"] == max(logs) - min(logs), f"{path.name}: duration"
        assert max(logs) - min(logs) <= 1_200_000_000, (
            f"{path.name} spans {(max(logs) - min(logs)) / 1e9:.2f} s with --split-duration 1"
        )
        for topic, count in bag.channel_counts().items():
            totals[topic] = totals.get(topic, 0) + count
    assert sum(f["message_count"] for f in info["files"]) == info["message_count"]
    assert totals == topic_counts(info), (totals, topic_counts(info))
    # The last file's rosbag2 record is the final metadata.yaml.
    assert yaml.safe_load(bag.records["rosbag2"]["serialized_metadata"]) == yaml.safe_load(
        (episode / "metadata.yaml").read_text()
    )


# =========================================================================== 7. a full disk
FULL_DISK_SCRIPT = """
set -u
disk={disk}; work={work}
mount -t tmpfs -o size=4m tmpfs "$disk" || {{ echo "MOUNT FAILED"; exit 97; }}
# 1 MiB of ballast, freed once the disk is full (as an operator would).
head -c 1048576 /dev/zero > "$disk/ballast"
{recorder} --output "$disk/bags" --start > "$work/recorder.log" 2>&1 &
rec=$!
for i in $(seq 400); do [ -f "$disk/bags/episode_000000/episode_000000_0.mcap" ] && break; sleep 0.05; done
{publisher} --cameras top,front --camera-rate 30 --joint-rate 500 --duration 2 --wait-subscribers 2 \\
    > "$work/publisher.out" 2> "$work/publisher.err"
echo "publisher exit $?"
sleep 1
df -k "$disk" > "$work/df.txt"
if kill -0 $rec 2>/dev/null; then echo "recorder alive after the disk filled"; fi
rm -f "$disk/ballast"
touch "$work/space_freed"
# The test drives the recorder through its services meanwhile.
for i in $(seq 600); do [ -f "$work/finish" ] && break; sleep 0.05; done
kill -INT $rec
wait $rec
echo "recorder exit $?"
cp -a "$disk/bags" "$work/bags"
"""


def test_a_full_disk_is_reported_and_what_was_written_stays_readable(tmp_path, ros):
    from sensor_msgs.msg import JointState

    probe = subprocess.run(["unshare", "--mount", "--propagation", "private", "true"], capture_output=True, text=True)
    if probe.returncode != 0:
        pytest.fail(
            f"cannot create a mount namespace for the small tmpfs (unshare --mount refused): {probe.stderr.strip()}",
            pytrace=False,
        )
    disk = tmp_path / "disk"
    disk.mkdir()
    script = FULL_DISK_SCRIPT.format(
        disk=shlex.quote(str(disk)),
        work=shlex.quote(str(tmp_path)),
        recorder=shlex.quote(str(node_binary(RECORDER))),
        publisher=shlex.quote(str(node_binary(LOAD_PUBLISHER))),
    )
    # Same network namespace as this test (its rclpy peer reaches the recorder), own mount namespace.
    proc = subprocess.Popen(
        ["unshare", "--mount", "--propagation", "private", "bash", "-c", script],
        env=node_environment(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    log_path = tmp_path / "recorder.log"
    answers = {}
    sent = 10
    try:
        deadline = time.monotonic() + 40
        while not (tmp_path / "space_freed").exists():
            if proc.poll() is not None or time.monotonic() > deadline:
                out, err = proc.communicate(timeout=30) if proc.poll() is not None else ("", "")
                pytest.fail(f"the full-disk script did not reach the freed-space phase:\n{out}\n{err[-2000:]}", pytrace=False)
            time.sleep(0.05)
        # The node keeps running for the next episode: close the failed one, record another.
        services = RecorderServices(ros, None)
        answers["stop failed episode"] = services.call("stop")
        answers["start next episode"] = services.call("start")
        commands = ros.publisher("/joint_commands", JointState, wait_for_subscriber=None)
        wait_until(lambda: commands.get_subscription_count() >= 1, 15.0, "the recorder's reader of /joint_commands")
        time.sleep(1.0)
        for k in range(sent):
            commands.publish(JointState(name=["gripper"], position=[k * 0.1]))
            time.sleep(0.02)
        time.sleep(0.5)
        answers["stop next episode"] = services.call("stop")
        services.close()
    finally:
        (tmp_path / "finish").touch()
        try:
            out, err = proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, err = proc.communicate()
    log = log_path.read_text(errors="replace") if log_path.exists() else "<no recorder log>"
    context = f"script stdout:\n{out}\nstderr:\n{err[-2000:]}\nrecorder log:\n{log[-4000:]}"
    assert proc.returncode == 0 and "MOUNT FAILED" not in out, f"the full-disk script failed ({proc.returncode}):\n{context}"
    assert "publisher exit 0" in out, context
    assert "recorder alive after the disk filled" in out, f"the recorder died when the disk filled:\n{context}"
    assert "recorder exit 0" in out, f"the recorder did not exit 0 on SIGINT after the full disk:\n{context}"
    errors = [line for line in log.splitlines() if "No space left on device" in line]
    assert errors, f"no log line names the OS error (No space left on device):\n{log[-4000:]}"
    assert any("error" in line.lower() for line in errors), errors
    # Stopping the failed episode says it failed, and why; the rest succeeds.
    failed_stop = answers.pop("stop failed episode")
    assert not failed_stop.success and "No space left on device" in failed_stop.message, failed_stop.message
    for what, answer in answers.items():
        assert answer.success, f"{what}: {answer.message}\n{log[-3000:]}"

    first, second = episode_dirs(tmp_path / "bags")
    # The failed episode: closed once space was freed, its loss counted.
    assert (first / "metadata.yaml").exists(), f"no metadata.yaml; files {sorted(p.name for p in first.iterdir())}\n{log[-3000:]}"
    info = load_metadata(first)
    check_metadata_fields(info, first)
    report = json.loads((tmp_path / "publisher.out").read_text().strip().splitlines()[-1])
    dropped = int(info["custom_data"]["dropped_messages"])
    assert dropped > 0, f"the messages after the full disk are not counted as dropped: {info['custom_data']}"
    assert "No space left on device" in info["custom_data"]["error"], info["custom_data"]
    # Every published message reached the recorder (reliable): written, or counted as dropped.
    assert info["message_count"] + dropped == sum(report["published"].values()), (info["message_count"], dropped, report)
    # The next episode is a complete bag.
    second_info = load_metadata(second)
    check_metadata_fields(second_info, second)
    assert second_info["custom_data"]["dropped_messages"] == "0", second_info["custom_data"]
    bag = read_bag(mcap_files(second)[0])
    assert [m.ros.position[0] for m in bag.on("/joint_commands")] == [k * 0.1 for k in range(sent)]

    # What the failed file holds stays readable, chunk by chunk.
    [path] = mcap_files(first)
    got = recover(path)
    assert got.messages, f"nothing readable in {path.name} ({path.stat().st_size} bytes; reader stopped by {got.error!r})"
    cameras = ("/camera/top/image_raw", "/camera/front/image_raw")
    # Whatever a reader gets out of the file must be whole: a record cut by the full disk must not
    # read as a message.
    torn = [
        f"{m.topic} seq {m.record.sequence}: {len(m.ros.data)} of {m.ros.step * m.ros.height} image bytes"
        for m in got.messages
        if m.topic in cameras and len(m.ros.data) != m.ros.step * m.ros.height
    ]
    counts = topic_counts(info)
    readable = {topic: len(got.on(topic)) for topic in sorted({m.topic for m in got.messages})}
    assert not torn, (
        f"the file holds a chunk that reads as complete but ends in a truncated message: {torn}; "
        f"readable per topic {readable}, counted as written in metadata.yaml {counts}"
    )
    for topic, count in readable.items():
        assert count <= counts.get(topic, 0), f"{topic}: {count} messages readable, {counts.get(topic, 0)} counted as written"
    pattern = ImagePattern(640 * 480 * 3)
    for topic in cameras:
        for k, m in enumerate(got.on(topic)):
            assert pattern.matches(bytes(m.ros.data), k), f"{topic} frame {k}: {pattern.first_mismatch(bytes(m.ros.data), k)}"
    for k, m in enumerate(got.on("/joint_states")):
        assert list(m.ros.position) == [k * 0.001 + j for j in range(6)], f"joint_states #{k}"


# =========================================================================== 8. bad input
def run_recorder(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    try:
        return subprocess.run(
            [str(node_binary(RECORDER)), *args], cwd=cwd, env=node_environment(), capture_output=True, text=True, timeout=30
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"recorder_node {' '.join(args)} did not exit within 30 s (it should refuse the options)", pytrace=False)


def test_bad_options_are_refused_with_a_clear_message(tmp_path):
    done = run_recorder("--regex", "(", "--output", str(tmp_path / "bags"), cwd=tmp_path)
    output = done.stdout + done.stderr
    assert done.returncode != 0, f"--regex '(' accepted:\n{output}"
    assert "panicked" not in output, output
    line = next(
        (line for line in output.splitlines() if "(" in line and ("pattern" in line.lower() or "regex" in line.lower())), None
    )
    assert line is not None and "error" in output.lower(), f"the message does not name the bad pattern:\n{output}"

    not_a_dir = tmp_path / "a_file"
    not_a_dir.write_text("not a directory\n")
    done = run_recorder("--output", str(not_a_dir), "--start", cwd=tmp_path)
    output = done.stdout + done.stderr
    assert done.returncode != 0, f"--output naming a file accepted:\n{output}"
    assert str(not_a_dir) in output, f"the message does not name {not_a_dir}:\n{output}"
    assert "panicked" not in output, output
    assert not_a_dir.read_text() == "not a directory\n"

    done = run_recorder("--compression", "gzip", "--output", str(tmp_path / "bags"), cwd=tmp_path)
    assert done.returncode != 0 and "gzip" in done.stderr, done.stderr
