"""so101-launch: start the stack's nodes together by profile and stop them cleanly.

  robot:    sim (so101_sim_node) or real (so101_feetech_driver on --port; --emulate puts the
            servo-bus emulator behind it, for a try without an arm: the arm of
            assets/emulated_arm/so101_calibration.json, or of --calibration / --robot-id's file,
            for the emulator and the driver alike)
  control:  teleop (teleop_node: keyboard, gamepad or leader arm), expert (the scripted expert,
            --episodes N), policy (so101-run-policy with --policy), or none
  cameras:  --camera NAME=DEVICE (real arm): so101_camera_node serves USB cameras beside the
            driver (camera/NAME/image_raw/compressed, as the sim's cameras)
  --record: recorder_node, one bag per episode into --bags (the expert and the keyboard mark the
            episodes; with a policy, one episode from start to stop; with --episode-time S, timed
            episodes as lerobot-record records them: S seconds each, --reset-time between, keys
            right arrow (next), left arrow (re-record), Esc (stop)). Cameras are recorded
            compressed: the sim also publishes JPEG (--jpeg-quality, default 100) and the recorder
            keeps /camera/NAME/image_raw/compressed instead of the raw images (8 MB per second of
            robot time for the three 640x480 cameras at 30 Hz instead of 83, at 52 dB PSNR);
            --raw-images records the raw sensor_msgs/Image frames instead
  --tf:     so101_state_publisher (/robot_description and /tf, for RViz)
  --rviz:   RViz 2 (rviz2, from a ROS 2 Jazzy install on PATH) with the stack's view
            (assets/rviz/so101.rviz: the arm, its frames, the three cameras); implies --tf and
            installs the so101_description package (meshes for package:// URIs) into
            LOG_DIR/ros_prefix, which RViz finds through AMENT_PREFIX_PATH
  --rerun:  so101_rerun live into a viewer it starts (spawn), a running one (connect[=URL]) or a
            FILE.rrd

Nodes start in order (robot, visualization, recorder, control), each once the one before is on
the ROS graph.
The run ends when the control ends by itself (the expert's last episode, the policy's --duration,
q in the keyboard teleop), at Ctrl-C or SIGTERM, or when a node dies; then the nodes are stopped in
reverse order with SIGINT (the recorder closes its bag, the driver turns torque off), and
killed only if they do not exit within --stop-timeout. Each node's log goes to --log-dir.

DDS stays on this machine: outside a private network namespace the launcher re-runs itself in
scripts/isolated (--host-network opts out, to reach ROS 2 tools on other hosts).

Examples:
  so101-launch --control expert --episodes 10 --record --bags bags/
  so101-launch --robot real --port /dev/ttyACM0 --robot-id my_arm --control policy --policy outputs/act_so101/checkpoints/last/pretrained_model
  so101-launch --control teleop --teleop-source gamepad --record
  so101-launch --robot real --port /dev/ttyACM0 --robot-id my_arm --teleop-source leader --leader-port /dev/ttyACM1 --camera top=/dev/video0 --camera wrist=/dev/video2 --record --episodes 50 --episode-time 30
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from .. import contract
from ..paths import isolated_wrapper, node_environment
from . import process as processes
from . import record_session
from .isolation import network_namespace_problem
from .launch_plan import DEFAULT_JPEG_QUALITY, NodeSpec, check_session, plan, speed_value


@dataclass
class Running:
    spec: NodeSpec
    process: subprocess.Popen
    log: Path
    stopped_by_us: bool = False


class Launch:
    def __init__(self, log_dir: Path, ready_timeout: float, stop_timeout: float, namespace: str):
        self.log_dir = log_dir
        self.ready_timeout, self.stop_timeout = ready_timeout, stop_timeout
        self.prefix = "/" + namespace.strip("/") if namespace.strip("/") else ""
        self.running: list[Running] = []
        self._graph = None
        # The episodes reported (watch, report_episodes) or an earlier run's; None until looked at.
        self.reported: set[Path] | None = None

    # ------------------------------------------------------------------ readiness
    def graph_node(self):
        if self._graph is None:
            import rclpy

            rclpy.init()
            self._graph = rclpy.create_node("so101_launch", start_parameter_services=False)
        return self._graph

    def forget_graph_node(self) -> None:
        """Ends the graph node and its DDS participant; graph_node() makes a fresh one."""
        if self._graph is not None:
            import rclpy

            self._graph.destroy_node()
            rclpy.try_shutdown()
            self._graph = None

    def wait_ready(self, entry: Running) -> None:
        """Blocks until the node shows on the graph ("publisher TOPIC" / "subscriber TOPIC") or its
        file exists ("path P"); SystemExit when it dies or takes longer than the ready timeout."""
        from .discovery import REDISCOVER_AFTER_S

        kind, _, what = entry.spec.ready.partition(" ")
        deadline = time.monotonic() + self.ready_timeout
        looked = time.monotonic()
        while True:
            if entry.process.poll() is not None:
                raise SystemExit(
                    f"so101-launch: {entry.spec.name} exited with {entry.process.returncode} while starting\n" + tail(entry.log)
                )
            if kind == "path":
                up = Path(what).exists()
            elif kind in ("publisher", "subscriber"):
                graph = self.graph_node()
                topic = self.prefix + what
                count = graph.count_publishers(topic) if kind == "publisher" else graph.count_subscribers(topic)
                up = count > 0
            else:
                up = True
            if up:
                return
            if kind == "publisher" and time.monotonic() - looked > REDISCOVER_AFTER_S:
                # A node slow to start, or one this participant's discovery missed (so101.stack.discovery).
                self.forget_graph_node()
                looked = time.monotonic()
            if time.monotonic() > deadline:
                raise SystemExit(
                    f"so101-launch: {entry.spec.name} not up within {self.ready_timeout:.0f} s "
                    f"({entry.spec.ready})\n" + tail(entry.log)
                )
            time.sleep(0.1)

    # ------------------------------------------------------------------ processes
    def start(self, spec: NodeSpec) -> Running:
        """Starts a node; it gets SIGTERM from the kernel should the launcher die without
        stopping it (SIGKILL, a crash), so no node outlives the launch."""
        log = self.log_dir / f"{spec.name}.log"
        with open(log, "wb") as out:
            # Every node in a session of its own, so a Ctrl-C at the terminal reaches the launcher
            # only and the nodes stop in order; the keyboard teleop keeps the terminal (raw mode
            # turns Ctrl-C into a key it handles itself).
            stdin = None if spec.terminal else subprocess.PIPE if spec.open_stdin else subprocess.DEVNULL
            process = processes.start(
                [*DIE_WITH_PARENT, *spec.argv],
                env=spec.env if spec.env is not None else node_environment(),
                stdin=stdin,
                stdout=None if spec.terminal else out,
                stderr=out,
                start_new_session=not spec.terminal,
            )
        entry = Running(spec, process, log)
        self.running.append(entry)
        print(f"so101-launch: started {spec.name} (pid {process.pid}, log {log})", flush=True)
        if spec.ready:
            self.wait_ready(entry)
        return entry

    def stop_all(self) -> None:
        """SIGINT to each node in reverse start order, each given stop_timeout to exit, then SIGKILL.
        A second Ctrl-C (or SIGTERM) meanwhile hurries it: the nodes still running are killed."""
        for entry in reversed(self.running):
            if entry.process.poll() is not None:
                continue
            entry.stopped_by_us = True
            entry.process.send_signal(signal.SIGINT)
            try:
                entry.process.wait(timeout=self.stop_timeout)
            except (subprocess.TimeoutExpired, KeyboardInterrupt) as reason:
                why = "was hurried" if isinstance(reason, KeyboardInterrupt) else f"did not stop within {self.stop_timeout:.0f} s"
                print(f"so101-launch: {entry.spec.name} {why}: killed", flush=True)
                for other in self.running:
                    if other.process.poll() is None and (other is entry or isinstance(reason, KeyboardInterrupt)):
                        other.stopped_by_us = True
                        other.process.kill()
                        other.process.wait()
        self.forget_graph_node()

    def watch(self, bags: Path | None, session=None) -> Running | None:
        """Until a node exits; returns it (None when none is left, or when `session`, a
        record_session.SessionRunner, has recorded its episodes). Meanwhile reports each episode
        the recorder closes in `bags`."""
        if self.reported is None:
            self.remember_earlier_episodes(bags)
        while self.running:
            self.report_episodes(bags)
            for entry in self.running:
                if entry.process.poll() is not None:
                    self.report_episodes(bags)
                    return entry
            if session is not None and session.poll():
                return None
            # A session's keys and episode ends want a quicker look than the nodes and the bags do.
            time.sleep(0.05 if session is not None else 0.2)
        return None

    def remember_earlier_episodes(self, bags: Path | None) -> None:
        """Episodes already in `bags` are an earlier run's, never reported. Called before the nodes
        start: an episode closed between their start and watch's first look is this run's."""
        pattern = f"{contract.EPISODE_DEFAULT_PREFIX}_*/{contract.EPISODE_METADATA_FILE}"
        self.reported = set(bags.glob(pattern)) if bags is not None else set()

    def report_episodes(self, bags: Path | None) -> None:
        """Reports the episodes closed in `bags` since the last look (none before watch). After
        stop_all, those the recorder closed on its way out: the expert's node ends the run right
        after its last stop event, and a busy recorder may write that episode's metadata after."""
        if bags is not None and self.reported is not None:
            report_closed_episodes(bags, self.reported)


def report_closed_episodes(bags: Path, reported: set[Path]) -> None:
    """Prints the episodes newly closed in `bags` (metadata.yaml written), with their verdict."""
    from ..dataset.bags import BagError, episode_verdict

    for metadata in sorted(bags.glob(f"{contract.EPISODE_DEFAULT_PREFIX}_*/{contract.EPISODE_METADATA_FILE}")):
        if metadata in reported:
            continue
        reported.add(metadata)
        try:
            verdict = {True: "success", False: "failure", None: "no verdict"}[episode_verdict(metadata.parent)]
        except BagError as error:  # shown now, before a conversion meets it
            verdict = f"no verdict: {error}"
        print(f"so101-launch: recorded {metadata.parent.name} ({verdict})", flush=True)


def stop_like_ctrl_c(_signum, _frame) -> None:
    """SIGTERM (a service manager, kill) and SIGHUP (the terminal closed) stop the run as Ctrl-C does."""
    raise KeyboardInterrupt


# Each node gets SIGTERM from the kernel when the launcher dies (prctl PDEATHSIG, set by
# util-linux's setpriv just before it execs the node; a preexec_fn would not be safe here, the
# launcher's rclpy graph node runs DDS threads).
DIE_WITH_PARENT = ["setpriv", "--pdeathsig", "TERM", "--"] if shutil.which("setpriv") else []


def tail(log: Path, lines: int = 15) -> str:
    try:
        text = log.read_text(errors="replace").splitlines()[-lines:]
    except OSError:
        return ""
    return "\n".join(f"    {line}" for line in text)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="so101-launch", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--robot", choices=["sim", "real"], default="sim", help="the arm: simulation or the physical driver")
    p.add_argument("--control", choices=["teleop", "expert", "policy", "none"], default="teleop", help="who moves the arm")
    p.add_argument("--record", action="store_true", help="record episode bags with recorder_node")
    p.add_argument("--namespace", default="", help="put every node under /NAMESPACE/")
    p.add_argument("--seed", type=int, default=0, help="sim and expert seed")
    p.add_argument(
        "--task",
        default="cube_to_bin",
        help=f"the task ({', '.join(contract.TASKS)}): the sim scores it, the expert plays it, the recorded "
        "episodes carry its text; any other text is the episodes' text for cube_to_bin",
    )
    p.add_argument("--log-dir", default=None, help="node logs (default logs/launch-<time>/)")
    p.add_argument("--ready-timeout", type=float, default=30.0, help="seconds a node may take to come up")
    p.add_argument("--stop-timeout", type=float, default=15.0, help="seconds a node may take to stop before it is killed")
    p.add_argument("--host-network", action="store_true", help="do not isolate DDS in a private network namespace")
    sim = p.add_argument_group("sim")
    sim.add_argument("--lite", action="store_true", help="no meshes (renders ~5x faster on a CPU)")
    sim.add_argument(
        "--speed",
        type=speed_value,
        default=None,
        help="sim speed (default: real time; 4 with the expert), or 'lockstep' with the expert: the sim steps once per "
        "command and the expert waits for each period's state, so a recording repeats for one seed and runs as fast "
        "as the machine goes",
    )
    sim.add_argument("--sim-args", default="", help='more so101_sim_node flags in one string (--sim-args="--cameras top,wrist")')
    real = p.add_argument_group("real")
    real.add_argument("--port", default=None, help="the arm's servo bus, e.g. /dev/ttyACM0")
    real.add_argument("--robot-id", default=None, help="the arm's LeRobot calibration id")
    real.add_argument("--calibration", default=None, help="a LeRobot calibration file instead of --robot-id's")
    real.add_argument(
        "--emulate",
        action="store_true",
        help="run so101_servo_emulator as the arm (no hardware): the arm of --calibration or "
        "--robot-id's file, else the project's assets/emulated_arm/so101_calibration.json",
    )
    real.add_argument("--leader-port", default=None, help="the leader arm's bus (--teleop-source leader)")
    real.add_argument("--leader-id", default=None, help="the leader arm's calibration id")
    real.add_argument("--driver-args", default="", help="more so101_feetech_driver flags")
    real.add_argument(
        "--camera",
        action="append",
        default=[],
        metavar="NAME=DEVICE",
        help="a camera for so101_camera_node, NAME=DEVICE[:WIDTHxHEIGHT][@FPS] (repeatable; e.g. "
        "top=/dev/v4l/by-id/usb-...-video-index0); its JPEG frames are recorded with --record",
    )
    real.add_argument("--camera-args", default="", help='more so101_camera_node flags, e.g. "--control top.exposure=156"')
    control = p.add_argument_group("control")
    control.add_argument("--teleop-source", choices=["keyboard", "gamepad", "leader"], default="keyboard")
    control.add_argument("--mode", choices=["joint", "cartesian"], default="joint", help="teleop space")
    control.add_argument(
        "--episodes", type=int, default=0, help="expert or --episode-time: stop after N episodes (0: until stopped)"
    )
    control.add_argument("--teleop-args", default="", help="more teleop_node flags")
    control.add_argument("--policy", default=None, help="policy checkpoint directory or Hub id (--control policy)")
    control.add_argument("--policy-args", default="", help='more so101-run-policy flags, e.g. "--duration 60"')
    viz = p.add_argument_group("visualization")
    viz.add_argument("--tf", action="store_true", help="publish /robot_description and /tf (so101_state_publisher)")
    viz.add_argument("--rviz", action="store_true", help="open RViz 2 with the stack's view (needs rviz2 on PATH; implies --tf)")
    viz.add_argument(
        "--rerun",
        default=None,
        metavar="SINK",
        help="show the run in Rerun: spawn (a viewer), connect[=URL] (a running one) or FILE.rrd",
    )
    record = p.add_argument_group("recording")
    record.add_argument("--bags", default="bags", help="directory of the episode bags")
    record.add_argument(
        "--raw-images",
        action="store_true",
        help="record the cameras' raw sensor_msgs/Image frames (about 83 MB per second of robot time for three "
        "640x480 cameras at 30 Hz) instead of their JPEG frames on image_raw/compressed",
    )
    record.add_argument(
        "--jpeg-quality",
        type=int,
        default=DEFAULT_JPEG_QUALITY,
        choices=range(1, 101),
        metavar="1-100",
        help=f"JPEG quality of the recorded sim camera frames (default {DEFAULT_JPEG_QUALITY})",
    )
    record.add_argument(
        "--episode-time",
        type=float,
        default=0.0,
        metavar="S",
        help="record timed episodes as lerobot-record does: --episodes N (0: until Esc) of S seconds each, a "
        "reset period between them; keys: right arrow ends the episode or the reset now, left arrow "
        "re-records, Esc stops",
    )
    record.add_argument(
        "--reset-time", type=float, default=10.0, metavar="S", help="seconds of each reset period (--episode-time)"
    )
    record.add_argument(
        "--recorder-args",
        default="",
        help="more recorder_node flags (--topics, --regex or --all choose the topics instead of the launcher)",
    )
    return p


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = parser().parse_args(argv)
    if args.rerun and args.rerun.startswith("connect") and not args.host_network:
        raise SystemExit(
            "so101-launch: --rerun connect reaches a viewer on this network namespace's loopback, not the "
            "host's: use --rerun spawn or --rerun FILE.rrd, or --host-network"
        )
    if not args.host_network and network_namespace_problem():
        # Re-run inside a private network namespace; every node inherits it.
        isolated = str(isolated_wrapper())
        os.execv(isolated, [isolated, sys.executable, "-m", "so101.stack.launch", *argv])
    if args.speed is None and args.robot == "sim" and args.control == "expert":
        args.speed = 4.0  # every camera frame rendered; as fast as the renderer allows, up to 4x
    args.log_dir = args.log_dir or f"logs/launch-{time.strftime('%Y%m%d-%H%M%S')}"
    log_dir = Path(args.log_dir)
    log_dir.mkdir(parents=True, exist_ok=True)
    try:
        check_session(args)
        specs = plan(args)
    except FileNotFoundError as error:
        raise SystemExit(f"so101-launch: {error}") from error

    launch = Launch(log_dir, args.ready_timeout, args.stop_timeout, args.namespace)
    keys = None
    # Ctrl-C is set explicitly: a launcher started as `so101-launch ... &` from a script inherits
    # SIGINT ignored, and so would every node it starts, deaf to the SIGINT that stops them.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, stop_like_ctrl_c)
    signal.signal(signal.SIGHUP, stop_like_ctrl_c)
    status = 0
    launch.remember_earlier_episodes(Path(args.bags) if args.record else None)
    try:
        for spec in specs:
            launch.start(spec)
        print("so101-launch: all nodes up (Ctrl-C stops them)", flush=True)
        session = None
        if args.episode_time:
            keys = record_session.TerminalKeys()
            session = record_session.SessionRunner(
                launch.graph_node(),
                launch.prefix,
                record_session.Session(args.episodes, args.episode_time, args.reset_time),
                sim=args.robot == "sim",
                keys=keys,
            )
        ended = launch.watch(Path(args.bags) if args.record else None, session)
        if session is not None and session.session.done:
            print("so101-launch: the recording session is over", flush=True)
        if ended is not None:
            code = ended.process.returncode
            if ended.spec.ends_run and code == 0:
                print(f"so101-launch: {ended.spec.name} finished", flush=True)
            else:
                status = 1
                print(f"so101-launch: {ended.spec.name} exited with {code}\n{tail(ended.log)}", flush=True)
    except KeyboardInterrupt:
        print("so101-launch: stopping", flush=True)
    except SystemExit as error:
        print(error, file=sys.stderr, flush=True)
        status = 1
    finally:
        if keys is not None:
            keys.close()
        launch.stop_all()
        launch.report_episodes(Path(args.bags) if args.record else None)
    for entry in launch.running:
        code = entry.process.returncode
        if entry.stopped_by_us and code not in (0, -signal.SIGINT):
            print(f"so101-launch: {entry.spec.name} stopped with {code} (log {entry.log})", flush=True)
            status = 1
    print(f"so101-launch: stopped; logs in {log_dir}", flush=True)
    return status


if __name__ == "__main__":
    sys.exit(main())
