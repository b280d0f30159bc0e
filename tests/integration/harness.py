"""Building blocks of the ROS 2 integration tests (imported by conftest.py and the tests).

Constants of the topic contract (docs/sim_node_interface.md), the network-namespace guard, the
so101_sim_node process wrapper, and an rclpy probe node spinning in a background thread.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from so101 import contract
from so101.paths import repo_root

REPO_ROOT = repo_root()
NODE_NAME = "so101_sim_node"

JOINT_NAMES = list(contract.JOINT_NAMES)
JOINT_LIMITS = dict(zip(contract.JOINT_NAMES, contract.JOINT_LIMITS, strict=True))
# MuJoCo joint limits are soft constraints: a joint driven onto its limit may sit a hair beyond it.
LIMIT_TOLERANCE = 0.02  # rad

# Topics and services of the node, relative to its namespace, with their ROS type names.
PUBLISHED_TOPICS = {
    "joint_states": "sensor_msgs/msg/JointState",
    "clock": "rosgraph_msgs/msg/Clock",
    "task/reward": "std_msgs/msg/Float64",
    "task/success": "std_msgs/msg/Bool",
    "cube/pose": "geometry_msgs/msg/PoseStamped",
    "diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
}
SUBSCRIBED_TOPICS = {
    "joint_commands": "sensor_msgs/msg/JointState",
    "forward_position_controller/commands": "std_msgs/msg/Float64MultiArray",
}
SERVICES = {
    "sim/reset": "std_srvs/srv/Trigger",
    "sim/step": "std_srvs/srv/Trigger",
}
DIAGNOSTICS_STATUS_NAME = "so101_sim_node"


# =========================================================================== namespace guard
from so101.stack.isolation import network_namespace_problem  # noqa: E402,F401 - re-exported for conftest


# =========================================================================== the node process
def node_binary(name: str = NODE_NAME) -> Path:
    """Path of a built binary (default so101_sim_node) from $SO101_BIN_DIR; fails the test (never
    skips) when missing."""
    bin_dir = os.environ.get("SO101_BIN_DIR")
    default = "${CARGO_TARGET_DIR:-$HOME/.cache/so101/target}/release"
    if not bin_dir:
        pytest.fail(
            f"SO101_BIN_DIR is not set: it must name the directory holding the built {name} "
            f"(cargo build --release puts it in {default}).",
            pytrace=False,
        )
    binary = Path(bin_dir) / name
    if not binary.is_file():
        pytest.fail(f"{name} binary not found at {binary} (SO101_BIN_DIR={bin_dir}); build it first.", pytrace=False)
    if not os.access(binary, os.X_OK):
        pytest.fail(f"{binary} is not executable.", pytrace=False)
    return binary


def node_environment() -> dict[str, str]:
    """The test's environment minus what the venv's ROS-wheel bootstrapper added for Python.

    ros-wheels-bootstrapper re-executes the venv's Python with LD_LIBRARY_PATH pointing into the
    venv (ROS and Fast DDS libraries); the Rust node must not load libraries from there.
    """
    env = dict(os.environ)
    prefix = os.path.realpath(sys.prefix) + os.sep
    kept = [
        p for p in env.get("LD_LIBRARY_PATH", "").split(os.pathsep) if p and not (os.path.realpath(p) + os.sep).startswith(prefix)
    ]
    if kept:
        env["LD_LIBRARY_PATH"] = os.pathsep.join(kept)
    else:
        env.pop("LD_LIBRARY_PATH", None)
    env.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)
    env.setdefault("RUST_BACKTRACE", "1")
    return env


class SimNode:
    """One running so101_sim_node; stdout+stderr go to a log file shown when a test fails."""

    # Every node started, in order: conftest stops those a test left running (see its fixture).
    started: list[SimNode] = []

    def __init__(self, binary: Path, args: list[str], log_path: Path):
        self.args = list(args)
        self.command = [str(binary), *self.args]
        self.log_path = log_path
        self.namespace = ""
        if "--namespace" in self.args:
            self.namespace = "/" + self.args[self.args.index("--namespace") + 1].strip("/")
        self._log = open(log_path, "wb")
        self.proc = subprocess.Popen(
            self.command,
            cwd=REPO_ROOT,
            env=node_environment(),
            stdin=subprocess.DEVNULL,
            stdout=self._log,
            stderr=subprocess.STDOUT,
        )
        self.started_at = time.monotonic()
        SimNode.started.append(self)
        self._stopped = False
        self._stop_result: int | None = None

    def name(self, relative: str) -> str:
        """Absolute name of a topic/service of this node (with its --namespace)."""
        return f"{self.namespace}/{relative.lstrip('/')}"

    def log(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")
        except OSError as error:
            return f"<cannot read {self.log_path}: {error}>"

    def log_tail(self, chars: int = 6000) -> str:
        text = self.log() or "<no output>"
        return text if len(text) <= chars else "...\n" + text[-chars:]

    def describe(self) -> str:
        return f"`{shlex.join(self.command)}`"

    def alive(self) -> bool:
        return self.proc.poll() is None

    def assert_alive(self) -> None:
        code = self.proc.poll()
        if code is not None:
            pytest.fail(
                f"{self.describe()} exited with {describe_returncode(code)}; its output:\n{self.log_tail()}", pytrace=False
            )

    def stop(self, timeout: float = 10.0) -> int | None:
        """SIGINT, then wait; SIGKILL after `timeout`. Returns the return code, or None when it had
        to be killed. Idempotent."""
        if not self._stopped:
            self._stopped = True
            if self.proc.poll() is None:
                self.proc.send_signal(signal.SIGINT)
                try:
                    self.proc.wait(timeout=timeout)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait()
                    self._log.close()
                    return None
            self._stop_result = self.proc.returncode
            self._log.close()
        return self._stop_result


def wait_for_launcher(launcher: subprocess.Popen, timeout: float) -> str:
    """Reads so101-launch's output (a text pipe) until it reports every node up; returns it."""
    output = ""
    deadline = time.monotonic() + timeout
    while "all nodes up" not in output:
        line = launcher.stdout.readline()
        assert line or launcher.poll() is None, f"the launcher exited early:\n{output}"
        output += line
        assert time.monotonic() < deadline, f"not up within {timeout:.0f} s:\n{output}"
    return output


def stop_nodes(nodes: list[SimNode]) -> list[str]:
    """SIGINT to every node still running; what went wrong, for the fixture to report. A node must
    exit 0, unless its test set `node.exit_expected = True` (it was killed or meant to fail)."""
    problems = []
    for node in nodes:
        was_running = node.alive()
        code = node.stop()
        if code != 0 and not getattr(node, "exit_expected", False):
            how = "after SIGINT" if was_running else "by itself during the test (crash or early exit)"
            problems.append(f"{node.describe()} ended {how} with {describe_returncode(code)}; its output:\n{node.log_tail()}")
    return problems


def describe_returncode(code: int | None) -> str:
    if code is None:
        return "no exit (killed after not stopping on SIGINT)"
    if code < 0:
        try:
            return f"signal {signal.Signals(-code).name}"
        except ValueError:
            return f"signal {-code}"
    return f"return code {code}"


# =========================================================================== rclpy probe
class Inbox:
    """Messages of one subscription, with their local arrival times (time.monotonic)."""

    def __init__(self, topic: str, rediscover: Callable[[str], None] | None = None):
        self.topic = topic
        self._cond = threading.Condition()
        self._items: list[tuple[float, Any]] = []
        self._rediscover = rediscover  # the probe's remedy for a participant blind to the topic

    def _push(self, msg: Any) -> None:
        now = time.monotonic()
        with self._cond:
            self._items.append((now, msg))
            self._cond.notify_all()

    def items(self) -> list[tuple[float, Any]]:
        with self._cond:
            return list(self._items)

    def messages(self) -> list[Any]:
        return [m for _, m in self.items()]

    def count(self) -> int:
        with self._cond:
            return len(self._items)

    def latest(self) -> Any | None:
        with self._cond:
            return self._items[-1][1] if self._items else None

    def clear(self) -> None:
        with self._cond:
            self._items.clear()

    def wait_for(
        self, predicate: Callable[[list[Any]], bool], timeout: float, what: str, sim: SimNode | None = None
    ) -> list[Any]:
        """Wait until predicate(messages) holds; fails the test with `what` on timeout (or node death)."""
        from so101.stack.discovery import REDISCOVER_AFTER_S

        deadline = time.monotonic() + timeout
        next_look = time.monotonic() + REDISCOVER_AFTER_S
        while True:
            with self._cond:
                msgs = [m for _, m in self._items]
                if predicate(msgs):
                    return msgs
                if sim is not None and not sim.alive():
                    break
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    break
                self._cond.wait(min(remaining, 0.1))
            if not msgs and self._rediscover is not None and time.monotonic() > next_look:
                self._rediscover(self.topic)  # outside the lock: the spinning thread pushes under it
                next_look = time.monotonic() + REDISCOVER_AFTER_S
        if sim is not None:
            sim.assert_alive()
        pytest.fail(f"timeout after {timeout:.1f} s on {self.topic}: {what} (received {len(msgs)} messages)", pytrace=False)

    def wait_count(self, n: int, timeout: float, sim: SimNode | None = None) -> list[Any]:
        return self.wait_for(lambda msgs: len(msgs) >= n, timeout, f"waiting for {n} messages", sim)

    def next_message(self, timeout: float, sim: SimNode | None = None) -> Any:
        start = self.count()
        return self.wait_for(lambda msgs: len(msgs) > start, timeout, "waiting for a new message", sim)[-1]


def reliable_qos(depth: int = 10):
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        depth=depth, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE
    )


def best_effort_qos(depth: int = 100):
    """Matches a writer of any reliability (used where the contract does not fix the QoS)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        depth=depth,
        history=HistoryPolicy.KEEP_LAST,
        reliability=ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.VOLATILE,
    )


def blind_domain() -> str:
    """A ROS domain no node of the tests runs in (the worker's domain + 40; the workers' domains
    start at 20): a participant opened there is blind to every node, as Fast DDS's discovery fault
    leaves one (so101.stack.discovery)."""
    return str(int(os.environ.get("ROS_DOMAIN_ID", "0")) + 40)


def fresh_participant_sees_publishers(topic: str, within: float = 2.0) -> bool:
    """Whether a participant created now discovers a publisher of `topic` within `within` s."""
    import rclpy

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node("so101_test_witness", context=context, start_parameter_services=False)
        try:
            deadline = time.monotonic() + within
            while node.count_publishers(topic) == 0:
                if time.monotonic() > deadline:
                    return False
                time.sleep(0.05)
            return True
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


class Probe:
    """An rclpy node, in its own context (DDS participant), spinning in a background thread, with
    helpers for the tests.

    Fast DDS can miss a starting node's publications for good (so101.stack.discovery): a subscription
    that has received nothing, while a fresh participant (a "witness") sees the topic's publishers
    and this one sees none, makes the probe start over on a fresh participant with the same
    subscriptions (the Inboxes keep what they had). Handles a test took from `node` directly
    belong to the old participant then: only a probe that was blind ever starts over."""

    def __init__(self, name: str):
        self.name = name
        self._subscriptions: dict[Inbox, tuple[str, Any, Any, Any]] = {}  # inbox -> (topic, type, qos, handle)
        self.rediscoveries = 0
        self._open()

    def _open(self) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(self.name, context=self.context, start_parameter_services=False)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, name=f"spin-{self.name}", daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        executor, context, stop = self.executor, self.context, self._stop
        while not stop.is_set() and context.ok():
            try:
                executor.spin_once(timeout_sec=0.05)
            except Exception:  # noqa: BLE001 - context shutting down
                if stop.is_set() or not context.ok():
                    return
                raise

    def close(self) -> None:
        import rclpy

        self._stop.set()
        self._thread.join(timeout=5)
        self.executor.shutdown(timeout_sec=2)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)

    def _rediscover(self, topic: str) -> None:
        if self.node.count_publishers(topic) > 0 or not fresh_participant_sees_publishers(topic):
            return  # not blind: the publisher is absent, or sends nothing this subscription takes
        self.close()
        self._open()
        self.rediscoveries += 1
        for inbox, (name, msg_type, qos, _old) in list(self._subscriptions.items()):
            self._subscriptions[inbox] = (name, msg_type, qos, self.node.create_subscription(msg_type, name, inbox._push, qos))

    # ---- topics
    def subscribe(self, topic: str, msg_type, qos=None) -> Inbox:
        inbox = Inbox(topic, self._rediscover)
        qos = qos if qos is not None else reliable_qos()
        self._subscriptions[inbox] = (topic, msg_type, qos, self.node.create_subscription(msg_type, topic, inbox._push, qos))
        return inbox

    def one_message(self, topic: str, msg_type, timeout: float, sim: SimNode | None = None, qos=None) -> Any:
        """The next message on `topic`, from a subscription that ends with it (no callbacks after)."""
        inbox = self.subscribe(topic, msg_type, qos if qos is not None else best_effort_qos())
        try:
            return inbox.next_message(timeout, sim)
        finally:
            self.node.destroy_subscription(self._subscriptions.pop(inbox)[3])

    def publisher(self, topic: str, msg_type, qos=None, wait_for_subscriber: float | None = 10.0, sim: SimNode | None = None):
        pub = self.node.create_publisher(msg_type, topic, qos if qos is not None else reliable_qos())
        if wait_for_subscriber:
            self.wait_for_graph(lambda: pub.get_subscription_count() >= 1, wait_for_subscriber, f"a subscriber of {topic}", sim)
        return pub

    # ---- services
    def call(self, srv_type, name: str, request=None, timeout: float = 10.0, sim: SimNode | None = None):
        client = self.node.create_client(srv_type, name)
        try:
            self.wait_for_graph(client.service_is_ready, timeout, f"service {name}", sim)
            future = client.call_async(request if request is not None else srv_type.Request())
            wait_until(future.done, timeout, f"the response of {name}", sim)
            if future.exception() is not None:
                raise future.exception()
            return future.result()
        finally:
            self.node.destroy_client(client)

    # ---- graph
    def topics(self) -> dict[str, list[str]]:
        return dict(self.node.get_topic_names_and_types())

    def services(self) -> dict[str, list[str]]:
        return dict(self.node.get_service_names_and_types())

    def graph_report(self) -> str:
        """What this probe's DDS participant has discovered: on a discovery timeout it tells a
        participant never seen (no node) from endpoints never matched (node, no topic)."""
        nodes = sorted(f"{ns.rstrip('/')}/{name}" for name, ns in self.node.get_node_names_and_namespaces())
        topics = {
            topic: (self.node.count_publishers(topic), self.node.count_subscribers(topic)) for topic in sorted(self.topics())
        }
        services = sorted(self.services())
        return f"the probe sees nodes {nodes}, topics (publishers, subscribers) {topics}, services {services}"

    def wait_for_graph(self, predicate: Callable[[], bool], timeout: float, what: str, node=None) -> None:
        """wait_until for a discovery condition, reporting the probe's view of the graph on timeout."""
        wait_until(predicate, timeout, what, node, explain=self.graph_report)

    def wait_for_publisher(self, topic: str, timeout: float, what: str, node=None) -> None:
        """wait_for_graph for a publisher of `topic`, starting over on a fresh participant if this
        one is blind to it (see the class)."""
        from so101.stack.discovery import REDISCOVER_AFTER_S

        next_look = time.monotonic() + REDISCOVER_AFTER_S

        def found() -> bool:
            nonlocal next_look
            if self.node.count_publishers(topic) >= 1:
                return True
            if time.monotonic() > next_look:
                self._rediscover(topic)
                next_look = time.monotonic() + REDISCOVER_AFTER_S
            return False

        self.wait_for_graph(found, timeout, what, node)


def wait_until(
    predicate: Callable[[], bool],
    timeout: float,
    what: str,
    sim: SimNode | None = None,
    period: float = 0.02,
    explain: Callable[[], str] | None = None,
) -> None:
    """Poll predicate; fail the test naming `what` (and `explain()`) on timeout, or at once if the
    node died."""
    deadline = time.monotonic() + timeout
    while True:
        if predicate():
            return
        if sim is not None:
            sim.assert_alive()
        if time.monotonic() >= deadline:
            detail = f": {explain()}" if explain is not None else ""
            if sim is not None:
                detail += f"\n{sim.describe()} log:\n{sim.log_tail()}"
            pytest.fail(f"timeout after {timeout:.1f} s waiting for {what}{detail}", pytrace=False)
        time.sleep(period)


# =========================================================================== message helpers
def stamp_seconds(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def stamp_nanoseconds(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def positions_by_name(msg) -> dict[str, float]:
    return dict(zip(msg.name, msg.position))


def limit_violations(msg, tolerance: float = LIMIT_TOLERANCE) -> list[str]:
    """Joints of a JointState that are non-finite or outside their limits (+ tolerance)."""
    problems = []
    for name, value in zip(msg.name, msg.position):
        low, high = JOINT_LIMITS.get(name, (-math.inf, math.inf))
        if not math.isfinite(value) or value < low - tolerance or value > high + tolerance:
            problems.append(f"{name}={value!r} (limits {low}..{high})")
    return problems


def max_error(msg, target: dict[str, float]) -> float:
    actual = positions_by_name(msg)
    return max(abs(actual[name] - value) for name, value in target.items())


@dataclass
class Running:
    """A started node and the inbox of its joint_states (see start_and_wait)."""

    sim: SimNode
    joint_states: Inbox

    def current_positions(self, timeout: float = 5.0) -> dict[str, float]:
        return positions_by_name(self.joint_states.next_message(timeout, self.sim))


def start_and_wait(sim_factory, ros: Probe, *args: str, timeout: float = 30.0) -> Running:
    """Start a node with `args`, subscribe its joint_states and wait for the first message."""
    from sensor_msgs.msg import JointState

    sim = sim_factory(*args)
    # Reliable like the node's writer; a deep reader cache so a briefly busy test process loses nothing.
    inbox = ros.subscribe(sim.name("joint_states"), JointState, reliable_qos(depth=100))
    inbox.wait_count(1, timeout, sim)
    return Running(sim=sim, joint_states=inbox)


def offset_pose(start: dict[str, float], delta: float, margin: float = 0.15) -> dict[str, float]:
    """`start` moved by `delta` rad on every joint, towards the middle of each joint's range (away
    from the nearer limit, so a rest pose folded onto a limit unfolds), kept `margin` inside."""
    target = {}
    for name in JOINT_NAMES:
        low, high = JOINT_LIMITS[name]
        value = start[name]
        step = delta if value <= 0.5 * (low + high) else -delta
        target[name] = min(max(value + step, low + margin), high - margin)
    return target


def wait_reached(running: Running, target: dict[str, float], tolerance: float = 0.05, timeout: float = 6.0, settled: int = 20):
    """Wait until `settled` consecutive joint_states are all within `tolerance` of `target` (rad)."""
    seen: list = []

    def predicate(msgs: list) -> bool:
        seen[:] = msgs[-1:]
        tail = msgs[-settled:]
        return len(tail) == settled and all(max_error(m, target) <= tolerance for m in tail)

    start = running.joint_states.count()
    try:
        return running.joint_states.wait_for(
            lambda msgs: predicate(msgs[start:]), timeout, f"the arm to settle within {tolerance} rad of {target}", running.sim
        )
    except pytest.fail.Exception as failure:
        last = positions_by_name(seen[0]) if seen else None
        raise pytest.fail.Exception(f"{failure}; last joint_states positions: {last}", pytrace=False) from None


def diagnostics_values(array_msg, status_name: str = DIAGNOSTICS_STATUS_NAME) -> dict[str, str] | None:
    """key -> value of the named status in a DiagnosticArray, or None when it is not there."""
    for status in array_msg.status:
        if status.name == status_name:
            return {kv.key: kv.value for kv in status.values}
    return None


def latest_diagnostics_values(array_msgs) -> dict[str, str] | None:
    """key -> value of the node's status in the newest DiagnosticArray that has it, or None."""
    for msg in reversed(array_msgs):
        values = diagnostics_values(msg)
        if values is not None:
            return values
    return None


# =========================================================================== an independent FK
SCENE = REPO_ROOT / "assets" / "so101_cube_to_bin.xml"
ARM_BODIES = ["base", "shoulder", "upper_arm", "lower_arm", "wrist", "gripper", "moving_jaw"]


def _quaternion_matrix(w: float, x: float, y: float, z: float):
    import numpy as np

    n = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def scene_body_poses(joints: dict[str, float]) -> dict[str, tuple]:
    """World pose (rotation 3x3, position) of each arm body of the scene file for the given joint
    positions, walking the MJCF body tree (each body: pos, quat, then its hinge about local z),
    independently of the Rust kinematic model. Also "gripper_tip": the grasp point site."""
    import xml.etree.ElementTree as ElementTree

    import numpy as np

    root = ElementTree.parse(SCENE).getroot()
    body = root.find("./worldbody")
    rotation, position = np.eye(3), np.zeros(3)
    poses = {}
    for name in ARM_BODIES:
        body = next(b for b in body.iter("body") if b.get("name") == name)
        offset = np.array([float(v) for v in body.get("pos", "0 0 0").split()])
        quat = [float(v) for v in body.get("quat", "1 0 0 0").split()]
        position = position + rotation @ offset
        rotation = rotation @ _quaternion_matrix(*quat)
        joint = body.find("joint")
        if joint is not None:
            angle = joints[joint.get("name")]
            c, s = math.cos(angle), math.sin(angle)
            rotation = rotation @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        poses[name] = (rotation, position)
        if name == "gripper":
            site = next(s for s in body.iter("site") if s.get("name") == "gripper_tip")
            poses["gripper_tip"] = (rotation, position + rotation @ np.array([float(v) for v in site.get("pos").split()]))
    return poses


def grasp_point(joints: dict[str, float]):
    """World position of the scene's gripper_tip site (the grasp point)."""
    return scene_body_poses(joints)["gripper_tip"][1]


# lerobot-train's ACT shrunk to a few thousand transformer weights, CPU, no pretrained backbone
# (nothing downloaded), nothing pushed: what the tests that train a policy share.
TINY_ACT = [
    "--policy.type=act",
    "--policy.device=cpu",
    "--policy.push_to_hub=false",
    "--policy.pretrained_backbone_weights=null",
    "--policy.dim_model=32",
    "--policy.n_heads=2",
    "--policy.dim_feedforward=64",
    "--policy.n_encoder_layers=1",
    "--policy.n_decoder_layers=1",
]


def rrd_entities(path) -> dict[str, int]:
    """Entity path -> number of rows, read with the rerun SDK."""
    from rerun.experimental import RrdReader

    rows: dict[str, int] = {}
    for chunk in RrdReader(str(path)).stream().to_chunks():
        rows[str(chunk.entity_path)] = rows.get(str(chunk.entity_path), 0) + chunk.num_rows
    return rows


# =========================================================================== LeRobot's CLIs
def offline_env(home: Path) -> dict[str, str]:
    """This environment with the Hugging Face caches under `home` and no Hub, no Weights & Biases."""
    return {
        **os.environ,
        "HF_HUB_OFFLINE": "1",
        "WANDB_MODE": "disabled",
        "HF_HOME": str(home / "hf"),
        "HF_LEROBOT_HOME": str(home / "lerobot"),
    }


def run_offline(argv: list, timeout: float, home: Path) -> subprocess.CompletedProcess:
    """A LeRobot or so101 command in offline_env(home), its output captured."""
    return run_or_dump_stacks(argv, timeout, offline_env(home))


def so101_learn(*argv: str, timeout: float) -> subprocess.CompletedProcess:
    """`so101-learn ARGV...` offline (no Hub, no Weights & Biases); the test fails with its output
    when it does."""
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "WANDB_MODE": "disabled"}
    done = run_or_dump_stacks([Path(sys.executable).parent / "so101-learn", *argv], timeout, env)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return done


def lerobot_eval_two_small_cameras(checkpoint: Path, output: Path) -> dict:
    """LeRobot's own lerobot-eval of the policy in `checkpoint`, one 8-step episode on the env type
    so101_sim with the camera tests' top and wrist cameras at 32x24 and no cube pose, offline; the
    test fails with its output when it does. Its eval_info.json's "overall"."""
    command = [
        str(Path(sys.executable).parent / "lerobot-eval"),
        f"--policy.path={checkpoint}",
        "--policy.device=cpu",
        "--env.type=so101_sim",
        "--env.cameras={top: [24, 32], wrist: [24, 32]}",
        "--env.environment_state=false",
        "--env.episode_length=8",
        "--eval.n_episodes=1",
        "--eval.batch_size=1",
        "--eval.use_async_envs=false",
        f"--output_dir={output}",
    ]
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "WANDB_MODE": "disabled"}
    done = subprocess.run(command, capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, (done.stdout + done.stderr)[-4000:]
    return json.loads((output / "eval_info.json").read_text())["overall"]


def run_or_dump_stacks(argv: list, timeout: float, env: dict[str, str]) -> subprocess.CompletedProcess:
    """A command, its output captured. When it runs over `timeout`, every process of it gives its
    threads' native stacks (gdb, where installed) and every Python one its Python stacks
    (faulthandler, on SIGABRT), and the test fails with them: a hang on a CI machine says where it
    hung (a 2-process training once hung after "Creating dataset", once after its last step, in
    native code after train() returned)."""
    argv = [str(a) for a in argv]
    process = subprocess.Popen(
        argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env={**env, "PYTHONFAULTHANDLER": "1"}
    )
    try:
        stdout, stderr = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        native = "\n".join(native_stacks(pid) for pid in [process.pid, *descendants(process.pid)])
        for pid in [*reversed(descendants(process.pid)), process.pid]:  # the workers first
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGABRT)
                wait_until_ended(pid, 5.0)  # one dump at a time: they share the pipe
        try:
            stdout, stderr = process.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            for pid in [*descendants(process.pid), process.pid]:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)
            stdout, stderr = process.communicate()
        pytest.fail(
            f"{shlex.join(argv)[:300]} ran over {timeout} s; its processes' native stacks:\n{native[-15000:]}\n"
            f"their Python stacks:\n{stderr[-15000:]}\n{stdout[-3000:]}"
        )
    return subprocess.CompletedProcess(argv, process.returncode, stdout, stderr)


def wait_until_ended(pid: int, seconds: float) -> None:
    """Until `pid` has ended (gone, or a zombie), at most `seconds`."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except (OSError, IndexError):
            return
        if state in ("Z", "X"):
            return
        time.sleep(0.02)


def native_stacks(pid: int) -> str:
    """The native stacks of `pid`'s threads (gdb attached for a moment, its 12 innermost frames per
    thread), or why there are none."""
    try:
        command = (Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace"))[:200]
    except OSError:
        return f"process {pid}: gone"
    if shutil.which("gdb") is None:
        return f"process {pid} ({command}): no gdb for its native stacks"
    try:
        done = subprocess.run(
            ["gdb", "-p", str(pid), "-batch", "-nx", "-ex", "thread apply all bt 12"],
            capture_output=True,
            text=True,
            timeout=60,
        )
    except subprocess.TimeoutExpired:
        return f"process {pid} ({command}): gdb took over 60 s"
    frames = [line for line in done.stdout.splitlines() if line.startswith(("Thread ", "#"))]
    return f"process {pid} ({command}):\n" + "\n".join(frames)


def descendants(pid: int) -> list[int]:
    """The processes below `pid`, parents before their children (from /proc)."""
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        with contextlib.suppress(OSError, ValueError, IndexError):
            # "pid (comm) state ppid ...": comm may hold spaces, so split after its closing parenthesis.
            ppid = int(stat.read_text().rsplit(")", 1)[1].split()[1])
            children.setdefault(ppid, []).append(int(stat.parent.name))
    found, queue = [], [pid]
    while queue:
        for child in children.get(queue.pop(0), []):
            found.append(child)
            queue.append(child)
    return found
