"""Fixtures of the ROS 2 integration tests: the so101_sim_node process and an rclpy probe node.

These tests talk to a live DDS graph, so they must run inside a private network namespace with
only loopback (DDS discovery multicasts on every interface):

    scripts/setup_python.sh
    SO101_BIN_DIR=$HOME/.cache/so101/target/release \\
        scripts/isolated .venv/bin/python -m pytest tests/integration

(scripts/test.sh does exactly this.) The conftest refuses to run (pytest.exit) anywhere
else. Every pytest run gets its own namespace. scripts/test.sh runs the tests in pytest-xdist
workers (`-n 3` on two cores) that share that namespace, so each worker takes a DDS domain of its
own (below): the workers' graphs never meet. Each test starts its own node(s). A missing node binary FAILS the
tests (it never skips them).
"""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

from harness import (  # noqa: E402
    REPO_ROOT,
    Probe,
    SimNode,
    network_namespace_problem,
    node_binary,
    stop_nodes,
)

# The tests stop programs as a user at a terminal does, with Ctrl-C. A suite started in the background
# of a script (`scripts/test.sh &`, nohup) runs with SIGINT ignored, and every program it starts would
# inherit that (LeRobot's CLIs, which do not catch SIGINT themselves, would then not stop). Catching
# it here gives them the terminal's default again: exec resets a caught signal, not an ignored one.
signal.signal(signal.SIGINT, signal.default_int_handler)

# Fast DDS profile (large socket buffers) and RMW for every rclpy participant of the run; set before
# rclpy creates any context.
os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
os.environ.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", str(REPO_ROOT / "python" / "fastdds_profile.xml"))

# One DDS domain per pytest-xdist worker ("gw0", "gw1", ...), inherited by every node and rclpy
# process the worker starts: the workers share one network namespace and /dev/shm, and a domain
# of its own gives each worker its own discovery and data ports (UDP and Fast DDS shared memory).
# Domains from 20 up: test_plumbing uses 7 and listens on 0; harness.blind_domain() is the
# worker's + 40.
XDIST_DOMAIN_BASE = 20
_worker = os.environ.get("PYTEST_XDIST_WORKER", "")
if _worker.startswith("gw"):
    os.environ["ROS_DOMAIN_ID"] = str(XDIST_DOMAIN_BASE + int(_worker[2:]))


def pytest_configure(config: pytest.Config) -> None:
    # Noise from the ROS wheels' dependencies (lark-parser imports sre_parse).
    config.addinivalue_line("filterwarnings", "ignore:module 'sre_:DeprecationWarning")
    config.addinivalue_line(
        "markers",
        "alone: a peer that times each answer on its own clock in a busy-polling loop; scripts/test.sh "
        "runs these after the parallel phase, with no other test worker beside them",
    )


# =========================================================================== namespace guard
def _refuse_outside_namespace() -> None:
    problem = network_namespace_problem()
    if problem:
        pytest.exit(
            "REFUSING to run the ROS 2 integration tests: " + problem + ".\n"
            "They open DDS participants, whose discovery multicast must not leave this machine. Run them as\n"
            "    scripts/isolated .venv/bin/python -m pytest tests/integration\n"
            "(or scripts/test.sh).",
            returncode=3,
        )


@pytest.hookimpl(trylast=True)
def pytest_collection_finish(session: pytest.Session) -> None:
    """Refuse the whole run as soon as any test of this directory is selected (also --collect-only)."""
    if any(Path(str(item.path)).resolve().is_relative_to(HERE) for item in session.items):
        _refuse_outside_namespace()


# =========================================================================== the node process
def show_on_failure(request: pytest.FixtureRequest, nodes: list[SimNode]) -> None:
    """Registers a fixture's list of nodes: their output goes into the report of a failed test."""
    groups = getattr(request.node, "_so101_node_groups", None)
    if groups is None:
        groups = request.node._so101_node_groups = []
    groups.append(nodes)


@pytest.fixture(autouse=True)
def no_node_outlives_its_test():
    """Every node a test started is stopped when the test ends, whatever happened (after the
    factories' own teardown, which checks exit codes). One left running by a failed test kept
    publishing on the worker's DDS domain into the tests after it: one failure became four. Nodes
    of module- and session-scoped fixtures are started before this and left alone."""
    first = len(SimNode.started)
    yield
    for node in SimNode.started[first:]:
        node.stop()
    del SimNode.started[first:]


@pytest.fixture
def sim_factory(request: pytest.FixtureRequest, tmp_path: Path):
    """start(*args, lite=True) -> SimNode: starts $SO101_BIN_DIR/so101_sim_node with the given flags
    (`--lite` added unless lite=False, `--cameras none` unless the flags name cameras). At teardown every node still running gets SIGINT and must
    exit with return code 0; a node that died during the test fails it too."""
    binary: list[Path] = []
    nodes: list[SimNode] = []
    show_on_failure(request, nodes)

    def start(*args: str, lite: bool = True) -> SimNode:
        if not binary:
            binary.append(node_binary())
        argv = [str(a) for a in args]
        if lite and "--lite" not in argv:
            argv.insert(0, "--lite")
        # Rendering is tested where a test asks for cameras; elsewhere it would only load the CPU.
        if not any(a == "--cameras" or a.startswith("--cameras=") for a in argv):
            argv[:0] = ["--cameras", "none"]
        node = SimNode(binary[0], argv, tmp_path / f"so101_sim_node.{len(nodes)}.log")
        nodes.append(node)
        return node

    yield start

    problems = stop_nodes(nodes)
    if problems:
        pytest.fail("\n\n".join(problems), pytrace=False)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo):
    """Attach the output of every node of a failed test to its report."""
    report = yield
    if report.failed:
        nodes = [node for group in getattr(item, "_so101_node_groups", []) for node in group]
        for index, node in enumerate(nodes):
            report.sections.append((f"node #{index} output ({report.when}): {node.describe()}", node.log_tail(20000)))
    return report


# =========================================================================== the driver + emulator
@pytest.fixture
def arm_factory(request: pytest.FixtureRequest, tmp_path: Path):
    """start(*driver_args, emulator_args=(), calibration=CALIBRATION, emulator_calibration=None)
    -> (SimNode, ServoEmulator): a servo-bus emulator on a pty (linked at tmp_path/bus), its servos
    calibrated with `emulator_calibration` (default: the same file; "factory": uncalibrated), and
    so101_feetech_driver on it with the LeRobot calibration file `calibration`. At teardown the driver gets SIGINT and must exit 0 (unless the test set
    `node.exit_expected = True`)."""
    from driver_harness import CALIBRATION, DRIVER_NAME, ServoEmulator, write_calibration

    nodes: list[SimNode] = []
    emulators: list[ServoEmulator] = []
    show_on_failure(request, nodes)

    def start(*args: str, emulator_args=(), calibration=CALIBRATION, emulator_calibration=None, wait=True):
        # The emulated servos come calibrated as the file says (as after `calibrate`), unless the
        # test gives them another calibration, or "factory" for servos fresh from the box.
        index = len(emulators)
        link = tmp_path / f"bus{index}"
        cal_path = write_calibration(tmp_path / f"calibration{index}.json", calibration)
        if emulator_calibration == "factory":
            preset = []
        else:
            servo_cal = emulator_calibration or calibration
            preset = ["--calibration", str(write_calibration(tmp_path / f"servos{index}.json", servo_cal))]
        emulator = ServoEmulator(link, tmp_path / f"emulator.{index}.log", *preset, *emulator_args)
        emulators.append(emulator)
        argv = ["--port", str(link), "--calibration", str(cal_path), *[str(a) for a in args]]
        node = SimNode(node_binary(DRIVER_NAME), argv, tmp_path / f"{DRIVER_NAME}.{index}.log")
        nodes.append(node)
        return node, emulator

    yield start

    problems = stop_nodes(nodes)
    for emulator in emulators:
        emulator.stop()
    if problems:
        pytest.fail("\n\n".join(problems), pytrace=False)


# =========================================================================== the recorder
@pytest.fixture
def recorder_factory(request: pytest.FixtureRequest, tmp_path: Path):
    """start(*args, output=tmp_path/"bags") -> SimNode: recorder_node recording into `output`. At
    teardown it gets SIGINT and must exit 0 (unless the test set `node.exit_expected = True`)."""
    nodes: list[SimNode] = []
    show_on_failure(request, nodes)

    def start(*args: str, output: Path | None = None) -> SimNode:
        output = output or tmp_path / "bags"
        argv = ["--output", str(output), *[str(a) for a in args]]
        node = SimNode(node_binary("recorder_node"), argv, tmp_path / f"recorder_node.{len(nodes)}.log")
        node.output = output
        nodes.append(node)
        return node

    yield start

    problems = stop_nodes(nodes)
    if problems:
        pytest.fail("\n\n".join(problems), pytrace=False)


# =========================================================================== teleop
@pytest.fixture
def teleop_factory(request: pytest.FixtureRequest, tmp_path: Path):
    """start(*args, stdin=None) -> SimNode: teleop_node with the given flags. At teardown it gets
    SIGINT and must exit 0 (unless the test set `node.exit_expected = True`, or it already ended
    with 0 by itself)."""
    nodes: list[SimNode] = []
    show_on_failure(request, nodes)

    def start(*args: str) -> SimNode:
        node = SimNode(node_binary("teleop_node"), [str(a) for a in args], tmp_path / f"teleop_node.{len(nodes)}.log")
        nodes.append(node)
        return node

    yield start

    problems = stop_nodes(nodes)
    if problems:
        pytest.fail("\n\n".join(problems), pytrace=False)


# =========================================================================== rclpy
@pytest.fixture
def ros():
    """A probe node in a fresh rclpy context (its own DDS participant, so no graph state leaks
    between tests), spinning in a background thread."""
    _refuse_outside_namespace()  # belt and braces: never open a participant outside the namespace
    probe = Probe("so101_test_probe")
    try:
        yield probe
    finally:
        probe.close()
