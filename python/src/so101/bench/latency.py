#!/usr/bin/env python3
"""Latency benchmarks of the ROS 2 graph, printed as one JSON line on stdout.

Modes
  (default) node reaction latency: publish a sensor_msgs/JointState command on /joint_commands
            (target alternating between two poses) and time until the next /joint_states
            message arrives, N samples. This is the reaction latency through the node
            (so101_sim_node or the driver): DDS hop in + wait for the node's next control tick
            + DDS hop out. At --rate 100 its p50 is dominated by the tick (~period/2).
  --pingpong baseline: two rclpy processes (this one and an echo child it starts) bounce a
            6-joint JointState between /bench/ping and /bench/pong; reports the round trip.

Run it with the venv's python, inside the project's network namespace (the caller wraps it):
    scripts/isolated .venv/bin/python -m so101.bench.latency --pingpong
    scripts/isolated bash -c '$SO101_BIN_DIR/so101_sim_node --lite & sleep 2;
                              .venv/bin/python -m so101.bench.latency; kill -INT %1; wait'
or let it start the node itself (same namespace, it is its child):
    scripts/isolated .venv/bin/python -m so101.bench.latency --spawn-node -- --rate 100
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import signal
import subprocess
import sys
import time

from so101 import contract
from so101.contract import JOINT_NAMES
from so101.paths import node_binary, node_environment, repo_root
from so101.stack.isolation import network_namespace_problem
from so101.stack.process import start
from so101.stack.process import stop as stop_process
from so101.subcommands import Subcommand, run_alone


def set_default_environment() -> None:
    os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    os.environ.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", str(repo_root() / "python" / "fastdds_profile.xml"))


# --------------------------------------------------------------------------- statistics


def percentile(sorted_values: list[float], q: float) -> float:
    """Linear-interpolated percentile (q in 0..100) of an already sorted list."""
    if not sorted_values:
        return math.nan
    pos = (len(sorted_values) - 1) * q / 100.0
    lo = math.floor(pos)
    hi = min(lo + 1, len(sorted_values) - 1)
    return sorted_values[lo] + (sorted_values[hi] - sorted_values[lo]) * (pos - lo)


def summary(latencies_s: list[float]) -> dict:
    values = sorted(x * 1e6 for x in latencies_s)
    if not values:
        return {"p50_us": None, "p90_us": None, "p99_us": None, "mean_us": None, "min_us": None, "max_us": None}
    return {
        "p50_us": round(percentile(values, 50), 1),
        "p90_us": round(percentile(values, 90), 1),
        "p99_us": round(percentile(values, 99), 1),
        "mean_us": round(sum(values) / len(values), 1),
        "min_us": round(values[0], 1),
        "max_us": round(values[-1], 1),
    }


# --------------------------------------------------------------------------- helpers
def spin_until(executor, predicate, timeout_s: float) -> bool:
    deadline = time.perf_counter() + timeout_s
    while not predicate():
        remaining = deadline - time.perf_counter()
        if remaining <= 0:
            return False
        executor.spin_once(timeout_sec=min(remaining, 0.05))
    return True


def drain(executor, max_callbacks: int = 100) -> None:
    """Run the callbacks of everything that has already arrived (without waiting)."""
    for _ in range(max_callbacks):
        executor.spin_once(timeout_sec=0.0)


def make_joint_state(positions: list[float], seq: int = 0):
    from sensor_msgs.msg import JointState

    msg = JointState()
    msg.header.frame_id = str(seq)
    msg.name = list(JOINT_NAMES)
    msg.position = [float(p) for p in positions]
    return msg


# --------------------------------------------------------------------------- ping-pong
def run_echo(args) -> int:
    """Child of --pingpong: republish every /bench/ping on /bench/pong."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import JointState

    rclpy.init()
    node = rclpy.create_node("bench_echo")
    pub = node.create_publisher(JointState, "/bench/pong", 10)
    node.create_subscription(JointState, "/bench/ping", pub.publish, 10)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    try:
        while not stop:
            executor.spin_once(timeout_sec=0.1)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def run_pingpong(args) -> dict:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import JointState

    child = start([sys.executable, "-m", "so101.bench.latency", "--role", "echo"], stdin=None)
    rclpy.init()
    node = rclpy.create_node("bench_pingpong")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    received: dict[str, float] = {}

    def on_pong(msg: JointState) -> None:
        received[msg.header.frame_id] = time.perf_counter()

    pub = node.create_publisher(JointState, "/bench/ping", 10)
    node.create_subscription(JointState, "/bench/pong", on_pong, 10)
    latencies: list[float] = []
    lost = 0
    try:
        # Discovery: both directions matched, then one full round trip.
        if not spin_until(
            executor,
            lambda: pub.get_subscription_count() >= 1 and node.count_publishers("/bench/pong") >= 1,
            args.discovery_timeout,
        ):
            raise RuntimeError("echo process not discovered (is this inside scripts/isolated?)")
        seq = 0
        ok = False
        deadline = time.perf_counter() + args.discovery_timeout
        while time.perf_counter() < deadline and not ok:
            seq += 1
            pub.publish(make_joint_state([0.0] * 6, -seq))
            ok = spin_until(executor, lambda: str(-seq) in received, 0.2)
        if not ok:
            raise RuntimeError("no echo came back")

        rng = random.Random(0)
        total = args.warmup + args.samples
        for i in range(total):
            key = str(i)
            positions = [rng.uniform(-1.0, 1.0) for _ in JOINT_NAMES]
            t0 = time.perf_counter()
            pub.publish(make_joint_state(positions, i))
            if spin_until(executor, lambda: key in received, args.timeout):
                if i >= args.warmup:
                    latencies.append(received[key] - t0)
            elif i >= args.warmup:
                lost += 1
            received.pop(key, None)
            if args.interval > 0:
                time.sleep(args.interval)
    finally:
        stop_process(child)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return {
        "bench": "pingpong_rclpy_rclpy",
        "what": "round trip JointState(6) rclpy -> rclpy echo -> rclpy, two processes",
        "samples": len(latencies),
        "lost": lost,
        **summary(latencies),
    }


# --------------------------------------------------------------------------- node reaction
def spawn_node(node_args: list[str], full_scene: bool = False) -> subprocess.Popen:
    try:
        binary = node_binary("so101_sim_node")
    except FileNotFoundError as error:
        raise SystemExit(f"bench latency: {error}") from error
    args = list(node_args)
    if not full_scene and "--lite" not in args:
        args.insert(0, "--lite")
    if "--cameras" not in args:
        args[:0] = ["--cameras", "none"]
    return start([binary, *args], env=node_environment(), stdin=None)


def run_node(args) -> dict:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import JointState

    ns = "/" + args.namespace.strip("/") if args.namespace.strip("/") else ""
    node_proc = spawn_node(args.node_args, args.full_scene) if args.spawn_node else None
    rclpy.init()
    node = rclpy.create_node("bench_node_latency")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    arrivals: list[float] = []
    node.create_subscription(JointState, f"{ns}/{contract.JOINT_STATES}", lambda _msg: arrivals.append(time.perf_counter()), 10)
    pub = node.create_publisher(JointState, f"{ns}/{contract.JOINT_COMMANDS}", 10)
    latencies: list[float] = []
    lost = 0
    try:
        if not spin_until(
            executor,
            lambda: pub.get_subscription_count() >= 1 and len(arrivals) >= 5,
            args.discovery_timeout,
        ):
            raise RuntimeError(
                f"no node on {ns}/joint_commands + {ns}/joint_states (start it in the same namespace, or pass --spawn-node)"
            )
        # Observed publish rate, to put the numbers in context.
        arrivals.clear()
        spin_until(executor, lambda: False, 1.0)
        rate_hz = (len(arrivals) - 1) / (arrivals[-1] - arrivals[0]) if len(arrivals) >= 2 else math.nan

        # Two nearby poses inside every joint limit; the command alternates between them so every
        # sample changes the target.
        poses = [[0.0, 0.0, 0.0, 0.0, 0.0, 0.2], [0.05, -0.05, 0.05, -0.05, 0.05, 0.25]]
        rng = random.Random(0)
        total = args.warmup + args.samples
        for i in range(total):
            # Random phase relative to the node's tick, so the samples cover the whole period.
            time.sleep(rng.uniform(0.0, args.jitter))
            drain(executor)  # what arrived before the command is not the reaction
            before = len(arrivals)
            t0 = time.perf_counter()
            pub.publish(make_joint_state(poses[i % 2], i))
            if spin_until(executor, lambda: len(arrivals) > before, args.timeout):
                if i >= args.warmup:
                    latencies.append(arrivals[before] - t0)
            elif i >= args.warmup:
                lost += 1
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
        if node_proc is not None:
            stop_process(node_proc)
    return {
        "bench": "node_reaction",
        "what": "publish /joint_commands -> next /joint_states received",
        "joint_states_rate_hz": round(rate_hz, 2),
        "samples": len(latencies),
        "lost": lost,
        **summary(latencies),
    }


# --------------------------------------------------------------------------- main
def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--pingpong", action="store_true", help="rclpy <-> rclpy round-trip baseline")
    parser.add_argument("--samples", "-n", type=int, default=1000, help="measured samples (default 1000)")
    parser.add_argument("--warmup", type=int, default=50, help="samples dropped first (default 50)")
    parser.add_argument("--timeout", type=float, default=1.0, help="per-sample timeout in s (lost after)")
    parser.add_argument("--interval", type=float, default=0.0005, help="pingpong: pause between samples, s")
    parser.add_argument("--jitter", type=float, default=0.01, help="node: random pause before each sample, up to s")
    parser.add_argument("--discovery-timeout", type=float, default=15.0)
    parser.add_argument("--namespace", default="", help="node: topic namespace (as the node's --namespace)")
    parser.add_argument("--spawn-node", action="store_true", help="node: start $SO101_BIN_DIR/so101_sim_node")
    parser.add_argument("--full-scene", action="store_true", help="node: do not add --lite to the spawned node")
    parser.add_argument("--role", choices=["echo"], help=argparse.SUPPRESS)
    parser.add_argument("node_args", nargs="*", help="node: extra arguments of the spawned node, after '--' (--lite is added)")


def run(args: argparse.Namespace) -> int:
    problem = network_namespace_problem()
    if problem:
        print(
            f"bench_latency: refusing to open a DDS participant: {problem}.\n"
            "Run it inside the project's namespace: scripts/isolated .venv/bin/python -m so101.bench.latency ...",
            file=sys.stderr,
        )
        return 2
    set_default_environment()

    if args.role == "echo":
        return run_echo(args)
    if args.samples <= 0:
        print("so101-bench latency: --samples must be positive", file=sys.stderr)
        return 2
    result = run_pingpong(args) if args.pingpong else run_node(args)
    try:
        import rclpy.utilities

        result["rmw"] = rclpy.utilities.get_rmw_implementation_identifier()
    except Exception:  # noqa: BLE001 - informative only
        pass
    result["python"] = ".".join(str(part) for part in sys.version_info[:3])
    print(json.dumps(result), flush=True)
    return 0 if result["samples"] > 0 else 1


SUBCOMMAND = Subcommand(
    "ROS 2 graph latency: rclpy ping-pong and the sim node's reaction, one JSON line", add_arguments, run, __doc__
)


def main(argv: list[str] | None = None) -> int:
    return run_alone("so101-bench latency", SUBCOMMAND, argv)


if __name__ == "__main__":
    sys.exit(main())
