"""so101_feetech_driver end to end: the node on the servo-bus emulator (a real pty), talking to a
Jazzy rclpy peer. Topic contract, command safety (clamping, malformed input, step limit, watchdog),
torque service, diagnostics, fault containment and reconnection, leader mode, shutdown."""

from __future__ import annotations

import math
import time

import pytest
from driver_harness import CALIBRATION, joints_in_order, rad_from_ticks, range_in_rad
from harness import JOINT_NAMES, diagnostics_values, reliable_qos, wait_until

DRIVER = "so101_feetech_driver"


def joint_command(target: dict[str, float]):
    from sensor_msgs.msg import JointState

    msg = JointState()
    msg.name = list(target)
    msg.position = [float(v) for v in target.values()]
    return msg


def subscribe_joint_states(ros, topic="/joint_states"):
    from sensor_msgs.msg import JointState

    return ros.subscribe(topic, JointState, reliable_qos(depth=1000))


def subscribe_diagnostics(ros):
    from diagnostic_msgs.msg import DiagnosticArray

    return ros.subscribe("/diagnostics", DiagnosticArray, reliable_qos(depth=100))


def bus_values(array_msgs, node=DRIVER) -> dict[str, str]:
    for msg in reversed(array_msgs):
        values = diagnostics_values(msg, f"{node}: bus")
        if values is not None:
            return values
    return {}


def level(status) -> int:
    """rclpy gives the `byte` level as a one-byte bytes object."""
    return status.level[0] if isinstance(status.level, bytes) else int(status.level)


def status_of(array_msg, name: str):
    for status in array_msg.status:
        if status.name == name:
            return status
    return None


def wait_positions(inbox, target: dict[str, float], node, tolerance=0.02, timeout=8.0):
    def reached(msgs):
        if not msgs:
            return False
        actual = dict(zip(msgs[-1].name, msgs[-1].position))
        return all(abs(actual[name] - value) <= tolerance for name, value in target.items())

    inbox.wait_for(reached, timeout, f"joint_states within {tolerance} rad of {target}", node)


def test_joint_states_at_the_control_rate_in_radians_from_the_calibration(arm_factory, ros):
    node, emulator = arm_factory("--rate", "200")
    inbox = subscribe_joint_states(ros)
    inbox.wait_count(1, 30.0, node)
    time.sleep(0.3)
    inbox.clear()
    time.sleep(2.0)
    msgs = inbox.messages()
    # One message per cycle, stamped at the cycle's read, never faster than the requested 200 Hz.
    # How close a busy machine lets it come to 200 Hz is the driver benchmark's (so101-bench driver:
    # cycle lateness at 200 Hz), not this test's.
    assert 10 <= len(msgs) <= 2.0 * 200 * 1.1, f"{len(msgs)} joint_states in 2 s at 200 Hz"
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in msgs]
    assert all(b > a for a, b in zip(stamps, stamps[1:])), "two joint_states of one cycle, or stamps going back"
    assert (stamps[-1] - stamps[0]) / (len(stamps) - 1) >= 0.9 / 200, "cycles faster than the requested 200 Hz"
    last = msgs[-1]
    assert list(last.name) == JOINT_NAMES
    # Each servo reports shaft - Homing_Offset; the driver maps that through the calibration.
    slots = emulator.slots()
    for index, name in enumerate(JOINT_NAMES):
        expected = rad_from_ticks(name, slots[index]["present_position"])
        assert math.isclose(joints_in_order(last)[index], expected, abs_tol=2e-3), name
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in msgs]
    assert all(b >= a for a, b in zip(stamps, stamps[1:])), "stamps go backwards"
    assert abs(stamps[-1] - time.time()) < 1.0, "joint_states are stamped with the wall clock"


def test_commands_move_the_servos_by_name_and_as_an_array(arm_factory, ros):
    from std_msgs.msg import Float64MultiArray

    node, emulator = arm_factory()
    inbox = subscribe_joint_states(ros)
    inbox.wait_count(1, 30.0, node)
    start = dict(zip(inbox.latest().name, inbox.latest().position))
    pub = ros.publisher("/joint_commands", type(joint_command({})), sim=node)
    target = {"shoulder_pan": 0.4, "elbow_flex": -0.3, "gripper": 0.5}
    deadline = time.monotonic() + 8
    while time.monotonic() < deadline:  # keep commanding, as a teleop does (the watchdog is on)
        pub.publish(joint_command(target))
        latest = dict(zip(inbox.latest().name, inbox.latest().position))
        if all(abs(latest[k] - v) < 0.02 for k, v in target.items()):
            break
        time.sleep(0.02)
    wait_positions(inbox, target, node)
    latest = dict(zip(inbox.latest().name, inbox.latest().position))
    for name in ("shoulder_lift", "wrist_flex", "wrist_roll"):
        assert abs(latest[name] - start[name]) < 0.02, f"{name} moved without being commanded"

    array_pub = ros.publisher("/forward_position_controller/commands", Float64MultiArray, sim=node)
    pose = [0.1, 0.2, -0.2, 0.3, -0.5, 0.2]
    deadline = time.monotonic() + 8
    while time.monotonic() < deadline:
        array_pub.publish(Float64MultiArray(data=pose))
        if all(abs(a - b) < 0.02 for a, b in zip(joints_in_order(inbox.latest()), pose)):
            break
        time.sleep(0.02)
    wait_positions(inbox, dict(zip(JOINT_NAMES, pose)), node)


def test_out_of_range_and_malformed_commands_never_reach_a_servo(arm_factory, ros):
    node, emulator = arm_factory()
    diagnostics = subscribe_diagnostics(ros)
    inbox = subscribe_joint_states(ros)
    inbox.wait_count(1, 30.0, node)
    pub = ros.publisher("/joint_commands", type(joint_command({})), sim=node)
    bad = [
        joint_command({"shoulder_pan": float("nan")}),
        joint_command({"elbow_flex": float("inf")}),
        joint_command({"nose": 0.1}),
        joint_command({"gripper": 0.1, "gripper ": 0.2}),
    ]
    mismatched = joint_command({"wrist_flex": 0.1})
    mismatched.position = [0.1, 0.2]
    bad.append(mismatched)
    for _ in range(20):
        for msg in bad:
            pub.publish(msg)
        time.sleep(0.01)
    # Far outside every range: clamped to the calibrated ends, approached step by step.
    deadline = time.monotonic() + 6
    while time.monotonic() < deadline:
        pub.publish(joint_command({"shoulder_pan": 1e9, "elbow_flex": -1e9}))
        goals = emulator.goals()
        if goals[0] == CALIBRATION["shoulder_pan"]["range_max"] and goals[2] == CALIBRATION["elbow_flex"]["range_min"]:
            break
        for index, name in enumerate(JOINT_NAMES):
            motor = CALIBRATION[name]
            assert motor["range_min"] <= goals[index] <= motor["range_max"], f"{name} goal {goals[index]} outside {motor}"
        time.sleep(0.05)
    goals = emulator.goals()
    assert goals[0] == CALIBRATION["shoulder_pan"]["range_max"]
    assert goals[2] == CALIBRATION["elbow_flex"]["range_min"]
    low, high = range_in_rad("shoulder_pan")
    wait_positions(inbox, {"shoulder_pan": high}, node, tolerance=0.02)
    node.assert_alive()

    def counted(msgs):
        values = bus_values(msgs)
        return int(values.get("rejected_commands", 0)) >= 100 and int(values.get("clamped_targets", 0)) >= 1

    diagnostics.wait_for(counted, 5.0, "rejected and clamped commands counted in /diagnostics", node)
    values = bus_values(diagnostics.messages())
    assert int(values["limited_steps"]) > 0, "a jump of the whole range is approached step by step"


def test_the_watchdog_holds_position_when_commands_stop(arm_factory, ros):
    # Goals at most 0.05 rad ahead of the joint: with the servo's lag that is ~1.2 rad/s, so a far
    # target takes longer than the timeout.
    node, emulator = arm_factory("--command-timeout", "0.4", "--max-step", "0.05")
    diagnostics = subscribe_diagnostics(ros)
    inbox = subscribe_joint_states(ros)
    inbox.wait_count(1, 30.0, node)
    start = dict(zip(inbox.latest().name, inbox.latest().position))
    pub = ros.publisher("/joint_commands", type(joint_command({})), sim=node)
    target = start["shoulder_pan"] + 1.5

    def pan() -> float:
        return dict(zip(inbox.latest().name, inbox.latest().position))["shoulder_pan"]

    # Commands until the arm moves (the driver's reader may match the publisher a moment after
    # rclpy sees the subscription: early messages can be lost), then silence.
    deadline = time.monotonic() + 10
    while pan() < start["shoulder_pan"] + 0.02:
        assert time.monotonic() < deadline, "the arm never started towards the command"
        pub.publish(joint_command({"shoulder_pan": target}))
        time.sleep(0.02)
    moving = pan()
    time.sleep(1.5)
    held = pan()
    assert moving + 0.05 < held < target - 0.4, f"moved from {moving} to {held}: expected a stop part-way to {target}"
    time.sleep(0.5)
    still = dict(zip(inbox.latest().name, inbox.latest().position))["shoulder_pan"]
    assert abs(still - held) < 0.01, "the arm kept going after the watchdog fired"
    diagnostics.wait_for(lambda m: bus_values(m).get("watchdog_holds") == "1", 3.0, "watchdog_holds = 1", node)
    # A fresh command resumes motion.
    deadline = time.monotonic() + 6
    while (
        time.monotonic() < deadline
        and abs(dict(zip(inbox.latest().name, inbox.latest().position))["shoulder_pan"] - target) > 0.03
    ):
        pub.publish(joint_command({"shoulder_pan": target}))
        time.sleep(0.05)
    wait_positions(inbox, {"shoulder_pan": target}, node, tolerance=0.03)


def test_torque_service_switches_every_servo(arm_factory, ros):
    from std_srvs.srv import SetBool

    node, emulator = arm_factory()
    subscribe_joint_states(ros).wait_count(1, 30.0, node)
    assert all(slot["torque_enable"] == 1 for slot in emulator.slots())
    answer = ros.call(SetBool, "/torque_enable", SetBool.Request(data=False), sim=node)
    assert answer.success, answer.message
    assert all(slot["torque_enable"] == 0 for slot in emulator.slots())
    # With torque off a hand moves the arm; torque back on holds it there, no jump back.
    emulator.command("move 1 2600")
    time.sleep(0.2)
    answer = ros.call(SetBool, "/torque_enable", SetBool.Request(data=True), sim=node)
    assert answer.success, answer.message
    slots = emulator.slots()
    assert all(slot["torque_enable"] == 1 for slot in slots)
    assert abs(slots[0]["goal_position"] - (2600 - 100)) <= 2, slots[0]


def test_a_silent_servo_stops_goals_and_states_until_it_answers_again(arm_factory, ros):
    node, emulator = arm_factory("--retries", "1", "--reopen-after", "30")
    diagnostics = subscribe_diagnostics(ros)
    inbox = subscribe_joint_states(ros)
    inbox.wait_count(1, 30.0, node)
    pub = ros.publisher("/joint_commands", type(joint_command({})), sim=node)
    emulator.command("silent 3 on")
    time.sleep(0.3)
    goals_before = emulator.goals()
    inbox.clear()
    for _ in range(20):
        pub.publish(joint_command({"shoulder_pan": 0.5}))
        time.sleep(0.05)
    assert inbox.count() == 0, "joint_states published although a servo did not answer"
    assert emulator.goals() == goals_before, "goals written without fresh positions"

    def elbow_error(msgs):
        for msg in reversed(msgs):
            status = status_of(msg, f"{DRIVER}: elbow_flex (id 3)")
            if status is not None:
                return level(status) == 2 and "not answering" in status.message
        return False

    diagnostics.wait_for(elbow_error, 3.0, "elbow_flex reported as not answering", node)
    bus = next(status_of(m, f"{DRIVER}: bus") for m in reversed(diagnostics.messages()) if status_of(m, f"{DRIVER}: bus"))
    assert level(bus) == 2 and "elbow_flex" in bus.message, bus.message
    node.assert_alive()
    emulator.command("silent 3 off")
    inbox.wait_count(20, 5.0, node)
    deadline = time.monotonic() + 6
    while (
        time.monotonic() < deadline and abs(dict(zip(inbox.latest().name, inbox.latest().position))["shoulder_pan"] - 0.5) > 0.02
    ):
        pub.publish(joint_command({"shoulder_pan": 0.5}))
        time.sleep(0.05)
    wait_positions(inbox, {"shoulder_pan": 0.5}, node)


def test_an_unplugged_adapter_is_survived_and_reconnected(arm_factory, ros):
    node, emulator = arm_factory("--reconnect-interval", "0.2")
    diagnostics = subscribe_diagnostics(ros)
    inbox = subscribe_joint_states(ros)
    inbox.wait_count(1, 30.0, node)
    emulator.command("hangup 1.5")
    time.sleep(0.5)
    inbox.clear()
    time.sleep(0.5)
    assert inbox.count() == 0, "joint_states while the adapter is gone"
    diagnostics.wait_for(lambda m: bus_values(m).get("connected") == "false", 3.0, "connected = false", node)
    inbox.wait_count(50, 10.0, node)
    diagnostics.wait_for(lambda m: bus_values(m).get("reconnects") == "1", 5.0, "reconnects = 1", node)
    assert all(slot["torque_enable"] == 1 for slot in emulator.slots()), "torque restored after reconnecting"
    assert "bus reconnected" in node.log()


def test_leader_mode_publishes_hand_motion_and_never_drives_the_servos(arm_factory, ros):
    from std_srvs.srv import SetBool

    node, emulator = arm_factory("--leader")
    inbox = subscribe_joint_states(ros, "/leader/joint_states")
    inbox.wait_count(1, 30.0, node)
    assert all(slot["torque_enable"] == 0 for slot in emulator.slots())
    goals = emulator.goals()
    emulator.command("move 3 2400")
    expected = rad_from_ticks("elbow_flex", 2400)
    wait_positions(inbox, {"elbow_flex": expected}, node, tolerance=0.005)
    assert emulator.goals() == goals, "a leader must never be sent goals"
    topics = ros.topics()
    assert "/joint_states" not in topics
    # The node's own name reaches the graph through discovery, a little after its topics.
    wait_until(
        lambda: ("so101_leader_driver", "/") in ros.node.get_node_names_and_namespaces(),
        15.0,
        "the leader node in the graph",
        node,
    )
    subs = dict(ros.node.get_subscriber_names_and_types_by_node("so101_leader_driver", "/"))
    assert "/joint_commands" not in subs
    answer = ros.call(SetBool, "/torque_enable", SetBool.Request(data=True), sim=node)
    assert not answer.success and "leader" in answer.message
    assert all(slot["torque_enable"] == 0 for slot in emulator.slots())


@pytest.mark.parametrize("keep", [False, True])
def test_shutdown_turns_torque_off_unless_asked_not_to(arm_factory, ros, keep):
    args = ["--keep-torque-on-exit"] if keep else []
    node, emulator = arm_factory(*args)
    subscribe_joint_states(ros).wait_count(1, 30.0, node)
    assert node.stop() == 0
    torque = [slot["torque_enable"] for slot in emulator.slots()]
    assert torque == ([1] * 6 if keep else [0] * 6)


def test_a_missing_calibration_is_a_clear_error(arm_factory, tmp_path):
    import subprocess

    from driver_harness import DRIVER_NAME, ServoEmulator
    from harness import node_binary, node_environment

    emulator = ServoEmulator(tmp_path / "bus", tmp_path / "emu.log")
    try:
        done = subprocess.run(
            [str(node_binary(DRIVER_NAME)), "--port", str(tmp_path / "bus"), "--calibration", str(tmp_path / "none.json")],
            env=node_environment(),
            capture_output=True,
            text=True,
            timeout=30,
        )
        assert done.returncode != 0
        assert "calibrate first" in done.stderr, done.stderr
        done = subprocess.run(
            [str(node_binary(DRIVER_NAME)), "--port", str(tmp_path / "nothing"), "--calibration", str(tmp_path / "none.json")],
            env=node_environment(),
            capture_output=True,
            text=True,
            timeout=30,
        )
        assert done.returncode != 0
    finally:
        emulator.stop()


def test_diagnostics_report_every_servo_at_one_hertz(arm_factory, ros):
    node, emulator = arm_factory()
    diagnostics = subscribe_diagnostics(ros)
    subscribe_joint_states(ros).wait_count(1, 30.0, node)
    emulator.command("error 6 0x20")
    diagnostics.wait_count(3, 5.0, node)
    diagnostics.clear()
    time.sleep(3.0)
    assert 2 <= diagnostics.count() <= 4, f"{diagnostics.count()} /diagnostics in 3 s"
    last = diagnostics.latest()
    names = [status.name for status in last.status]
    assert names[0] == f"{DRIVER}: bus"
    for index, joint in enumerate(JOINT_NAMES):
        status = status_of(last, f"{DRIVER}: {joint} (id {index + 1})")
        values = {kv.key: kv.value for kv in status.values}
        assert float(values["voltage_v"]) > 5 and int(values["temperature_c"]) > 0, values
    gripper = status_of(last, f"{DRIVER}: gripper (id 6)")
    assert level(gripper) == 1 and "overload" in gripper.message, gripper
    bus = {kv.key: kv.value for kv in last.status[0].values}
    # The rate it reports is never above the requested one, and a slower one is said in the status.
    cycle_rate = float(bus["cycle_rate_hz"])
    assert 0 < cycle_rate <= 210 and float(bus["requested_rate_hz"]) == 200.0, bus
    if cycle_rate < 0.9 * 200 and level(last.status[0]) != 2:  # unless a fault (ERROR) is what it says
        assert "below the requested" in last.status[0].message, (last.status[0].message, bus)
    # A reply can miss its deadline when the emulator (realistic wire timing over a pty) is
    # starved of CPU on this 2-core machine; the bus retries it. Rare, never routine.
    transactions, timeouts = int(bus["transactions"]), int(bus["timeouts"])
    assert transactions > 0 and timeouts <= transactions / 200, bus


def test_servos_of_another_arm_are_refused_at_start_never_written(arm_factory):
    # The file says shoulder_pan is calibrated to 100..1000; the servos hold another calibration:
    # they belong to another arm. Nothing is written into their EPROM, torque stays off.
    wrong = {**CALIBRATION, "shoulder_pan": {**CALIBRATION["shoulder_pan"], "range_min": 100, "range_max": 1000}}
    node, emulator = arm_factory(calibration=wrong, emulator_calibration=CALIBRATION)
    node.exit_expected = True
    code = node.proc.wait(timeout=30)
    assert code != 0, node.log_tail()
    assert "EPROM calibration differs" in node.log() and "--write-calibration" in node.log(), node.log_tail()
    slots = emulator.slots()
    assert all(slot["torque_enable"] == 0 for slot in slots), slots
    assert (slots[0]["min_position_limit"], slots[0]["max_position_limit"]) == (1000, 3000), slots[0]


def test_a_wrong_calibration_written_on_request_never_moves_a_servo(arm_factory):
    # Asked to write the file (--write-calibration), the driver does; then shoulder_pan reads ~2000
    # against a range of 100..1000. Holding "present, clamped into the range" would swing the
    # joint; the driver refuses.
    wrong = {**CALIBRATION, "shoulder_pan": {**CALIBRATION["shoulder_pan"], "range_min": 100, "range_max": 1000}}
    node, emulator = arm_factory("--write-calibration", calibration=wrong, emulator_calibration=CALIBRATION)
    node.exit_expected = True
    code = node.proc.wait(timeout=30)
    assert code != 0, node.log_tail()
    assert "far outside its calibrated range" in node.log(), node.log_tail()
    slots = emulator.slots()
    assert all(slot["torque_enable"] == 0 for slot in slots), slots
    # Holding the bad reading would have meant a goal inside the (wrong) range: none was written.
    assert not 100 <= slots[0]["goal_position"] <= 1000, slots[0]


def test_shutdown_with_the_servos_silent_still_turns_torque_off(arm_factory, ros):
    # Every reply lost: the driver goes disconnected; on exit it broadcasts torque off, which the
    # servos obey without answering.
    # One retry and some slack: a start-up read must survive a scheduling hiccup of the emulator
    # on a loaded machine (with none, one late reply failed the start in a CI run).
    node, emulator = arm_factory("--reopen-after", "0.3", "--retries", "1", "--bus-slack-ms", "10")
    subscribe_joint_states(ros).wait_count(1, 30.0, node)
    assert all(slot["torque_enable"] == 1 for slot in emulator.slots())
    emulator.command("drop 1")
    wait_until(lambda: "bus lost" in node.log(), 5.0, "the driver to report the bus lost", node)
    assert node.stop() == 0
    assert all(slot["torque_enable"] == 0 for slot in emulator.slots()), emulator.slots()
