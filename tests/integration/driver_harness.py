"""Building blocks of the driver's integration tests: the servo-bus emulator process (driven through
its control commands on stdin), a LeRobot calibration file, and ticks <-> rad as the driver maps them.
"""

from __future__ import annotations

import json
import math
import subprocess
import threading
from pathlib import Path

import pytest
from harness import JOINT_NAMES, REPO_ROOT, node_binary

DRIVER_NAME = "so101_feetech_driver"
EMULATOR_NAME = "so101_servo_emulator"

# A LeRobot calibration of the emulated arm (ids 1..6). Offsets are non-zero so the tests see the
# servo-side Homing_Offset at work.
CALIBRATION = {
    "shoulder_pan": {"id": 1, "drive_mode": 0, "homing_offset": 100, "range_min": 1000, "range_max": 3000},
    "shoulder_lift": {"id": 2, "drive_mode": 0, "homing_offset": -200, "range_min": 900, "range_max": 3100},
    "elbow_flex": {"id": 3, "drive_mode": 0, "homing_offset": 0, "range_min": 1000, "range_max": 3000},
    "wrist_flex": {"id": 4, "drive_mode": 0, "homing_offset": 0, "range_min": 1000, "range_max": 3000},
    "wrist_roll": {"id": 5, "drive_mode": 0, "homing_offset": 0, "range_min": 0, "range_max": 4095},
    "gripper": {"id": 6, "drive_mode": 0, "homing_offset": 0, "range_min": 2000, "range_max": 3000},
}
GRIPPER_CLOSED_RAD = -0.1745  # the model's closed gripper limit, where range_min maps
RAD_PER_TICK = 2 * math.pi / 4095


def write_calibration(path: Path, calibration: dict = CALIBRATION) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(calibration, indent=4))
    return path


def rad_from_ticks(joint: str, ticks: float, calibration: dict = CALIBRATION) -> float:
    motor = calibration[joint]
    if joint == "gripper":
        return GRIPPER_CLOSED_RAD + (ticks - motor["range_min"]) * RAD_PER_TICK
    return (ticks - (motor["range_min"] + motor["range_max"]) / 2) * RAD_PER_TICK


def range_in_rad(joint: str, calibration: dict = CALIBRATION) -> tuple[float, float]:
    motor = calibration[joint]
    return rad_from_ticks(joint, motor["range_min"], calibration), rad_from_ticks(joint, motor["range_max"], calibration)


class ServoEmulator:
    """so101_servo_emulator as a process; `command()` sends one control line and returns its answer."""

    def __init__(self, link: Path, log_path: Path, *args: str):
        self.link = link
        self.log_path = log_path
        self._log = open(log_path, "wb")
        self.proc = subprocess.Popen(
            [str(node_binary(EMULATOR_NAME)), "--link", str(link), *args],
            cwd=REPO_ROOT,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self._log,
            text=True,
            bufsize=1,
        )
        self._lock = threading.Lock()
        first = self._readline(10.0)
        if not first.startswith("PTY "):
            pytest.fail(f"the emulator did not announce its pty: {first!r}; log:\n{self.log_tail()}", pytrace=False)

    def _readline(self, timeout: float) -> str:
        result: list[str] = []
        reader = threading.Thread(target=lambda: result.append(self.proc.stdout.readline()), daemon=True)
        reader.start()
        reader.join(timeout)
        if not result:
            pytest.fail(f"the emulator did not answer within {timeout} s; log:\n{self.log_tail()}", pytrace=False)
        return result[0].strip()

    def command(self, line: str) -> str:
        with self._lock:
            self.proc.stdin.write(line + "\n")
            self.proc.stdin.flush()
            answer = self._readline(10.0)
        if answer.startswith("error"):
            pytest.fail(f"emulator refused {line!r}: {answer}", pytrace=False)
        return answer

    def slots(self) -> list[dict]:
        return json.loads(self.command("dump"))["slots"]

    def goals(self) -> list[int]:
        return [slot["goal_position"] for slot in self.slots()]

    def log_tail(self, chars: int = 4000) -> str:
        try:
            text = self.log_path.read_text(errors="replace")
        except OSError as error:
            return f"<cannot read {self.log_path}: {error}>"
        return text[-chars:] or "<no output>"

    def stop(self) -> None:
        if self.proc.poll() is None:
            try:
                self.proc.stdin.write("quit\n")
                self.proc.stdin.flush()
                self.proc.wait(timeout=5)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait()
        self._log.close()


def joints_in_order(msg) -> list[float]:
    by_name = dict(zip(msg.name, msg.position))
    return [by_name[name] for name in JOINT_NAMES]
