"""Position commands: /joint_commands (by name, partial sets) and
/forward_position_controller/commands (6 positions in joint order)."""

from __future__ import annotations

from harness import JOINT_NAMES, offset_pose, positions_by_name, start_and_wait, wait_reached


def joint_command(target: dict[str, float]):
    from sensor_msgs.msg import JointState

    msg = JointState()
    msg.name = list(target)
    msg.position = [float(v) for v in target.values()]
    return msg


def test_joint_commands_full_pose_then_partial(sim_factory, ros):
    from sensor_msgs.msg import JointState

    running = start_and_wait(sim_factory, ros)
    start = running.current_positions()
    pub = ros.publisher(running.sim.name("joint_commands"), JointState, sim=running.sim)

    # Full pose, names deliberately not in joint order: positions are taken by name.
    target = offset_pose(start, 0.3)
    pub.publish(joint_command(dict(reversed(list(target.items())))))
    wait_reached(running, target)

    # Partial command: only elbow_flex's target changes, every other joint holds.
    partial = offset_pose(target, 0.2)["elbow_flex"]
    pub.publish(joint_command({"elbow_flex": partial}))
    expected = {**target, "elbow_flex": partial}
    wait_reached(running, expected)


def test_forward_position_controller_commands(sim_factory, ros):
    from std_msgs.msg import Float64MultiArray

    running = start_and_wait(sim_factory, ros)
    start = running.current_positions()
    pub = ros.publisher(running.sim.name("forward_position_controller/commands"), Float64MultiArray, sim=running.sim)

    target = offset_pose(start, 0.25)
    pub.publish(Float64MultiArray(data=[target[name] for name in JOINT_NAMES]))
    wait_reached(running, target)

    # A second pose, to see it follows and not just a one-shot.
    second = offset_pose(target, -0.15)
    pub.publish(Float64MultiArray(data=[second[name] for name in JOINT_NAMES]))
    wait_reached(running, second)


def test_commands_under_a_namespace(sim_factory, ros):
    from sensor_msgs.msg import JointState

    running = start_and_wait(sim_factory, ros, "--namespace", "arm1")
    start = positions_by_name(running.joint_states.next_message(5.0, running.sim))
    pub = ros.publisher("/arm1/joint_commands", JointState, sim=running.sim)
    target = {**start, "wrist_roll": offset_pose(start, 0.3)["wrist_roll"]}
    pub.publish(joint_command({"wrist_roll": target["wrist_roll"]}))
    wait_reached(running, target)
