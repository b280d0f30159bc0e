"""Joint trajectories on the sim, from rclpy: trajectory_msgs/JointTrajectory on
/arm_controller/joint_trajectory (ros2_control's joint_trajectory_controller topic) followed to
within 0.05 rad at each point's time_from_start, preempted by a direct command, malformed ones
refused whole. The FollowJointTrajectory action is tested from Rust
(crates/so101_sim_node/tests/follow_joint_trajectory.rs); its definition against the published
control_msgs here."""

from __future__ import annotations

import contextlib
import io
import json
import subprocess
import sys
import time
from pathlib import Path

from builtin_interfaces.msg import Duration, Time
from diagnostic_msgs.msg import DiagnosticArray
from harness import (
    JOINT_NAMES,
    latest_diagnostics_values,
    offset_pose,
    reliable_qos,
    stamp_seconds,
    start_and_wait,
    wait_reached,
    wait_until,
)
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from so101 import contract

TOPIC = f"/{contract.JOINT_TRAJECTORY}"
TOLERANCE = 0.05  # rad, at each point's time_from_start


def duration(seconds: float) -> Duration:
    return Duration(sec=int(seconds), nanosec=int(round((seconds % 1) * 1e9)))


def trajectory(
    points: list[tuple[float, dict[str, float]]], stamp: Time | None = None, velocities: bool = True
) -> JointTrajectory:
    names = list(points[0][1])
    message = JointTrajectory(
        joint_names=names,
        points=[
            JointTrajectoryPoint(
                positions=[pose[name] for name in names],
                velocities=[0.0] * len(names) if velocities else [],
                time_from_start=duration(t),
            )
            for t, pose in points
        ],
    )
    if stamp is not None:
        message.header.stamp = stamp
    return message


def test_a_trajectory_is_followed_within_tolerance_at_each_point(sim_factory, ros):
    running = start_and_wait(sim_factory, ros, "--speed", "2")
    clock = ros.subscribe("/clock", Clock, reliable_qos(100))
    publisher = ros.publisher(TOPIC, JointTrajectory, sim=running.sim)
    start = running.current_positions()
    first = offset_pose(start, 0.3)
    second = offset_pose(first, -0.45)
    third = offset_pose(second, 0.25)
    now = stamp_seconds(clock.next_message(5, running.sim).clock)
    begin = now + 0.5  # a stamp in the (sim time) future pins the start, so times can be checked
    points = [(1.0, first), (2.2, second), (3.0, third)]
    publisher.publish(trajectory(points, stamp=Time(sec=int(begin), nanosec=int((begin % 1) * 1e9))))
    states = running.joint_states
    states.clear()
    wait_until(
        lambda: states.latest() is not None and stamp_seconds(states.latest().header.stamp) > begin + 3.2,
        20,
        "the trajectory's end",
        running.sim,
    )
    received = states.messages()
    for t, pose in points:
        at = min(received, key=lambda m: abs(stamp_seconds(m.header.stamp) - (begin + t)))
        actual = dict(zip(at.name, at.position))
        errors = {name: round(actual[name] - pose[name], 4) for name in JOINT_NAMES}
        assert max(abs(e) for e in errors.values()) < TOLERANCE, f"at t={t}: {errors}"
    # Before its stamp the arm did not move.
    early = [m for m in received if stamp_seconds(m.header.stamp) < begin - 0.05]
    assert early and all(abs(dict(zip(m.name, m.position))["shoulder_pan"] - start["shoulder_pan"]) < 0.01 for m in early)


def test_a_direct_command_preempts_the_trajectory(sim_factory, ros):
    running = start_and_wait(sim_factory, ros, "--speed", "2")
    trajectories = ros.publisher(TOPIC, JointTrajectory, sim=running.sim)
    commands = ros.publisher("/joint_commands", JointState, sim=running.sim)
    start = running.current_positions()
    far = offset_pose(start, 0.6)
    trajectories.publish(trajectory([(4.0, far)], velocities=False))
    wait_until(
        lambda: abs(running.current_positions()["shoulder_pan"] - start["shoulder_pan"]) > 0.05,
        10,
        "the trajectory moving the arm",
        running.sim,
    )
    here = running.current_positions()
    commands.publish(JointState(name=list(here), position=list(here.values())))
    wait_reached(running, here, tolerance=0.03)
    time.sleep(1.0)
    latest = running.current_positions()
    moved = {name: round(latest[name] - here[name], 4) for name in JOINT_NAMES}
    assert max(abs(d) for d in moved.values()) < 0.03, f"the trajectory kept going after the command: {moved}"


def test_malformed_trajectories_are_refused_whole(sim_factory, ros):
    running = start_and_wait(sim_factory, ros)
    publisher = ros.publisher(TOPIC, JointTrajectory, sim=running.sim)
    start = running.current_positions()
    moved = offset_pose(start, 0.3)
    unknown = trajectory([(1.0, {**moved, "elbow": 0.1})])
    outside = trajectory([(1.0, {**moved, "shoulder_pan": 5.0})])
    backwards = trajectory([(1.0, moved), (0.5, start)])
    short = trajectory([(1.0, moved)])
    short.points[0].positions = short.points[0].positions[:3]
    for message in (unknown, outside, backwards, short):
        publisher.publish(message)
    time.sleep(1.5)
    latest = running.current_positions()
    assert all(abs(latest[name] - start[name]) < 0.01 for name in JOINT_NAMES), latest
    diagnostics = ros.subscribe("/diagnostics", DiagnosticArray, reliable_qos(10))
    diagnostics.wait_for(
        lambda msgs: (latest_diagnostics_values(msgs) or {}).get("rejected_trajectories") == "4",
        5,
        "4 rejected trajectories",
        running.sim,
    )
    assert "trajectory refused: unknown joint name" in running.sim.log()  # the first; the rest rate-limited
    running.sim.assert_alive()


def test_the_driver_follows_a_trajectory_within_its_max_step(arm_factory, ros):
    """On the real arm's driver (over the servo-bus emulator) a trajectory asking for a jump moves
    no joint more than --max-step per cycle, and still arrives."""
    node, _emulator = arm_factory("--max-step", "0.02", "--rate", "100")
    states = ros.subscribe("/joint_states", JointState, reliable_qos(1000))
    states.wait_count(5, 30.0, node)
    latest = states.latest()
    start = dict(zip(latest.name, latest.position))
    target = {"shoulder_pan": start["shoulder_pan"] + 0.4, "elbow_flex": start["elbow_flex"] - 0.3}
    publisher = ros.publisher(TOPIC, JointTrajectory, sim=node)
    states.clear()
    publisher.publish(trajectory([(0.1, target)], velocities=False))

    def position(message, name: str) -> float:
        return dict(zip(message.name, message.position))[name]

    wait_until(
        lambda: states.latest() is not None and all(abs(position(states.latest(), n) - v) < 0.02 for n, v in target.items()),
        10,
        "the trajectory's end",
        node,
    )
    messages = states.messages()
    for name in JOINT_NAMES:
        path = [position(m, name) for m in messages]
        steps = [abs(b - a) for a, b in zip(path, path[1:])]
        assert max(steps) <= 0.02 + 0.003, f"{name} moved {max(steps):.4f} rad in a cycle (max_step 0.02)"
    assert len(messages) >= 15, "0.4 rad at 0.02 rad a cycle takes at least 20 cycles"
    # Arrived, the last point is no longer re-sent: the watchdog (0.5 s) acts as after any command.
    wait_until(lambda: "no command for longer than the timeout" in node.log(), 5, "the watchdog after the hold", node)


# Published RIHS01 type hashes of control_msgs 5.x (ROS 2 Jazzy): a colcon build of control_msgs
# (rosidl_generator_type_description's output, generated C description of FollowJointTrajectory).
PUBLISHED_CONTROL_MSGS_HASHES = {
    "control_msgs/action/FollowJointTrajectory": "RIHS01_738ebcb7a2d7cfa42f9f1001cc99ce3a4383d1cfe508015d9be8485e4b1c66f6",
    "control_msgs/action/FollowJointTrajectory_Goal": "RIHS01_8a9060704b269608f5a340934cc26e66869dd14bdac29e2e7fd9ec8b9882d205",
    "control_msgs/action/FollowJointTrajectory_Result": "RIHS01_8002e99ed2c14c6faa522f2a93c26d744c5982f254f9e98ff9c6f19789bdb220",
    "control_msgs/action/FollowJointTrajectory_Feedback": "RIHS01_3fd0aaecf71725121ae1ff7f01098a5e0da581e672be18a6b2c286cb43d96b49",
    "control_msgs/action/FollowJointTrajectory_SendGoal_Request": "RIHS01_179c93691f1f6d1d115881ff88c3917b7cc6eac2ba4bf56766cc7c4389e19ef1",
    "control_msgs/action/FollowJointTrajectory_GetResult_Response": "RIHS01_08eefbaa146ce02ba45898d5e99160afd6c4c54a30d159aee0f2ca6035b1580f",
    "control_msgs/action/FollowJointTrajectory_FeedbackMessage": "RIHS01_80398fcb9674a79081a9906e2ccf0c804dd7cb15e22e362e606ee87186beab71",
    "control_msgs/msg/JointTolerance": "RIHS01_c254f9cece0f3b733017b6990fd46d1326e25242d6b8844398c97d9a88e7d648",
    "control_msgs/msg/JointComponentTolerance": "RIHS01_739ea7566931944d33830fa10f1bf5e7a7fbdc3172bce7a7eaac642bd6e3ffa4",
}
DEPENDENCIES = [
    "builtin_interfaces",
    "std_msgs",
    "geometry_msgs",
    "trajectory_msgs",
    "unique_identifier_msgs",
    "action_msgs",
    "service_msgs",
]


def type_hashes(package: str, interfaces: list[str], tmp_path) -> dict[str, str]:
    """RIHS01 hashes, as rosidl computes them at build time, of the definitions the stack's Rust
    types carry (so101_contract --interface): .msg/.action -> .idl (rosidl_adapter) -> type
    description and hash (rosidl_generator_type_description), dependencies from the venv's share."""
    from harness import node_binary
    from rosidl_adapter.action import convert_action_to_idl
    from rosidl_adapter.msg import convert_msg_to_idl
    from rosidl_generator_type_description import generate_type_hash

    share = Path(sys.prefix) / "share"
    source = tmp_path / "src" / package
    idl_root = tmp_path / "idl"
    tuples = []
    for name in interfaces:
        kind, base = name.split("/")[1:]
        text = subprocess.run(
            [str(node_binary("so101_contract")), "--interface", name], capture_output=True, text=True, check=True
        ).stdout
        (source / kind).mkdir(parents=True, exist_ok=True)
        (source / kind / f"{base}.{kind}").write_text(text)
        (idl_root / kind).mkdir(parents=True, exist_ok=True)
        convert = convert_action_to_idl if kind == "action" else convert_msg_to_idl
        with contextlib.redirect_stdout(io.StringIO()):
            convert(source, package, Path(kind) / f"{base}.{kind}", idl_root / kind)
        tuples.append(f"{idl_root}:{kind}/{base}.idl")
    arguments = tmp_path / "arguments.json"
    arguments.write_text(
        json.dumps(
            {
                "package_name": package,
                "output_dir": str(tmp_path / "out"),
                "idl_tuples": tuples,
                "include_paths": [f"{d}:{share / d}" for d in DEPENDENCIES + ["rcl_interfaces"] if d != package],
            }
        )
    )
    hashes = {}
    for path in generate_type_hash(str(arguments)):
        for entry in json.loads(Path(path).read_text())["type_hashes"]:
            hashes.setdefault(entry["type_name"], entry["hash_string"])
    return hashes


def test_follow_joint_trajectory_is_control_msgs_own_definition(tmp_path):
    """The action's text in the Rust types hashes to the type hash published for control_msgs on
    Jazzy: names, field order, types and constants all as MoveIt's controller manager expects."""
    hashes = type_hashes(
        "control_msgs",
        [
            "control_msgs/msg/JointTolerance",
            "control_msgs/msg/JointComponentTolerance",
            "control_msgs/action/FollowJointTrajectory",
        ],
        tmp_path,
    )
    for name, published in PUBLISHED_CONTROL_MSGS_HASHES.items():
        assert hashes[name] == published, name


def test_trajectory_and_parameter_messages_hash_as_the_jazzy_packages(tmp_path):
    """trajectory_msgs and rcl_interfaces as the Rust types define them hash as the Jazzy wheels'
    own type descriptions (share/<pkg>/msg/*.json)."""
    cases = {
        "trajectory_msgs": ["JointTrajectory", "JointTrajectoryPoint", "MultiDOFJointTrajectory", "MultiDOFJointTrajectoryPoint"],
        "rcl_interfaces": [
            "ParameterValue",
            "Parameter",
            "ParameterDescriptor",
            "FloatingPointRange",
            "IntegerRange",
            "SetParametersResult",
            "ListParametersResult",
            "ParameterEvent",
        ],
    }
    for package, names in cases.items():
        hashes = type_hashes(package, [f"{package}/msg/{n}" for n in names], tmp_path / package)
        for name in names:
            description = json.loads((Path(sys.prefix) / "share" / package / "msg" / f"{name}.json").read_text())
            expected = next(h["hash_string"] for h in description["type_hashes"] if h["type_name"] == f"{package}/msg/{name}")
            assert hashes[f"{package}/msg/{name}"] == expected, f"{package}/{name}"


def test_the_driver_refuses_trajectories_while_torque_is_off(arm_factory, ros):
    node, _emulator = arm_factory("--start-torque-off")
    states = ros.subscribe("/joint_states", JointState, reliable_qos(1000))
    states.wait_count(5, 30.0, node)
    latest = states.latest()
    start = dict(zip(latest.name, latest.position))
    publisher = ros.publisher(TOPIC, JointTrajectory, sim=node)
    publisher.publish(trajectory([(0.5, {"shoulder_pan": start["shoulder_pan"] + 0.3})], velocities=False))
    wait_until(lambda: "trajectory refused: torque is off" in node.log(), 10, "the refusal", node)
