"""teleop_node against the real sim node, seen from rclpy: /joint_commands at its rate, joint and
Cartesian jogging (the grasp point checked with a forward kinematics computed here from the scene
file, independently of the Rust model), joint limits, the leader arm, the keyboard through a real
terminal, episode controls, and the scripted expert solving seeded cube_to_bin episodes."""

from __future__ import annotations

import json
import math
import os
import pty
import select
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from harness import (
    JOINT_LIMITS,
    JOINT_NAMES,
    LIMIT_TOLERANCE,
    REPO_ROOT,
    best_effort_qos,
    grasp_point,
    node_binary,
    node_environment,
    positions_by_name,
    reliable_qos,
    start_and_wait,
    wait_until,
)


def write_script(path: Path, lines: list[dict]) -> Path:
    path.write_text("".join(json.dumps(line) + "\n" for line in lines))
    return path


# A joint moving more than this between two consecutive states jumped (a sim reset), rad.
TELEPORT_RAD = 0.5


def jumped(before, after) -> bool:
    """Whether an arm joint moved more than TELEPORT_RAD between two consecutive JointStates."""
    return max(abs(a - b) for a, b in zip(after.position[:5], before.position[:5])) > TELEPORT_RAD


def commands_inbox(ros, name: str = "/joint_commands"):
    from sensor_msgs.msg import JointState

    return ros.subscribe(name, JointState, reliable_qos(1000))


def settle(running, timeout: float = 10.0, tolerance: float = 0.003):
    """Waits until the arm stops moving; returns its positions."""
    last = {}

    def still() -> bool:
        msg = running.joint_states.latest()
        nonlocal last
        now = positions_by_name(msg) if msg else {}
        done = bool(last) and all(abs(now[n] - last[n]) < tolerance for n in JOINT_NAMES)
        last = now
        return done

    wait_until(still, timeout, "the arm to settle", running.sim, period=0.2)
    return positions_by_name(running.joint_states.latest())


# =========================================================================== joint and Cartesian
def test_scripted_joint_jog_moves_the_sim_arm_at_the_set_speed_and_rate(sim_factory, teleop_factory, ros, tmp_path):
    running = start_and_wait(sim_factory, ros)
    commands = commands_inbox(ros)
    script = write_script(
        tmp_path / "jog.jsonl",
        [
            {"at": 0.0, "jog": [0, 0, 0, 0, 0, 0]},
            {"at": 1.0, "jog": [1, 0, 0, 0, 0, 1]},
            {"at": 2.0, "jog": [0, 0, 0, 0, 0, 0]},
        ],
    )
    teleop_factory("--source", "scripted", "--script", script, "--joint-speed", "0.5", "--gripper-speed", "0.2")
    commands.wait_count(10, 20.0, running.sim)
    start = positions_by_name(commands.messages()[0])
    time.sleep(3.0)
    items = commands.items()
    window = [t for t, _ in items if t >= items[-1][0] - 1.0]
    # Never faster than 50 Hz; a busy machine may make it slower, so the rate itself is not asserted.
    assert 1 <= len(window) <= 55, f"{len(window)} /joint_commands in the last second (50 Hz expected)"
    end = positions_by_name(items[-1][1])
    # Each period of the one-second jog moves the joint by speed x period (0.5 rad/s x 20 ms, the
    # gripper 0.2 x 20 ms), and no other step is taken: about 50 such periods on a quiet machine (0.5
    # rad, 0.2 rad), fewer when a busy one skips periods, never a longer step to catch up.
    pans = [positions_by_name(m)["shoulder_pan"] for _, m in items]
    grippers = [positions_by_name(m)["gripper"] for _, m in items]
    pan_steps = [b - a for a, b in zip(pans, pans[1:]) if abs(b - a) > 1e-9]
    gripper_steps = [b - a for a, b in zip(grippers, grippers[1:]) if abs(b - a) > 1e-9]
    assert pan_steps and all(s == pytest.approx(0.5 * 0.02, abs=1e-6) for s in pan_steps), pan_steps
    assert gripper_steps and all(s == pytest.approx(0.2 * 0.02, abs=1e-6) for s in gripper_steps), gripper_steps
    assert 10 <= len(pan_steps) <= 52 and len(gripper_steps) == len(pan_steps), (len(pan_steps), len(gripper_steps))
    assert end["shoulder_pan"] - start["shoulder_pan"] == pytest.approx(0.01 * len(pan_steps), abs=1e-6), (start, end)
    assert end["gripper"] - start["gripper"] == pytest.approx(0.004 * len(gripper_steps), abs=1e-6), (start, end)
    for name in ("shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll"):
        assert end[name] == pytest.approx(start[name], abs=1e-9), name
    # The sim arm went there.
    arm = settle(running)
    assert arm["shoulder_pan"] == pytest.approx(end["shoulder_pan"], abs=0.03), arm


def test_cartesian_jog_moves_the_grasp_point_along_each_axis(sim_factory, teleop_factory, ros, tmp_path):
    running = start_and_wait(sim_factory, ros)
    commands = commands_inbox(ros)
    reach = [0.1, -0.3, 0.3, 1.0, 0.2, 0.5]  # grasp point 11 cm above the table
    # Absolute to a reaching pose first (Cartesian mode ignores the mode for targets), then 1 s of
    # +x, then 1 s of -z and 1 s of +y, at 4 cm/s.
    script = write_script(
        tmp_path / "cartesian.jsonl",
        [
            {"at": 0.0, "targets": reach},
            {"at": 3.0, "jog": [0, 0, 0, 0, 0, 0]},
            {"at": 4.0, "jog": [1, 0, 0, 0, 0, 0]},
            {"at": 5.0, "jog": [0, 0, -1, 0, 0, 0]},
            {"at": 6.0, "jog": [0, 1, 0, 0, 0, 0]},
            {"at": 7.0, "jog": [0, 0, 0, 0, 0, 0]},
        ],
    )
    teleop_factory("--source", "scripted", "--script", script, "--mode", "cartesian", "--linear-speed", "0.04")
    commands.wait_count(5, 20.0, running.sim)
    t0 = commands.items()[0][0]

    def commanded_at(seconds: float) -> dict[str, float]:
        wait_until(lambda: commands.items()[-1][0] >= t0 + seconds, 20.0, f"commands {seconds} s in", running.sim)
        return positions_by_name(min(commands.items(), key=lambda item: abs(item[0] - (t0 + seconds)))[1])

    points = [grasp_point(commanded_at(t)) for t in (3.9, 4.95, 5.95, 6.95)]
    moves = np.diff(points, axis=0)
    for move, axis, sign in zip(moves, (0, 2, 1), (1, -1, 1)):
        expected = np.zeros(3)
        expected[axis] = sign * 0.04
        assert np.linalg.norm(move - expected) < 0.006, f"grasp point moved {move} (expected {expected})"
    # And the sim's arm follows: its own grasp point ends where the last command puts it.
    arm = settle(running)
    assert np.linalg.norm(grasp_point(arm) - points[-1]) < 0.01, (grasp_point(arm), points[-1])


def test_no_command_leaves_the_joint_limits_in_either_mode(sim_factory, teleop_factory, ros, tmp_path):
    running = start_and_wait(sim_factory, ros)
    commands = commands_inbox(ros)
    script = write_script(
        tmp_path / "push.jsonl",
        [
            {"at": 0.0, "jog": [1, -1, 1, -1, 1, 1]},
            {"at": 2.0, "control": "toggle_mode"},
            {"at": 2.0, "jog": [1, 1, 1, 1, 1, -1]},
            {"at": 4.0, "jog": [0, 0, -1, -1, -1, 0]},
            {"at": 6.0, "control": "quit"},
        ],
    )
    teleop = teleop_factory(
        "--source", "scripted", "--script", script, "--joint-speed", "3", "--linear-speed", "0.5", "--angular-speed", "3"
    )
    wait_until(lambda: not teleop.alive(), 30.0, "the script's quit", running.sim)
    assert teleop.proc.returncode == 0, teleop.log_tail()
    values = [positions_by_name(m) for m in commands.messages()]
    assert len(values) > 200
    for command in values:
        for name, value in command.items():
            low, high = JOINT_LIMITS[name]
            assert low - 1e-9 <= value <= high + 1e-9, f"{name}={value} outside {low}..{high}"
    # Full speed for 2 s reached the limits in joint mode.
    at_two = values[min(len(values) - 1, 95)]
    assert at_two["shoulder_pan"] == pytest.approx(JOINT_LIMITS["shoulder_pan"][1], abs=1e-6), at_two
    assert "out of reach" in teleop.log()
    for msg in running.joint_states.messages()[-20:]:
        for name, value in positions_by_name(msg).items():
            low, high = JOINT_LIMITS[name]
            assert low - LIMIT_TOLERANCE <= value <= high + LIMIT_TOLERANCE, (name, value)


# =========================================================================== leader and devices
def test_leader_arm_is_followed_and_a_silent_leader_holds_the_arm(sim_factory, teleop_factory, ros):
    from sensor_msgs.msg import JointState

    running = start_and_wait(sim_factory, ros)
    commands = commands_inbox(ros)
    leader = ros.publisher("/leader/joint_states", JointState, wait_for_subscriber=None)
    teleop = teleop_factory("--source", "leader", "--max-step", "0.05")
    wait_until(lambda: leader.get_subscription_count() >= 1, 20.0, "teleop's leader subscription", running.sim)

    def send(pose: list[float], seconds: float):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            leader.publish(JointState(name=JOINT_NAMES, position=[float(v) for v in pose]))
            time.sleep(0.02)

    pose = [0.4, -0.3, 0.5, 0.6, -0.5, 1.0]
    send(pose, 2.0)
    followed = positions_by_name(commands.latest())
    assert all(followed[n] == pytest.approx(v, abs=1e-6) for n, v in zip(JOINT_NAMES, pose)), followed
    # Every step of the way at most --max-step per joint.
    values = [np.array([positions_by_name(m)[n] for n in JOINT_NAMES]) for m in commands.messages()]
    assert max(np.abs(np.diff(values, axis=0)).max(axis=1)) <= 0.05 + 1e-9
    # Silent leader: the commands hold the last pose.
    time.sleep(1.5)
    held = [positions_by_name(m) for m in commands.messages()[-20:]]
    assert all(h == followed for h in held)
    wait_until(lambda: "went silent" in teleop.log(), 5.0, "the log to say the leader went silent", running.sim)
    # It comes back: following resumes.
    pose2 = [-0.3, 0.2, 0.1, 0.0, 0.4, 0.2]
    send(pose2, 2.5)
    back = positions_by_name(commands.latest())
    assert all(back[n] == pytest.approx(v, abs=1e-6) for n, v in zip(JOINT_NAMES, pose2)), back
    arm = settle(running)
    assert all(arm[n] == pytest.approx(v, abs=0.05) for n, v in zip(JOINT_NAMES, pose2) if n != "gripper"), arm


def test_a_gamepad_source_without_a_pad_holds_the_arm(sim_factory, teleop_factory, ros):
    running = start_and_wait(sim_factory, ros)
    commands = commands_inbox(ros)
    teleop_factory("--source", "gamepad")
    commands.wait_count(50, 20.0, running.sim)
    first = positions_by_name(commands.messages()[0])
    assert all(positions_by_name(m) == first for m in commands.messages())
    start = positions_by_name(running.joint_states.latest())
    assert all(first[n] == pytest.approx(start[n], abs=0.02) for n in JOINT_NAMES), (first, start)


def test_the_keyboard_drives_the_arm_through_a_real_terminal(sim_factory, ros, tmp_path):
    from std_msgs.msg import String

    running = start_and_wait(sim_factory, ros)
    commands = commands_inbox(ros)
    events = ros.subscribe("/episode/events", String, reliable_qos(100))
    controller, terminal = pty.openpty()
    log = open(tmp_path / "teleop_keyboard.log", "wb")
    teleop = subprocess.Popen(
        [str(node_binary("teleop_node")), "--source", "keyboard", "--joint-speed", "0.5"],
        stdin=terminal,
        stdout=terminal,
        stderr=log,
        env=node_environment(),
        cwd=REPO_ROOT,
    )
    os.close(terminal)
    screen = b""
    try:
        deadline = time.monotonic() + 20
        while b"shoulder_pan" not in screen and time.monotonic() < deadline:
            if select.select([controller], [], [], 0.2)[0]:
                screen += os.read(controller, 4096)
        assert b"shoulder_pan" in screen, f"no key help on screen: {screen[-500:]!r}"
        commands.wait_count(5, 20.0, running.sim)
        before, since = positions_by_name(commands.latest()), time.monotonic()
        # Right arrow held for ~1 s (a press, then auto-repeat every 30 ms).
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            os.write(controller, b"\x1b[C")
            time.sleep(0.03)
        time.sleep(1.0)  # the hold runs out: motion stops
        after, elapsed = positions_by_name(commands.latest()), time.monotonic() - since
        moved = after["shoulder_pan"] - before["shoulder_pan"]
        # The held key moved the joint the right way for at least the press's hold (0.55 s at
        # 0.5 rad/s), and never faster than 0.5 rad/s of the time that passed, however busy the
        # machine (teleop's periods never run ahead of the clock; one period's step of slack).
        assert 0.25 <= moved <= 0.5 * elapsed + 0.01, f"shoulder_pan moved {moved:.3f} rad in {elapsed:.2f} s"
        time.sleep(0.3)
        assert positions_by_name(commands.latest()) == after, "still moving after the key was let go"
        os.write(controller, b"\r")  # Enter: start recording
        events.wait_for(lambda msgs: any(m.data == "start" for m in msgs), 5.0, "a start event", running.sim)
        os.write(controller, b"q")
        assert teleop.wait(timeout=10) == 0
    finally:
        if teleop.poll() is None:
            teleop.kill()
        os.close(controller)
        log.close()


# =========================================================================== episode controls
def test_episode_controls_reach_the_recorder_topic_and_reset_the_sim(sim_factory, teleop_factory, ros, tmp_path):
    from geometry_msgs.msg import PoseStamped
    from std_msgs.msg import String

    running = start_and_wait(sim_factory, ros, "--seed", "3")
    events = ros.subscribe("/episode/events", String, reliable_qos(100))
    poses = ros.subscribe("/cube/pose", PoseStamped, best_effort_qos())
    poses.wait_count(1, 10.0, running.sim)
    first_cube = poses.latest().pose.position
    script = write_script(
        tmp_path / "controls.jsonl",
        [
            {"at": 1.0, "control": "toggle_recording"},
            {"at": 1.2, "control": "success"},
            {"at": 1.4, "control": "toggle_recording"},
            {"at": 1.6, "control": "start"},
            {"at": 1.8, "control": "failure"},
            {"at": 2.0, "control": "rerecord"},
            {"at": 2.2, "control": "stop"},
            {"at": 2.4, "control": "reset"},
        ],
    )
    teleop_factory("--source", "scripted", "--script", script)
    expected = ["start", "success", "stop", "start", "failure", "rerecord", "stop"]
    events.wait_for(lambda msgs: len(msgs) >= len(expected), 15.0, "the episode events", running.sim)
    assert [m.data for m in events.messages()] == expected
    # /sim/reset moved the cube (seeded placement) and started episode 1.
    wait_until(
        lambda: math.dist((poses.latest().pose.position.x, poses.latest().pose.position.y), (first_cube.x, first_cube.y)) > 0.005,
        10.0,
        "the cube to move after the reset",
        running.sim,
    )
    wait_until(lambda: "new episode" in running.sim.log(), 5.0, "the sim's new episode", running.sim)


# =========================================================================== the expert
def test_the_expert_puts_the_cube_in_the_bin_in_seeded_episodes_and_the_recorder_keeps_them(
    sim_factory, teleop_factory, recorder_factory, ros, tmp_path
):
    from recorder_harness import episode_dirs, load_metadata, mcap_files, read_bag
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String

    sim = sim_factory("--speed", "3", "--seed", "11")
    recorder = recorder_factory()
    events = ros.subscribe("/episode/events", String, reliable_qos(1000))
    states = ros.subscribe("/joint_states", JointState, best_effort_qos())
    ros.wait_for_graph(
        lambda: ros.node.count_subscribers("/episode/events") >= 2, 20.0, "the recorder's /episode/events subscription", sim
    )
    report = tmp_path / "expert.json"
    episodes = 4
    teleop = teleop_factory(
        "--source",
        "expert",
        "--sim-time",
        "--episodes",
        str(episodes),
        "--seed",
        "5",
        "--waypoint-noise",
        "0.003",
        "--report",
        report,
    )
    wait_until(lambda: not teleop.alive(), 150.0, f"the expert's {episodes} episodes", sim)
    assert teleop.proc.returncode == 0, teleop.log_tail()
    result = json.loads(report.read_text())
    assert result["episodes"] == episodes
    assert result["successes"] >= episodes - 1, json.dumps(result, indent=1)
    texts = [m.data for m in events.messages()]
    starts = [t for t in texts if t.startswith("start ")]
    assert len(starts) == episodes and all(json.loads(t[6:])["task"] == "put the cube in the bin" for t in starts), texts
    assert texts.count("stop") == episodes
    assert texts.count("success") == result["successes"]
    # Each reset came a moment after the episode's stop, time for the recorder to close the episode
    # before the arm jumps home (right after it, the reset pose became 15 of 100 bags' last state).
    stops = [at for at, m in events.items() if m.data == "stop"]
    arrived = states.items()
    jumps = [at for (_, before), (at, after) in zip(arrived, arrived[1:]) if jumped(before, after)]
    for stop in stops[:-1]:  # the last episode ends the run: no reset follows it
        reset = next((at for at in jumps if at > stop), None)
        assert reset is not None, f"no jump of the arm to its reset pose after the stop at {stop:.3f}"
        assert reset - stop > 0.15, f"the sim reset {reset - stop:.3f} s after a stop event"
    # Every episode started from another cube pose (the sim's seeded resets).
    cubes = [tuple(r["cube"][:2]) for r in result["results"]]
    assert len({(round(x, 3), round(y, 3)) for x, y in cubes}) == episodes, cubes
    # One bag per episode, with the expert's verdict, task and seed, and its motion in it.
    wait_until(
        lambda: (
            len(episode_dirs(recorder.output)) == episodes
            and all((d / "metadata.yaml").is_file() for d in episode_dirs(recorder.output))
        ),
        15.0,
        "the episode bags",
        sim,
    )
    for directory, outcome, start in zip(episode_dirs(recorder.output), result["results"], starts):
        custom = load_metadata(directory)["custom_data"]
        announced = json.loads(start[6:])
        assert custom["success"] == str(outcome["success"]).lower(), (directory.name, custom, outcome)
        assert (custom["task"], custom["seed"]) == (announced["task"], str(announced["seed"])), custom
        bag = read_bag(mcap_files(directory)[0])
        before_last, last = (m.ros for m in bag.on("/joint_states")[-2:])
        assert not jumped(before_last, last), f"{directory.name} ends at the reset pose"
        commands = bag.on("/joint_commands")
        # About 380 on a quiet machine (7.6 s at 50 Hz); a busy one can skip periods.
        assert len(commands) > 50, f"{directory.name}: {len(commands)} joint_commands (about 7.6 s at 50 Hz expected)"
        grippers = [m.ros.position[5] for m in commands]
        assert min(grippers) < 0 < 0.8 < max(grippers), f"{directory.name}: the gripper never opened and closed"


def test_in_lockstep_each_command_is_stamped_with_the_state_it_answers(sim_factory, teleop_factory, ros):
    """The expert in step with the sim: each command advances one control period, and its stamp is
    the sim time of the /joint_states it answers (the period it acts in), so a recording places it
    on that state's frame whatever the order the recorder took the two in."""
    sim = sim_factory("--lockstep", "--step-on-command", "--seed", "3")
    commands = commands_inbox(ros)
    teleop = teleop_factory("--source", "expert", "--lockstep", "--episodes", "1", "--seed", "3")
    wait_until(lambda: commands.count() >= 90, 60.0, "90 lockstep commands", sim)
    assert teleop.alive(), teleop.log_tail()
    stamps = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in commands.messages()[:90]])
    assert np.all(stamps > 0), f"unstamped lockstep commands: {stamps[:10]}"
    # One control period of the sim (its default 100 Hz: five 2 ms physics steps) from one command
    # to the next: one step per command, each stamped with the state that step started from.
    steps = stamps / 0.002
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-3)
    assert set(np.round(np.diff(steps)).astype(int)) == {5}, np.diff(steps)


# =========================================================================== bad input
def test_bad_flags_and_scripts_are_refused_with_a_message(tmp_path):
    def run(*args):
        return subprocess.run(
            [str(node_binary("teleop_node")), *args],
            env=node_environment(),
            capture_output=True,
            text=True,
            timeout=60,
            stdin=subprocess.DEVNULL,
        )

    for args, words in {
        ("--source", "telepathy"): "--source",
        ("--source", "scripted"): "--script",
        ("--rate", "0"): "rate",
        ("--deadzone", "2"): "dead zone",
        ("--bin-xyz", "1,2"): "x,y,z",
    }.items():
        done = run(*args)
        assert done.returncode == 2 and words in done.stderr, (args, done.stderr)
    bad = tmp_path / "bad.jsonl"
    bad.write_text('{"at": 0, "jog": [0, 0, 0, 0, 0, 0]}\n{"at": 1, "jog": [1, 2]}\n')
    done = run("--source", "scripted", "--script", str(bad))
    assert done.returncode == 1 and "line 2" in done.stderr, done.stderr
    # The keyboard needs a terminal.
    done = run("--source", "keyboard", "--duration", "1")
    assert done.returncode == 1 and "terminal" in done.stderr, done.stderr
    help_text = run("--help").stdout
    assert "Left/Right" in help_text and "--source" in help_text
