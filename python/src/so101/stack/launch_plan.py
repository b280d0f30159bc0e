"""so101-launch's plan: which processes a profile starts, with their command lines, in start order.
Pure (no process is started): so101.stack.launch runs the plan."""

from __future__ import annotations

import argparse
import os
import shlex
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

from .. import contract
from ..paths import asset, node_binary

# The arm `--robot real --emulate` emulates unless the user names a calibration.
EMULATED_ARM_CALIBRATION = "emulated_arm/so101_calibration.json"  # under assets/

# JPEG quality of the recorded camera frames (docs/benchmarks.md, "Recording size": the best
# fidelity within 10 MB per second of robot time for the three default cameras).
DEFAULT_JPEG_QUALITY = 100
# --speed's value that runs the sim in lockstep with the expert (each command one control period).
LOCKSTEP = "lockstep"


def speed_value(text: str) -> float | str:
    """--speed's value (so101-launch's and so101-learn demos'): a factor of real time, or LOCKSTEP."""
    if text == LOCKSTEP:
        return text
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is neither a factor of real time nor {LOCKSTEP!r}") from None


# What the recorder keeps by default with compressed cameras: recorder_node's default set
# (crates/recorder_node/src/topics.rs DEFAULT_PATTERNS; a unit test holds the two together) with
# the cameras' compressed topics in place of their raw images.
COMPRESSED_RECORDING = [
    "joint_states",
    "joint_commands",
    "forward_position_controller/commands",
    "leader/joint_states",
    f"{contract.CAMERA_PREFIX}/[^/]+/{contract.IMAGE_COMPRESSED}",
    f"{contract.CAMERA_PREFIX}/[^/]+/{contract.CAMERA_INFO}",
    "task/reward",
    "task/success",
    "cube/pose",
    "episode/events",
    "diagnostics",
]
# recorder_node flags that choose the topics themselves (then the launcher adds none).
RECORDER_TOPIC_FLAGS = ("--topics", "--all", "--regex")


def has_flag(argv: list[str], flag: str) -> bool:
    """`flag` among `argv`, alone or as `flag=VALUE`."""
    return any(arg == flag or arg.startswith(flag + "=") for arg in argv)


@dataclass
class NodeSpec:
    """One process of the launch: its name (log file), command line, and what shows it is up."""

    name: str
    argv: list[str]
    ready: str = ""  # a graph condition, see Launch.wait_ready
    terminal: bool = False  # keeps the launcher's terminal (keyboard teleop)
    ends_run: bool = False  # its own exit ends the run
    open_stdin: bool = False  # reads commands from stdin and ends at its EOF (the emulator)
    env: dict[str, str] | None = None  # its whole environment (default: node_environment())


def task_of(value: str) -> tuple[str, str]:
    """--task: a task's name, with underscores or dashes, or its text (contract.TASKS: the sim
    scores it, the expert plays it, the episodes carry its text), or any other text for the
    episodes of cube_to_bin."""
    name = value.replace("-", "_")
    if name in contract.TASKS:
        return name, contract.TASKS[name].description
    described = [task for task, facts in contract.TASKS.items() if facts.description == value]
    if described:
        return described[0], value
    return "cube_to_bin", value


def plan(args) -> list[NodeSpec]:
    """The processes of a profile, in start order."""
    specs: list[NodeSpec] = []
    task, task_text = task_of(args.task)
    ns = ["--namespace", args.namespace] if args.namespace else []
    if args.robot == "sim":
        if args.camera:
            raise SystemExit(
                "so101-launch: --camera serves the real arm's cameras; the sim renders its own (--sim-args=--cameras)"
            )
        sim = [str(node_binary("so101_sim_node")), "--seed", str(args.seed), *ns]
        if args.lite:
            sim.append("--lite")
        if task != "cube_to_bin":
            sim += ["--task", task]
        if args.speed == LOCKSTEP:
            if args.control != "expert":
                raise SystemExit("so101-launch: --speed lockstep steps the sim once per command of the expert (--control expert)")
            sim += ["--lockstep", "--step-on-command"]
        elif args.speed:
            sim += ["--speed", f"{args.speed:g}"]
        extra = shlex.split(args.sim_args)
        if args.record and not args.raw_images:
            # The JPEG frames the recorder keeps (the raw ones are still published for live peers).
            sim += [] if has_flag(extra, "--jpeg") else ["--jpeg"]
            sim += [] if has_flag(extra, "--jpeg-quality") else ["--jpeg-quality", str(args.jpeg_quality)]
        sim += extra
        specs.append(NodeSpec("so101_sim_node", sim, ready="publisher /joint_states"))
    else:
        port = args.port
        calibration = args.calibration
        if args.emulate:
            port = port or str(Path(args.log_dir) / "servo_bus")
            # The emulated servos come configured as the calibration the driver reads says.
            if not calibration and not args.robot_id:
                calibration = str(asset(EMULATED_ARM_CALIBRATION))
            arm = Path(calibration) if calibration else lerobot_calibration_file(args.robot_id)
            if not arm.is_file():
                raise SystemExit(f"so101-launch: no calibration file {arm} for the emulated arm")
            specs.append(emulator_spec("so101_servo_emulator", port, arm))
        if not port:
            raise SystemExit("so101-launch: --robot real needs --port (or --emulate)")
        driver = [str(node_binary("so101_feetech_driver")), "--port", port, *ns]
        if args.robot_id:
            driver += ["--robot-id", args.robot_id]
        if calibration:
            driver += ["--calibration", calibration]
        driver += shlex.split(args.driver_args)
        specs.append(NodeSpec("so101_feetech_driver", driver, ready="publisher /joint_states"))
        if args.control == "teleop" and args.teleop_source == "leader":
            leader_port = args.leader_port
            if not leader_port and args.emulate:
                # An emulated leader arm beside the follower, configured as the same calibration.
                leader_port = str(Path(args.log_dir) / "leader_bus")
                specs.append(emulator_spec("leader_emulator", leader_port, arm))
            if not leader_port:
                raise SystemExit("so101-launch: a leader arm on the real robot needs --leader-port (or --emulate)")
            leader = [str(node_binary("so101_feetech_driver")), "--port", leader_port, "--leader", *ns]
            if args.leader_id:
                leader += ["--robot-id", args.leader_id]
            elif args.emulate and not args.leader_port:
                leader += ["--calibration", str(arm)]
            specs.append(NodeSpec("leader_arm", leader, ready="publisher /leader/joint_states"))
        if args.camera:
            specs.append(camera_spec(args, ns))

    if args.tf or args.rviz:
        specs.append(
            NodeSpec(
                "so101_state_publisher", [str(node_binary("so101_state_publisher")), *ns], ready="publisher /robot_description"
            )
        )
    if args.rviz:
        specs.append(rviz_spec(Path(args.log_dir) / "ros_prefix"))
    if args.rerun:
        sink = args.rerun
        if sink == "spawn":
            sink_args = ["--spawn"]
        elif sink == "connect" or sink.startswith("connect="):
            sink_args = ["--connect", *([sink.split("=", 1)[1]] if "=" in sink else [])]
        else:
            sink_args = ["--save", sink]
        # Only the bridge subscribes to the task's reward this early (the recorder starts after it).
        if args.camera:
            # The real cameras by their names (the default is the sim's).
            sink_args += ["--cameras", ",".join(camera_names(args))]
        specs.append(
            NodeSpec("so101_rerun", [str(node_binary("so101_rerun")), "live", *sink_args, *ns], ready="subscriber /task/reward")
        )

    if args.record:
        recorder = [str(node_binary("recorder_node")), "--output", args.bags, "--task", task_text, *ns]
        if args.control == "policy" and not args.episode_time:
            recorder.append("--start")  # no one marks episodes: one from start to stop
        extra = shlex.split(args.recorder_args)
        if not args.raw_images and not any(has_flag(extra, flag) for flag in RECORDER_TOPIC_FLAGS):
            for pattern in COMPRESSED_RECORDING:
                recorder += ["--regex", pattern]
        recorder += extra
        specs.append(NodeSpec("recorder_node", recorder, ready="subscriber /episode/events"))

    if args.control in ("teleop", "expert"):
        teleop = [str(node_binary("teleop_node")), *ns]
        if args.control == "expert":
            if args.robot != "sim":
                raise SystemExit("so101-launch: the scripted expert needs the sim (it reads /cube/pose)")
            clock = "--lockstep" if args.speed == LOCKSTEP else "--sim-time"
            teleop += ["--source", "expert", clock, "--seed", str(args.seed), "--task", task_text]
            teleop += ["--sim-task", task]
            if args.episodes:
                teleop += ["--episodes", str(args.episodes)]
        else:
            teleop += ["--source", args.teleop_source, "--mode", args.mode]
        teleop += shlex.split(args.teleop_args)
        specs.append(
            NodeSpec("teleop_node", teleop, terminal=args.control == "teleop" and args.teleop_source == "keyboard", ends_run=True)
        )
    elif args.control == "policy":
        if not args.policy:
            raise SystemExit("so101-launch: --control policy needs --policy (a checkpoint directory or a Hub id)")
        runner = [str(Path(sys.executable).parent / "so101-run-policy"), args.policy, *ns, "--quiet"]
        # The episodes' text is what a language-conditioned policy is told to do.
        runner += ["--sim-task", task, "--task", task_text]
        runner += shlex.split(args.policy_args)
        specs.append(NodeSpec("so101-run-policy", runner, ends_run=True))
    return specs


def emulator_spec(name: str, link: str, calibration: Path) -> NodeSpec:
    """so101_servo_emulator standing in for an arm's bus at `link`, its servos configured as
    `calibration` says; up once the link exists."""
    argv = [str(node_binary("so101_servo_emulator")), "--link", link, "--calibration", str(calibration)]
    return NodeSpec(name, argv, ready=f"path {link}", open_stdin=True)


def camera_names(args) -> list[str]:
    """The NAME of each --camera NAME=DEVICE."""
    return [request.split("=", 1)[0] for request in args.camera]


def camera_spec(args, ns: list[str]) -> NodeSpec:
    """so101_camera_node serving each --camera, up once the first camera's JPEG topic is there."""
    camera = [str(node_binary("so101_camera_node")), *ns]
    for request in args.camera:
        camera += ["--camera", request]
    camera += shlex.split(args.camera_args)
    first = camera_names(args)[0]
    return NodeSpec(
        "so101_camera_node",
        camera,
        ready=f"publisher /{contract.camera_topic(first, contract.IMAGE_COMPRESSED)}",
    )


def check_session(args) -> None:
    """A timed session (--episode-time) marks the episodes itself: no one else may."""
    if not args.episode_time:
        return
    if not args.record:
        raise SystemExit("so101-launch: --episode-time times recorded episodes: add --record")
    if args.control == "expert":
        raise SystemExit("so101-launch: the expert marks its own episodes; --episode-time is for a person (or a policy)")
    if args.control == "teleop" and args.teleop_source == "keyboard":
        raise SystemExit(
            "so101-launch: the keyboard teleop marks episodes itself (Enter, Backspace) and its arrows move the arm; "
            "--episode-time is for the leader arm or a gamepad"
        )


def rviz_spec(prefix: Path) -> NodeSpec:
    """rviz2 with the stack's view, the so101_description package installed into `prefix` for its
    package:// mesh URIs. rviz2 comes from the user's ROS 2 install, with its environment."""
    from .description import RVIZ_CONFIG, install

    rviz = shutil.which("rviz2")
    if rviz is None:
        raise SystemExit(
            "so101-launch: --rviz needs rviz2 on PATH (ROS 2 Jazzy: apt install ros-jazzy-rviz2, then "
            "source /opt/ros/jazzy/setup.bash); without it, `so101-description install DIR` gives the "
            "package and view to open elsewhere"
        )
    share = install(prefix)
    env = dict(os.environ)
    env["AMENT_PREFIX_PATH"] = os.pathsep.join([str(prefix), *filter(None, [env.get("AMENT_PREFIX_PATH")])])
    return NodeSpec("rviz2", [rviz, "-d", str(share / RVIZ_CONFIG)], env=env)


def lerobot_calibration_file(robot_id: str) -> Path:
    """Where LeRobot (and the driver's --robot-id) keeps a follower arm's calibration:
    $HF_LEROBOT_CALIBRATION, else $HF_LEROBOT_HOME/calibration, else $HF_HOME/lerobot/calibration,
    else ~/.cache/huggingface/lerobot/calibration; then robots/so_follower/ID.json."""
    env = {
        name: os.environ.get(name) or None
        for name in ("HF_LEROBOT_CALIBRATION", "HF_LEROBOT_HOME", "HF_HOME", "XDG_CACHE_HOME", "HOME")
    }
    if env["HF_LEROBOT_CALIBRATION"]:
        base = Path(env["HF_LEROBOT_CALIBRATION"])
    elif env["HF_LEROBOT_HOME"]:
        base = Path(env["HF_LEROBOT_HOME"]) / "calibration"
    else:
        cache = Path(env["XDG_CACHE_HOME"]) if env["XDG_CACHE_HOME"] else Path(env["HOME"] or "") / ".cache"
        hf_home = Path(env["HF_HOME"]) if env["HF_HOME"] else cache / "huggingface"
        base = hf_home / "lerobot" / "calibration"
    return base / "robots" / "so_follower" / f"{robot_id}.json"
