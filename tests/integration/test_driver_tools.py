"""The driver's set-up tools as a user runs them in a terminal, against the servo-bus emulator:
`calibrate` (prompts, a live sweep, LeRobot's file), `scan` and `setup-motors`."""

from __future__ import annotations

import json
import subprocess
import time

from driver_harness import DRIVER_NAME, ServoEmulator
from harness import node_binary, node_environment
from tool_terminal import Terminal


def tool(*args: str, env=None) -> Terminal:
    """so101_feetech_driver ARGS as a user runs it in a terminal."""
    return Terminal([str(node_binary(DRIVER_NAME)), *args], env=env or node_environment())


def test_calibrate_in_a_terminal_writes_lerobots_file_and_the_servos(tmp_path):
    emulator = ServoEmulator(tmp_path / "bus", tmp_path / "emu.log", "--timing", "instant")
    try:
        centre = [1900, 2200, 2047, 1600, 2500, 2100]
        for servo_id, raw in enumerate(centre, start=1):
            emulator.command(f"move {servo_id} {raw}")
        env = {**node_environment(), "HF_LEROBOT_CALIBRATION": str(tmp_path / "cal")}
        terminal = tool("calibrate", "--port", str(tmp_path / "bus"), "--robot-id", "desk_arm", env=env)
        terminal.expect("middle of its range")
        terminal.press_enter()
        terminal.expect("press Enter when done")
        for servo_id, raw in enumerate(centre, start=1):
            for delta in (-600 - 10 * servo_id, 700 + 10 * servo_id, 0):
                emulator.command(f"move {servo_id} {raw + delta}")
                time.sleep(0.15)
        terminal.press_enter()
        assert terminal.wait(15) == 0, terminal.text()
        path = tmp_path / "cal" / "robots" / "so_follower" / "desk_arm.json"
        calibration = json.loads(path.read_text())
        assert list(calibration) == ["shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper"]
        slots = emulator.slots()
        for index, (name, motor) in enumerate(calibration.items()):
            assert motor["id"] == index + 1 and motor["drive_mode"] == 0
            assert motor["homing_offset"] == centre[index] - 2047
            if name == "wrist_roll":
                assert (motor["range_min"], motor["range_max"]) == (0, 4095)
            else:
                assert (motor["range_min"], motor["range_max"]) == (2047 - 600 - 10 * (index + 1), 2047 + 700 + 10 * (index + 1))
            assert slots[index]["homing_offset"] == motor["homing_offset"]
            assert (slots[index]["min_position_limit"], slots[index]["max_position_limit"]) == (
                motor["range_min"],
                motor["range_max"],
            )
        assert "Calibration written" in terminal.text()
    finally:
        emulator.stop()


def test_scan_lists_the_servos_as_json(tmp_path):
    emulator = ServoEmulator(tmp_path / "bus", tmp_path / "emu.log", "--ids", "1,2,3,7", "--timing", "instant")
    try:
        done = subprocess.run(
            [str(node_binary(DRIVER_NAME)), "scan", "--port", str(tmp_path / "bus"), "--json", "--max-id", "20"],
            env=node_environment(),
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert done.returncode == 0, done.stderr
        found = json.loads(done.stdout)
        assert [servo["id"] for servo in found[0]["servos"]] == [1, 2, 3, 7]
        assert all(servo["model"] == 777 for servo in found[0]["servos"])
    finally:
        emulator.stop()


def test_setup_motors_assigns_the_id_of_the_one_connected_servo(tmp_path):
    # Two factory servos (both id 1); the user connects the gripper's first.
    emulator = ServoEmulator(tmp_path / "bus", tmp_path / "emu.log", "--ids", "1,1", "--plugged", "0", "--timing", "instant")
    try:
        terminal = tool("setup-motors", "--port", str(tmp_path / "bus"), "--joints", "gripper,wrist_roll")
        terminal.expect("'gripper' servo ONLY")
        terminal.press_enter()
        terminal.expect("id 1 -> 6")
        emulator.command("unplug 0")
        emulator.command("plug 1")
        terminal.expect("'wrist_roll' servo ONLY")
        terminal.press_enter()
        assert terminal.wait(15) == 0, terminal.text()
        assert "id 1 -> 5" in terminal.text()
        assert [slot["id"] for slot in emulator.slots()] == [6, 5]
    finally:
        emulator.stop()
