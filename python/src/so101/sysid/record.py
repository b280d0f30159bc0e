"""`so101-sysid record`: the arm (or the emulator standing in for it) driven one joint at a time
through the excitation, through the driver as every command goes (calibrated range, --max-step,
torque safety unchanged), each joint's run recorded as one episode bag with the task
"so101-sysid JOINT". The other joints hold where they were."""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from .. import contract
from ..paths import asset, isolated_wrapper, node_binary
from ..sim_options import DEFAULT_SERVO_MODEL, servo_params_argument
from ..stack.isolation import network_namespace_problem
from ..stack.launch import Launch
from ..stack.launch_plan import EMULATED_ARM_CALIBRATION, NodeSpec, emulator_spec, lerobot_calibration_file
from .excitation import Excitation, held_out

TASK_PREFIX = "so101-sysid "
HELD_OUT_SUFFIX = " held-out"
# Topics a sysid bag needs.
RECORDED = ["joint_states", "joint_commands", "episode/events", "diagnostics"]


def add_arguments(p) -> None:
    arm = p.add_argument_group("the arm")
    arm.add_argument("--port", help="the arm's servo bus, e.g. /dev/ttyACM0")
    arm.add_argument("--robot-id", help="the arm's LeRobot calibration id")
    arm.add_argument("--calibration", help="a LeRobot calibration file (instead of --robot-id)")
    arm.add_argument(
        "--emulate",
        action="store_true",
        help="so101_servo_emulator as the arm (no hardware), moving as --emulator-servo-params says",
    )
    arm.add_argument(
        "--emulator-servo-params",
        type=servo_params_argument,
        default=DEFAULT_SERVO_MODEL,
        help="with --emulate: the emulated servos' model, sts3215 or a parameter file (the ground truth of a test)",
    )
    arm.add_argument("--driver-args", default="", help="more so101_feetech_driver flags in one string")
    p.add_argument(
        "--joints",
        default=",".join(contract.JOINT_NAMES),
        help="joints to excite, comma-separated, one after the other (default: all six)",
    )
    p.add_argument("--amplitude", type=float, default=Excitation.amplitude, help="step size (rad), under the driver's --max-step")
    p.add_argument("--held-out", action="store_true", help="also record a different motion per joint, to check a fit on")
    p.add_argument("--bags", required=True, help="directory of the episode bags")
    p.add_argument("--log-dir", default=None, help="node logs (default: BAGS/logs)")
    p.add_argument("--ready-timeout", type=float, default=30.0)


def joints_of(text: str) -> list[str]:
    joints = [name.strip() for name in text.split(",") if name.strip()]
    unknown = [name for name in joints if name not in contract.JOINT_NAMES]
    if unknown or not joints:
        raise SystemExit(f"so101-sysid: --joints {text!r}: names among {', '.join(contract.JOINT_NAMES)}")
    return joints


def node_specs(args, log_dir: Path) -> list[NodeSpec]:
    """The emulator (with --emulate), the driver and the recorder."""
    specs = []
    port, calibration = args.port, args.calibration
    if args.emulate:
        port = port or str(log_dir / "servo_bus")
        if not calibration and not args.robot_id:
            calibration = str(asset(EMULATED_ARM_CALIBRATION))
        arm = Path(calibration) if calibration else lerobot_calibration_file(args.robot_id)
        emulator = emulator_spec("so101_servo_emulator", port, arm)
        emulator.argv += ["--servo-params", args.emulator_servo_params]
        specs.append(emulator)
    if not port:
        raise SystemExit("so101-sysid record: --port (or --emulate) names the arm")
    driver = [str(node_binary("so101_feetech_driver")), "--port", port]
    if args.robot_id:
        driver += ["--robot-id", args.robot_id]
    if calibration:
        driver += ["--calibration", calibration]
    driver += args.driver_args.split()
    specs.append(NodeSpec("so101_feetech_driver", driver, ready=f"publisher /{contract.JOINT_STATES}"))
    recorder = [str(node_binary("recorder_node")), "--output", args.bags, "--task", "so101-sysid"]
    for topic in RECORDED:
        recorder += ["--regex", topic]
    specs.append(NodeSpec("recorder_node", recorder, ready=f"subscriber /{contract.EPISODE_EVENTS}"))
    return specs


class Driver:
    """The commands' side: /joint_commands out, /joint_states in, /episode/events out."""

    def __init__(self, node):
        from sensor_msgs.msg import JointState
        from std_msgs.msg import String

        self._node = node
        self._JointState, self._String = JointState, String
        self.latest: np.ndarray | None = None
        self.states = 0  # /joint_states received
        self._commands = node.create_publisher(JointState, f"/{contract.JOINT_COMMANDS}", 10)
        self._events = node.create_publisher(String, f"/{contract.EPISODE_EVENTS}", 10)
        node.create_subscription(JointState, f"/{contract.JOINT_STATES}", self._on_state, 10)

    def _on_state(self, message) -> None:
        order = [list(message.name).index(name) for name in contract.JOINT_NAMES]
        self.latest = np.array([message.position[i] for i in order])
        self.states += 1

    def spin(self, seconds: float = 0.0) -> None:
        """Handles what arrived; for `seconds` at least (0: one wait of up to 1 ms)."""
        import rclpy

        deadline = time.monotonic() + seconds
        while True:
            rclpy.spin_once(self._node, timeout_sec=0.001)
            if time.monotonic() >= deadline:
                return

    def wait_for_state(self, timeout: float = 10.0) -> np.ndarray:
        deadline = time.monotonic() + timeout
        while self.latest is None:
            if time.monotonic() > deadline:
                raise SystemExit("so101-sysid record: no /joint_states from the driver")
            self.spin(0.05)
        return self.latest.copy()

    def event(self, text: str) -> None:
        self._events.publish(self._String(data=text))

    def command(self, targets: np.ndarray) -> None:
        self._commands.publish(self._JointState(name=list(contract.JOINT_NAMES), position=[float(v) for v in targets]))

    def play(self, rows: np.ndarray, hold: np.ndarray, joint: int) -> None:
        """Sends `hold` with joint `joint` at hold + offset, row by row at the rows' times.

        Each goal goes out right after a joint state arrives, i.e. just after one of the driver's
        cycles ended and long before the next begins: the driver takes it at its next cycle,
        whose stamp `fit` then gives it. (A goal sent at any moment would land in one cycle or the
        next by chance, a cycle of jitter on every goal's time.)"""
        start = time.monotonic()
        sent = -1
        deadline = start + rows[-1, 0] + 5.0
        while sent < len(rows) - 1:
            seen = self.states
            while self.states == seen:
                if time.monotonic() > deadline:
                    raise SystemExit("so101-sysid record: the driver stopped publishing /joint_states")
                self.spin()
            due = int(np.searchsorted(rows[:, 0], time.monotonic() - start, side="right")) - 1
            if due > sent:
                sent = due
                targets = hold.copy()
                targets[joint] = hold[joint] + rows[due, 1]
                self.command(targets)


def within_limits(hold: np.ndarray, joint: int, amplitude: float) -> np.ndarray:
    """The start position moved inside the joint's limits by the amplitude (the steps stay in)."""
    low, high = contract.JOINT_LIMITS[joint]
    moved = hold.copy()
    moved[joint] = float(np.clip(hold[joint], low + amplitude, high - amplitude))
    return moved


def run(args) -> int:
    joints = joints_of(args.joints)
    if network_namespace_problem():
        # Inside a private network namespace, as every DDS process of the project runs.
        isolated = str(isolated_wrapper())
        os.execv(isolated, [isolated, sys.executable, "-m", "so101.sysid.cli", *sys.argv[1:]])
    bags = Path(args.bags)
    bags.mkdir(parents=True, exist_ok=True)
    log_dir = Path(args.log_dir or bags / "logs")
    log_dir.mkdir(parents=True, exist_ok=True)
    excitation = Excitation(amplitude=args.amplitude)
    settle = np.column_stack([np.arange(100) / excitation.rate, np.zeros(100)])  # 1 s at the base pose
    launch = Launch(log_dir, args.ready_timeout, 10.0, "")
    try:
        for spec in node_specs(args, log_dir):
            launch.start(spec)
        driver = Driver(launch.graph_node())
        start = driver.wait_for_state()
        print(f"so101-sysid: the arm is at {np.round(start, 3).tolist()} rad", flush=True)
        for joint_name in joints:
            joint = contract.JOINT_NAMES.index(joint_name)
            base = within_limits(start, joint, args.amplitude)
            runs = [("", excitation.offsets())]
            if args.held_out:
                runs.append((HELD_OUT_SUFFIX, held_out(amplitude=0.8 * args.amplitude, seed=joint)))
            for suffix, rows in runs:
                driver.play(settle, base, joint)
                task = TASK_PREFIX + joint_name + suffix
                driver.event("start " + json.dumps({"task": task}))
                driver.play(rows, base, joint)
                driver.event("stop")
                driver.spin(0.3)
                print(f"so101-sysid: recorded {task} ({rows[-1, 0]:.1f} s)", flush=True)
        return 0
    finally:
        launch.stop_all()
