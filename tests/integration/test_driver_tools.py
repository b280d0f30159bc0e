"""The driver's set-up tools as a user runs them in a terminal, against the servo-bus emulator:
`calibrate` (prompts, a live sweep, LeRobot's file), `scan` and `setup-motors`."""

from __future__ import annotations

import json
import subprocess
import threading
import time

from driver_harness import DRIVER_NAME, ServoEmulator
from harness import node_binary, node_environment


class Terminal:
    """A tool process with stdin/stdout pipes; `expect` waits for text in its output."""

    def __init__(self, *args: str, env=None):
        self.proc = subprocess.Popen(
            [str(node_binary(DRIVER_NAME)), *args],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            env=env or node_environment(), text=True, bufsize=0,
        )
        self.output = ""
        self._lock = threading.Lock()
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self):
        while chunk := self.proc.stdout.read(1):
            with self._lock:
                self.output += chunk

    def expect(self, text: str, timeout: float = 15.0) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self._lock:
                if text in self.output:
                    return
            if self.proc.poll() is not None:
                break
            time.sleep(0.02)
        raise AssertionError(f"{text!r} not seen; output so far:\n{self.output}")

    def press_enter(self) -> None:
        self.proc.stdin.write("\n")
        self.proc.stdin.flush()


def test_calibrate_in_a_terminal_writes_lerobots_file_and_the_servos(tmp_path):
    emulator = ServoEmulator(tmp_path / "bus", tmp_path / "emu.log", "--timing", "instant")
    try:
        centre = [1900, 2200, 2047, 1600, 2500, 2100]
        for servo_id, raw in enumerate(centre, start=1):
            emulator.command(f"move {servo_id} {raw}")
        env = {**node_environment(), "HF_LEROBOT_CALIBRATION": str(tmp_path / "cal")}
        terminal = Terminal("calibrate", "--port", str(tmp_path / "bus"), "--robot-id", "desk_arm", env=env)
        terminal.expect("middle of its range")
        terminal.press_enter()
        terminal.expect("press Enter when done")
        for servo_id, raw in enumerate(centre, start=1):
            for delta in (-600 - 10 * servo_id, 700 + 10 * servo_id, 0):
                emulator.command(f"move {servo_id} {raw + delta}")
                time.sleep(0.15)
        terminal.press_enter()
        assert terminal.proc.wait(timeout=15) == 0, terminal.output
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
            assert (slots[index]["min_position_limit"], slots[index]["max_position_limit"]) == (motor["range_min"], motor["range_max"])
        assert "Calibration written" in terminal.output
    finally:
        emulator.stop()


def test_scan_lists_the_servos_as_json(tmp_path):
    emulator = ServoEmulator(tmp_path / "bus", tmp_path / "emu.log", "--ids", "1,2,3,7", "--timing", "instant")
    try:
        done = subprocess.run(
            [str(node_binary(DRIVER_NAME)), "scan", "--port", str(tmp_path / "bus"), "--json", "--max-id", "20"],
            env=node_environment(), capture_output=True, text=True, timeout=60,
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
        terminal = Terminal("setup-motors", "--port", str(tmp_path / "bus"), "--joints", "gripper,wrist_roll")
        terminal.expect("'gripper' servo ONLY")
        terminal.press_enter()
        terminal.expect("id 1 -> 6")
        emulator.command("unplug 0")
        emulator.command("plug 1")
        terminal.expect("'wrist_roll' servo ONLY")
        terminal.press_enter()
        assert terminal.proc.wait(timeout=15) == 0, terminal.output
        assert "id 1 -> 5" in terminal.output
        assert [slot["id"] for slot in emulator.slots()] == [6, 5]
    finally:
        emulator.stop()
