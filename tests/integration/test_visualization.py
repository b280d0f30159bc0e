"""Visualization: so101_state_publisher's /robot_description (a late joiner still gets it) and /tf
against the arm's body poses computed here from the scene file; so101_rerun's .rrd files, from a
live sim run and from an episode bag, read back with the rerun Python SDK."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import numpy as np
from harness import (
    JOINT_LIMITS,
    JOINT_NAMES,
    SimNode,
    node_binary,
    node_environment,
    rrd_entities,
    scene_body_poses,
    start_and_wait,
)

LINKS = ["shoulder", "upper_arm", "lower_arm", "wrist", "gripper", "moving_jaw"]
PARENTS = ["base", "shoulder", "upper_arm", "lower_arm", "wrist", "gripper"]


def latched_qos():
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        depth=1,
        history=HistoryPolicy.KEEP_LAST,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )


def quaternion_matrix(q) -> np.ndarray:
    w, x, y, z = q.w, q.x, q.y, q.z
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def run_node(name: str, *args: str, timeout: float = 120.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(node_binary(name)), *[str(a) for a in args]], capture_output=True, text=True, timeout=timeout, env=node_environment()
    )


def scalar_series(path, entity: str) -> np.ndarray:
    """The values of a Scalars entity in sim-time order."""
    from rerun.experimental import RrdReader

    rows = []
    for chunk in RrdReader(str(path)).stream().to_chunks():
        if str(chunk.entity_path) != entity:
            continue
        batch = chunk.to_record_batch()
        column = next(name for name in batch.schema.names if name.endswith("Scalars:scalars"))
        times = batch.column("sim_time").to_pylist()
        rows.extend((time, value[0]) for time, value in zip(times, batch.column(column).to_pylist()) if value)
    return np.array([value for _, value in sorted(rows, key=lambda row: row[0])])


def test_robot_description_and_tf_match_the_scene(sim_factory, recorder_factory, ros, tmp_path):
    """/tf is read back from a bag of it (recorder_node, then rosbags with its own Jazzy types):
    the rclpy wheels have no tf2_msgs."""
    from rclpy.qos import DurabilityPolicy
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String

    running = start_and_wait(sim_factory, ros, "--cameras", "none")
    recorder = recorder_factory("--topics", "tf,joint_states", "--start")
    state_publisher = SimNode(node_binary("so101_state_publisher"), [], tmp_path / "state_publisher.log")
    try:
        ros.wait_for_publisher("/robot_description", 20.0, "/robot_description", state_publisher)
        time.sleep(1.0)
        # Subscribed after it was published: transient local hands it over all the same.
        description = ros.subscribe("/robot_description", String, latched_qos())
        urdf = description.next_message(10.0, state_publisher).data
        robot = ElementTree.fromstring(urdf)
        joints = {j.get("name"): j for j in robot.iter("joint")}
        for index, name in enumerate(JOINT_NAMES):
            joint = joints[name]
            assert joint.get("type") == "revolute"
            assert joint.find("parent").get("link") == PARENTS[index] and joint.find("child").get("link") == LINKS[index]
            limit = joint.find("limit")
            assert abs(float(limit.get("lower")) - JOINT_LIMITS[name][0]) < 1e-3, name
            assert abs(float(limit.get("upper")) - JOINT_LIMITS[name][1]) < 1e-3, name
        assert {link.get("name") for link in robot.iter("link")} >= {"base", *LINKS, "grasp_point"}
        # /tf_static is offered latched, as tf2's static broadcaster does (RViz relies on it).
        ros.wait_for_publisher("/tf_static", 20.0, "/tf_static", state_publisher)
        (static_info,) = ros.node.get_publishers_info_by_topic("/tf_static")
        assert static_info.topic_type == "tf2_msgs/msg/TFMessage"
        assert static_info.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL

        # Move the arm, with the recorder keeping /tf and /joint_states.
        target = {
            "shoulder_pan": 0.5,
            "shoulder_lift": -0.4,
            "elbow_flex": 0.6,
            "wrist_flex": 0.7,
            "wrist_roll": -1.0,
            "gripper": 0.8,
        }
        commands = ros.publisher("/joint_commands", JointState, sim=running.sim)
        deadline = time.monotonic() + 3
        while time.monotonic() < deadline:
            commands.publish(JointState(name=list(target), position=list(target.values())))
            time.sleep(0.05)
        assert abs(running.current_positions()["shoulder_pan"] - 0.5) < 0.05
    finally:
        assert state_publisher.stop() == 0, state_publisher.log_tail()
    assert recorder.stop() == 0, recorder.log_tail()

    store = get_typestore(Stores.ROS2_JAZZY)
    states, trees = {}, {}
    with Reader(next(recorder.output.glob("episode_*"))) as bag:
        for connection, _, raw in bag.messages():
            message = store.deserialize_cdr(raw, connection.msgtype)
            if connection.topic == "/joint_states":
                stamp = (message.header.stamp.sec, message.header.stamp.nanosec)
                states[stamp] = dict(zip(message.name, message.position))
            else:
                stamp = (message.transforms[0].header.stamp.sec, message.transforms[0].header.stamp.nanosec)
                trees[stamp] = {t.child_frame_id: t for t in message.transforms}
    paired = sorted(set(states) & set(trees))
    assert len(paired) > 100, f"{len(trees)} /tf messages, {len(paired)} stamped like a joint state"
    for stamp in paired[:: len(paired) // 20]:
        transforms = trees[stamp]
        assert set(transforms) == set(LINKS)
        expected = scene_body_poses(states[stamp])
        # The base where the sim's scene mounts it (the default of /tf_static's world -> base).
        poses = {"base": (np.eye(3), np.array([0.0, 0.0, 0.75]))}
        for link in LINKS:
            t = transforms[link]
            parent_rotation, parent_position = poses[t.header.frame_id]
            offset = t.transform.translation
            poses[link] = (
                parent_rotation @ quaternion_matrix(t.transform.rotation),
                parent_position + parent_rotation @ np.array([offset.x, offset.y, offset.z]),
            )
            rotation, position = poses[link]
            want_rotation, want_position = expected[link]
            assert np.linalg.norm(position - want_position) < 1e-5, f"{link} at {stamp}: {position} vs {want_position}"
            assert np.abs(rotation - want_rotation).max() < 1e-4, f"{link} at {stamp}"


def test_a_live_run_saved_to_rrd_reads_back_with_the_expected_entities(sim_factory, ros, tmp_path):
    from sensor_msgs.msg import JointState

    running = start_and_wait(sim_factory, ros, "--cameras", "top:64x48,wrist:64x48", "--task", "cube_to_bin", "--dense-reward")
    output = tmp_path / "live.rrd"
    bridge = subprocess.Popen(
        [str(node_binary("so101_rerun")), "live", "--save", str(output), "--cameras", "top,wrist", "--image-rate", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=node_environment(),
    )
    # The arm moves once the bridge listens (its camera subscriptions show it on the graph).
    ros.wait_for_graph(lambda: ros.node.count_subscribers("/camera/wrist/image_raw") >= 1, 20.0, "the bridge", running.sim)
    time.sleep(0.5)
    commands = ros.publisher("/joint_commands", JointState, sim=running.sim)
    deadline = time.monotonic() + 3
    while time.monotonic() < deadline:
        commands.publish(JointState(name=["shoulder_pan"], position=[0.4]))
        time.sleep(0.05)
    time.sleep(0.5)
    bridge.send_signal(signal.SIGINT)  # it flushes the recording and exits
    out, _ = bridge.communicate(timeout=60)
    assert bridge.returncode == 0, out

    rows = rrd_entities(output)
    expected = {
        "/world",
        "/world/table/shape",
        "/world/bin/shape",
        "/world/cube",
        "/world/cube/shape",
        "/world/base/shoulder",
        "/world/base/shoulder/upper_arm/lower_arm/wrist/gripper/moving_jaw",
        "/cameras/top",
        "/cameras/wrist",
        "/task/reward",
        "/task/success",
        *(f"/joints/{name}/position" for name in JOINT_NAMES),
        "/joints/shoulder_pan/command",
    }
    missing = expected - set(rows)
    assert not missing, f"missing entities {missing}; have {sorted(rows)}"
    # Joint states at 100 Hz for over 3.5 s, camera frames at 30 Hz: all logged.
    assert rows["/joints/shoulder_pan/position"] > 200, rows["/joints/shoulder_pan/position"]
    assert rows["/cameras/top"] > 60, rows["/cameras/top"]
    pan = scalar_series(output, "/joints/shoulder_pan/position")
    assert abs(pan[0]) < 0.05 and abs(pan[-1] - 0.4) < 0.05, (pan[0], pan[-1])


def test_an_episode_bag_becomes_an_rrd_with_every_joint_state(sim_factory, recorder_factory, ros, tmp_path):
    from mcap.reader import make_reader

    sim = sim_factory("--cameras", "top:64x48", "--demo")
    # Small chunks: the damaged copy below, cut in half, still holds whole chunks.
    recorder = recorder_factory("--start", "--chunk-size", "32768")
    ros.wait_for_publisher("/joint_states", 20.0, "the sim", sim)
    time.sleep(3.0)
    assert recorder.stop() == 0, recorder.log_tail()
    episode = next(recorder.output.glob("episode_*"))
    # A second, damaged episode: its MCAP cut in half, as a killed recording may leave it.
    damaged = recorder.output / "episode_000099"
    damaged.mkdir()
    original = next(episode.glob("*.mcap")).read_bytes()
    (damaged / "episode_000099_0.mcap").write_bytes(original[: len(original) // 2])
    (recorder.output / "not_a_bag").mkdir()

    output = tmp_path / "rrd"
    done = run_node("so101_rerun", "bag", recorder.output, "--output", output, "--image-rate", "0")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "2 recording(s)" in done.stdout, done.stdout + done.stderr
    assert "ends early" in done.stderr, done.stderr

    with open(next(episode.glob("*.mcap")), "rb") as f:
        counts: dict[str, int] = {}
        for _schema, channel, _message in make_reader(f).iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    rows = rrd_entities(output / f"{episode.name}.rrd")
    assert rows["/joints/gripper/position"] == counts["/joint_states"], (
        rows.get("/joints/gripper/position"),
        counts["/joint_states"],
    )
    assert rows["/cameras/top"] == counts["/camera/top/image_raw"]
    assert rows["/world/cube"] == counts["/cube/pose"]
    # The truncated copy keeps what could be read.
    partial = rrd_entities(output / "episode_000099.rrd")
    assert 0 < partial.get("/joints/gripper/position", 0) < counts["/joint_states"]


def test_the_description_package_resolves_every_mesh_uri_and_rviz_view(tmp_path, monkeypatch):
    """so101-description install: ament_index (what RViz and MoveIt use) finds the package, every
    package:// URI of the URDF resolves to a file identical to the scene's mesh, and the RViz view
    shows the topics the stack publishes."""
    import filecmp

    import yaml
    from ament_index_python.packages import get_package_share_directory

    from so101 import contract
    from so101.paths import asset
    from so101.stack import description

    prefix = tmp_path / "prefix"
    done = subprocess.run(
        [str(Path(sys.executable).parent / "so101-description"), "install", str(prefix)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    assert f"AMENT_PREFIX_PATH={prefix}" in done.stdout
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(prefix))
    share = Path(get_package_share_directory("so101_description"))
    urdf = (share / "urdf" / "so101.urdf").read_text()
    uris = [mesh.get("filename") for mesh in ElementTree.fromstring(urdf).iter("mesh")]
    meshes = asset(description.MESH_DIR)
    if meshes.is_dir():  # the set-up fetched them; without, the URDF draws boxes
        assert uris and all(uri.startswith("package://so101_description/meshes/") for uri in uris)
    for uri in uris:
        package, relative = uri.removeprefix("package://").split("/", 1)
        resolved = Path(get_package_share_directory(package)) / relative
        assert filecmp.cmp(resolved, meshes / resolved.name, shallow=False), uri

    view = yaml.safe_load((share / description.RVIZ_CONFIG).read_text())["Visualization Manager"]
    assert view["Global Options"]["Fixed Frame"] == "world"
    displays = {d["Class"]: d for d in view["Displays"]}
    assert displays["rviz_default_plugins/RobotModel"]["Description Topic"]["Value"] == "/robot_description"
    assert displays["rviz_default_plugins/RobotModel"]["Description Topic"]["Durability Policy"] == "Transient Local"
    assert "rviz_default_plugins/TF" in displays
    images = [d["Topic"]["Value"] for d in view["Displays"] if d["Class"] == "rviz_default_plugins/Image"]
    assert images == [f"/{contract.CAMERA_PREFIX}/{name}/image_raw" for name in ("top", "front", "wrist")]
