"""The node plumbing every node shares, seen from rclpy: ROS_DOMAIN_ID, localhost-only discovery,
logs on /rosout, and clear failures for bad start-up input."""

from __future__ import annotations

import subprocess
import time

import pytest
from harness import Probe, best_effort_qos, blind_domain, node_binary, node_environment, reliable_qos, start_and_wait


def joint_states_seen(domain_id: int, seconds: float) -> int:
    """How many /joint_states an rclpy node in `domain_id` receives within `seconds`."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import JointState

    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    try:
        node = rclpy.create_node(f"domain_probe_{domain_id}", context=context)
        received = []
        node.create_subscription(JointState, "/joint_states", received.append, reliable_qos())
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        executor.shutdown()
        node.destroy_node()
        return len(received)
    finally:
        rclpy.try_shutdown(context=context)


def test_ros_domain_id_is_honoured(sim_factory, monkeypatch):
    monkeypatch.setenv("ROS_DOMAIN_ID", "7")
    sim = sim_factory()
    assert joint_states_seen(7, 4.0) > 50, "a peer in domain 7 gets nothing from a node started with ROS_DOMAIN_ID=7"
    assert joint_states_seen(0, 2.0) == 0, "a peer in domain 0 hears a node started with ROS_DOMAIN_ID=7"
    sim.assert_alive()


@pytest.mark.parametrize("variable", [("ROS_LOCALHOST_ONLY", "1"), ("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")])
def test_localhost_only_still_talks_to_local_peers(sim_factory, ros, monkeypatch, variable):
    monkeypatch.setenv(*variable)
    start_and_wait(sim_factory, ros)


def test_logs_are_mirrored_to_rosout(sim_factory, ros):
    from rcl_interfaces.msg import Log
    from std_srvs.srv import Trigger

    running = start_and_wait(sim_factory, ros)
    rosout = ros.subscribe("/rosout", Log, best_effort_qos(1000))
    time.sleep(1.0)  # let the subscription match before the node logs
    response = ros.call(Trigger, running.sim.name("sim/reset"), sim=running.sim)
    assert response.success
    records = rosout.wait_for(
        lambda logs: any(log.name == "so101_sim_node" and "new episode" in log.msg for log in logs),
        timeout=10.0,
        what="the node's 'new episode' record on /rosout",
        sim=running.sim,
    )
    record = next(log for log in records if "new episode" in log.msg)
    assert record.level == Log.INFO
    assert "episode=1" in record.msg, record.msg


def run_node_expecting_failure(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(node_binary()), *args], env=node_environment(), capture_output=True, text=True, timeout=30)


def test_bad_scene_gives_a_clear_error_and_exit_code():
    done = run_node_expecting_failure("--scene", "/nonexistent/scene.xml")
    assert done.returncode == 1, done
    assert "/nonexistent/scene.xml" in done.stderr, done.stderr
    assert "Press Enter" not in done.stdout + done.stderr  # MuJoCo's own handler never runs


def test_malformed_scene_gives_a_clear_error(tmp_path):
    scene = tmp_path / "broken.xml"
    scene.write_text("<mujoco><worldbody><body><geom type='box' size='0.1 0.1'/></worldbody></mujoco>")
    for lite in ([], ["--lite"]):
        done = run_node_expecting_failure("--scene", str(scene), *lite)
        assert done.returncode == 1, done
        assert "broken.xml" in done.stderr, done.stderr
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


def test_bad_flags_are_refused_with_a_message():
    cases = {
        "--rate": ["--rate", "0"],
        "--rate ": ["--rate", "nan"],
        "--speed": ["--speed=-2"],
        "--task": ["--task", "juggle"],
        "--lockstep": ["--lockstep", "--speed", "2"],
    }
    for flag, args in cases.items():
        done = run_node_expecting_failure(*args)
        assert done.returncode == 2, (args, done)
        assert done.stderr.startswith("error:") and flag.strip() in done.stderr, done.stderr
    done = run_node_expecting_failure("--rate", "1000")  # faster than the 2 ms physics step
    assert done.returncode == 1 and "lower --rate" in done.stderr, done.stderr


def test_help_lists_every_flag():
    done = subprocess.run([str(node_binary()), "--help"], capture_output=True, text=True, timeout=30)
    assert done.returncode == 0
    for flag in (
        "--scene",
        "--lite",
        "--task",
        "--dense-reward",
        "--seed",
        "--rate",
        "--speed",
        "--lockstep",
        "--demo",
        "--duration",
        "--namespace",
    ):
        assert flag in done.stdout, flag


def test_a_probe_blind_to_a_publisher_starts_over_on_a_fresh_participant(sim_factory, monkeypatch):
    """The probe's remedy for Fast DDS missing a starting node's publications (so101.stack.discovery).
    The blindness is made here: the probe's first participant opens in another domain. Its
    subscription gets nothing, a witness in the node's domain sees the publisher, and the probe
    starts over there with the same Inbox."""
    import os

    from sensor_msgs.msg import JointState

    sim = sim_factory()
    node_domain = os.environ.get("ROS_DOMAIN_ID", "0")
    monkeypatch.setenv("ROS_DOMAIN_ID", blind_domain())
    probe = Probe("so101_blind_probe")
    try:
        monkeypatch.setenv("ROS_DOMAIN_ID", node_domain)
        states = probe.subscribe("/joint_states", JointState, best_effort_qos())
        states.wait_count(5, 20.0, sim)
        assert probe.rediscoveries == 1
    finally:
        probe.close()


def test_a_hung_command_fails_with_its_native_and_python_stacks():
    """The harness's guard on long commands (trainings): a command past its timeout fails the test
    with where each of its processes was, natively (gdb) and in Python (faulthandler)."""
    import sys

    from harness import run_or_dump_stacks

    # The parent sleeps on after its child: it is aborted after the child, and must still be there.
    child = (
        "import subprocess, sys, time; subprocess.run([sys.executable, '-c', 'import time; time.sleep(120)']); time.sleep(120)"
    )
    with pytest.raises(pytest.fail.Exception) as failure:
        run_or_dump_stacks([sys.executable, "-c", child], timeout=3, env={})
    report = str(failure.value)
    assert "ran over 3 s; its processes' native stacks" in report
    # Both processes, the sleeping one in the C library's sleep, then each one's Python stack.
    assert report.count("time.sleep(120)") >= 1 and "#0 " in report and "sleep" in report.split("their Python stacks")[0]
    assert report.count("Fatal Python error: Aborted") == 2 and 'File "<string>", line 1 in <module>' in report
