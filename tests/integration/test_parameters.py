"""ROS parameters on the nodes, through rclpy's parameter client (what `ros2 param` uses): list,
get, describe, types, set one by one and atomically, /parameter_events, refusals with a reason,
and dynamic parameters that change what the node does while it runs."""

from __future__ import annotations

import time

from harness import NODE_NAME, reliable_qos, start_and_wait, wait_until
from parameter_peer import ParameterPeer, assert_documented, not_set
from rcl_interfaces.msg import ParameterEvent, ParameterType

SIM_PARAMETERS = {
    "scene",
    "lite",
    "task",
    "dense_reward",
    "seed",
    "rate",
    "speed",
    "lockstep",
    "step_on_command",
    "demo",
    "cameras",
    "camera_size",
    "camera_rate",
    "jpeg",
    "jpeg_quality",
    "renderer",
    "camera_shadows",
    "servo_params",
    "randomize",
    "camera_poses",
    "joints.names",
    "joints.min_positions",
    "joints.max_positions",
}


def test_sim_parameters_list_get_describe(sim_factory, ros):
    running = start_and_wait(sim_factory, ros, "--rate", "50", "--seed", "7")
    peer = ParameterPeer(ros, f"/{NODE_NAME}", running.sim)
    assert set(peer.names()) == SIM_PARAMETERS
    assert_documented(peer, NODE_NAME)
    rate, seed, task, names = peer.get("rate", "seed", "task", "joints.names")
    assert peer.get("servo_params", "randomize", "camera_poses") == ["sts3215", "off", ""]
    assert (rate, seed, task) == (50.0, 7, "cube_to_bin")
    assert names[0] == "shoulder_pan" and len(names) == 6
    assert peer.types("rate", "lite", "cameras") == [
        ParameterType.PARAMETER_DOUBLE,
        ParameterType.PARAMETER_BOOL,
        ParameterType.PARAMETER_STRING_ARRAY,
    ]
    # An undeclared name empties the answer, as rclcpp and rclpy nodes answer.
    assert peer.get("rate", "no_such_thing") == [] and peer.types("rate", "nope") == []
    rate, camera_rate = peer.describe("rate", "camera_rate")
    assert rate.read_only and not camera_rate.read_only
    assert "Control rate" in rate.description
    assert camera_rate.floating_point_range[0].from_value > 0
    # Depth and prefixes, as rcl lists them.
    top_level = peer.list(depth=1)
    assert "rate" in top_level.names and "joints.names" not in top_level.names
    joints = peer.list(prefixes=["joints"])
    assert set(joints.names) == {"joints.names", "joints.min_positions", "joints.max_positions"}
    assert list(joints.prefixes) == ["joints"]


def test_sim_refuses_bad_sets_with_the_reason_and_keeps_its_values(sim_factory, ros):
    running = start_and_wait(sim_factory, ros)
    peer = ParameterPeer(ros, f"/{NODE_NAME}", running.sim)
    results = peer.set(rate=10.0, camera_rate=5000.0, dense_reward="yes", undeclared=1)
    assert [r.successful for r in results] == [False] * 4
    assert "read-only" in results[0].reason
    assert "from 0.1 to 1000" in results[1].reason
    assert "is a boolean, not a string" in results[2].reason
    assert "not declared" in results[3].reason
    assert not peer.set_raw("dense_reward", not_set())[0].successful
    atomically = peer.set_atomically(dense_reward=True, camera_rate=-1.0)
    assert not atomically.successful and "camera_rate" in atomically.reason
    assert peer.get("rate", "camera_rate", "dense_reward") == [100.0, 30.0, False]
    running.sim.assert_alive()


def test_dense_reward_set_at_run_time_changes_the_reward(sim_factory, ros):
    from std_msgs.msg import Float64

    running = start_and_wait(sim_factory, ros, "--speed", "4")
    reward = ros.subscribe(running.sim.name("task/reward"), Float64, reliable_qos(100))
    events = ros.subscribe("/parameter_events", ParameterEvent, reliable_qos(100))
    # Sparse: zero until the cube is in the bin.
    sparse = reward.wait_count(20, 10, running.sim)
    assert all(m.data == 0.0 for m in sparse)
    peer = ParameterPeer(ros, f"/{NODE_NAME}", running.sim)
    assert peer.set(dense_reward=True)[0].successful
    assert peer.get("dense_reward") == [True]
    reward.clear()
    dense = reward.wait_count(20, 10, running.sim)
    assert any(m.data != 0.0 for m in dense), [m.data for m in dense]

    def changed(message) -> bool:
        return message.node == f"/{NODE_NAME}" and any(
            p.name == "dense_reward" and p.value.bool_value for p in message.changed_parameters
        )

    wait_until(lambda: any(changed(m) for m in events.messages()), 10, "the /parameter_events change", running.sim)


def test_camera_rate_set_at_run_time_changes_the_frame_rate(sim_factory, ros):
    from sensor_msgs.msg import Image

    sim = sim_factory("--cameras", "top:64x48", "--camera-rate", "30", "--speed", "2")
    frames = ros.subscribe(sim.name("camera/top/image_raw"), Image, reliable_qos(200))
    frames.wait_count(10, 30, sim)
    peer = ParameterPeer(ros, f"/{NODE_NAME}", sim)
    assert peer.set(camera_rate=10)[0].successful  # an integer is taken for a double
    assert peer.get("camera_rate") == [10.0]
    time.sleep(0.3)
    frames.clear()
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in frames.wait_count(6, 20, sim)]
    gaps = [b - a for a, b in zip(stamps, stamps[1:])]
    assert all(abs(gap - 0.1) < 0.011 for gap in gaps[1:]), gaps


def test_driver_safety_limits_take_effect_when_set(arm_factory, ros):
    from driver_harness import DRIVER_NAME
    from sensor_msgs.msg import JointState

    # A watchdog of 0.2 s would stop a far move part-way (test_driver's watchdog test); turned off
    # through its parameter, the same short burst of commands carries the arm all the way.
    node, _emulator = arm_factory("--command-timeout", "0.2", "--max-step", "0.05")
    states = ros.subscribe("/joint_states", JointState, reliable_qos(100))
    states.wait_count(1, 30.0, node)
    peer = ParameterPeer(ros, f"/{DRIVER_NAME}", node)
    assert {"max_step", "command_timeout", "port", "joints.min_positions"} <= set(peer.names())
    assert_documented(peer, DRIVER_NAME)
    refused = peer.set(max_step=0.8, port="/dev/null")
    assert "from 0 to 0.5" in refused[0].reason and "read-only" in refused[1].reason
    assert all(result.successful for result in peer.set(command_timeout=0.0, max_step=0.1))
    assert peer.get("command_timeout", "max_step") == [0.0, 0.1]

    def pan() -> float:
        latest = states.latest()
        return dict(zip(latest.name, latest.position))["shoulder_pan"]

    start = pan()
    target = start + 1.2
    commands = ros.publisher("/joint_commands", JointState, sim=node)
    deadline = time.monotonic() + 10
    while pan() < start + 0.02:
        assert time.monotonic() < deadline, "the arm never started towards the command"
        commands.publish(JointState(name=["shoulder_pan"], position=[target]))
        time.sleep(0.02)
    wait_until(lambda: abs(pan() - target) < 0.03, 10.0, "the arm reaching the target without a watchdog", node)


def test_teleop_speed_set_at_run_time(sim_factory, teleop_factory, ros):
    running = start_and_wait(sim_factory, ros)
    teleop = teleop_factory("--source", "expert", "--episodes", "0", "--no-reset", "--max-step", "0.1")
    peer = ParameterPeer(ros, "/teleop_node", teleop)
    assert peer.get("source", "max_step", "joint_speed") == ["expert", 0.1, 1.0]
    assert_documented(peer, "teleop_node")
    assert peer.set(gripper_speed=3.0)[0].successful
    assert peer.get("gripper_speed") == [3.0]
    assert "above 0" in peer.set(joint_speed=0.0)[0].reason
    running.sim.assert_alive()


def test_recorder_topic_selection_set_at_run_time(sim_factory, recorder_factory, ros):
    import yaml

    running = start_and_wait(sim_factory, ros)
    recorder = recorder_factory("--topics", "joint_states", "--start")
    peer = ParameterPeer(ros, "/recorder_node", recorder)
    assert peer.get("topics") == [["joint_states"]]
    assert_documented(peer, "recorder_node")
    assert "bad pattern" in peer.set(regex=["("])[0].reason
    assert peer.set(topics=["joint_states", "task/reward"])[0].successful
    time.sleep(2.5)  # the next discovery subscribes /task/reward
    assert recorder.stop() == 0, recorder.log_tail()
    (metadata,) = recorder.output.glob("*/metadata.yaml")
    info = yaml.safe_load(metadata.read_text())["rosbag2_bagfile_information"]
    counts = {t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]}
    assert counts.get("/task/reward", 0) > 0 and counts["/joint_states"] > 0, counts
    running.sim.assert_alive()


def test_state_publisher_serves_robot_description_as_a_parameter(ros, tmp_path):
    from harness import SimNode, node_binary

    publisher = SimNode(node_binary("so101_state_publisher"), ["--mesh-uri", "file"], tmp_path / "state_publisher.log")
    try:
        peer = ParameterPeer(ros, "/so101_state_publisher", publisher)
        urdf, mesh_uri = peer.get("robot_description", "mesh_uri")
        assert urdf.startswith("<?xml") and '<robot name="so101">' in urdf
        assert mesh_uri == "file"
        assert "package://" not in urdf
        assert_documented(peer, "so101_state_publisher")
    finally:
        assert publisher.stop() == 0, publisher.log_tail()


def test_rerun_bridge_image_rate_set_at_run_time(ros, tmp_path):
    from harness import SimNode, node_binary

    bridge = SimNode(
        node_binary("so101_rerun"), ["live", "--save", str(tmp_path / "live.rrd"), "--cameras", "none"], tmp_path / "rerun.log"
    )
    try:
        peer = ParameterPeer(ros, "/so101_rerun_bridge", bridge)
        assert_documented(peer, "so101_rerun_bridge")
        assert peer.set(image_rate=0.0)[0].successful
        assert peer.get("image_rate") == [0.0]
        assert not peer.set(image_rate=-1.0)[0].successful
    finally:
        assert bridge.stop() == 0, bridge.log_tail()


def test_parameter_services_and_the_arm_controller_live_in_the_namespace(sim_factory, ros):
    from rclpy.action import get_action_names_and_types

    running = start_and_wait(sim_factory, ros, "--namespace", "arm1")
    peer = ParameterPeer(ros, f"/arm1/{NODE_NAME}", running.sim)
    assert set(peer.names()) == SIM_PARAMETERS
    assert ros.node.count_subscribers("/arm1/arm_controller/joint_trajectory") == 1
    wait_until(
        lambda: (
            ("/arm1/arm_controller/follow_joint_trajectory", ["control_msgs/action/FollowJointTrajectory"])
            in get_action_names_and_types(ros.node)
        ),
        10,
        "the FollowJointTrajectory action in the namespace",
        running.sim,
    )
    assert ros.node.count_subscribers("/arm_controller/joint_trajectory") == 0
