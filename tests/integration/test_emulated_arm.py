"""The emulated arm out of the box: `so101-launch --robot real --emulate` from an empty HOME starts
the servo-bus emulator as the arm of assets/emulated_arm/so101_calibration.json and the driver with
that same file, so the driver finds the servos' EPROM as the file says (nothing to rewrite), the
joints rest mid-range, and /joint_states flow; LeRobot's calibration place (~/.cache/huggingface)
is never touched.

Runs the launcher of this checkout (python -m so101.stack.launch, the editable package in python/) with the driver
and emulator binaries of $SO101_BIN_DIR.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys

from harness import REPO_ROOT, best_effort_qos, node_binary, wait_for_launcher

CALIBRATION = REPO_ROOT / "assets" / "emulated_arm" / "so101_calibration.json"
RAD_PER_TICK = 2 * math.pi / 4095
GRIPPER_CLOSED_RAD = -0.1745


def expected_rest_radians(calibration: dict) -> dict[str, float]:
    """Where the driver should see each joint of the emulated arm: the middle of its range."""
    rest = {}
    for name, motor in calibration.items():
        mid = (motor["range_min"] + motor["range_max"]) // 2
        if name == "gripper":
            rest[name] = GRIPPER_CLOSED_RAD + (mid - motor["range_min"]) * RAD_PER_TICK
        else:
            rest[name] = (mid - (motor["range_min"] + motor["range_max"]) / 2) * RAD_PER_TICK
    return rest


def test_emulated_arm_comes_up_from_an_empty_home_with_matching_calibration(ros, tmp_path):
    from sensor_msgs.msg import JointState

    bin_dir = node_binary("so101_feetech_driver").parent
    node_binary("so101_servo_emulator")
    home, logs = tmp_path / "home", tmp_path / "logs"
    home.mkdir()
    env = {key: value for key, value in os.environ.items() if not key.startswith(("HF_", "XDG_")) and key != "PYTHONPATH"}
    env.update(HOME=str(home), SO101_BIN_DIR=str(bin_dir), PYTHONPATH=str(REPO_ROOT / "scripts"))
    states = ros.subscribe("/joint_states", JointState, best_effort_qos())
    launcher = subprocess.Popen(
        [sys.executable, "-m", "so101.stack.launch", "--robot", "real", "--emulate", "--control", "none", "--log-dir", str(logs)],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    output = ""
    try:
        output = wait_for_launcher(launcher, 60.0)
        messages = states.wait_count(20, 10.0)
        launcher.send_signal(signal.SIGTERM)
        rest, _ = launcher.communicate(timeout=60)
        output += rest
    finally:
        if launcher.poll() is None:
            launcher.kill()
            launcher.wait()
    assert launcher.returncode == 0, output
    driver_log = (logs / "so101_feetech_driver.log").read_text()
    assert "started so101_servo_emulator" in output and "started so101_feetech_driver" in output, output
    # The driver found the servos' EPROM as its calibration file says: nothing rewritten.
    assert "differed from the calibration file" not in driver_log, driver_log[-3000:]
    assert "servos configured" in driver_log, driver_log[-3000:]
    # The joints rest in the middle of their calibrated ranges.
    expected = expected_rest_radians(json.loads(CALIBRATION.read_text()))
    last = dict(zip(messages[-1].name, messages[-1].position))
    for name, radians in expected.items():
        assert abs(last[name] - radians) < 0.01, (name, last[name], radians)
    assert not (home / ".cache" / "huggingface").exists(), "LeRobot's calibration place was touched"
