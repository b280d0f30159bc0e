"""so101-run-policy: drive the arm with a LeRobot policy (a local checkpoint such as
outputs/act_so101/checkpoints/last/pretrained_model, or a Hub id) through rclpy.

Live (default): observations from /joint_states and /camera/<name>/image_raw (the cameras the
policy was trained with), one inference per period, /joint_commands at --fps. The same against
so101_sim_node and so101_feetech_driver: both speak the same topics. When an input goes stale
(older than --max-age) no command is sent, so the arm holds (the driver's watchdog, the sim's
last target) until it is fresh again.

A policy that acts in end-effector space (trained on a dataset converted with --action-space ee)
has each target turned into joint targets by the core's IK, then sent as any joint command: the
same limits, and the arm's node's own max-step.

Evaluation (--eval N): N seeded episodes on a sim of its own in lockstep (physics waits for the
policy), success rate, mean and best reward, an MP4 per episode and eval_info.json in --output;
with --backend inprocess --workers K, the episodes split over K processes.

Run it inside scripts/isolated with the arm's node (evaluation starts its own sim).
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

import numpy as np

from .. import contract, sim_options
from ..envs.spaces import reward_mode
from ..messages import cube_pose_vector, joint_positions, rgb_image
from ..stack.rclpy_wait import spin_until
from ..units import JOINT_LIMITS, JOINT_NAMES
from .policy import PolicyError, StackPolicy

log = logging.getLogger("so101-run-policy")


# =========================================================================== live
class PeriodClock:
    """The live loop's periods: each ends one period after the last, except that a period that ran
    past its end (a slow inference, a busy machine) is late: the next one starts then, and the time
    it overran is lost instead of made up by a burst of commands. So the accounting adds up:
    periods x period + lost = the time elapsed since the start (up to the current period)."""

    def __init__(self, period: float, now: float):
        self.period = period
        self.begun = now
        self.tick = now  # the end of the current period
        self.periods = 0
        self.late = 0
        self.lost = 0.0  # s of wall time the late periods ran past their end

    def elapsed(self) -> float:
        """The periods begun so far and the time lost, in seconds: what the run's length counts."""
        return self.tick - self.begun

    def next_period(self, now: float) -> float:
        """Ends the current period at `now`; returns the wall time the next one ends at."""
        self.periods += 1
        self.tick += self.period
        if now > self.tick:
            self.late += 1
            self.lost += now - self.tick
            self.tick = now  # never burst to catch up
        return self.tick


class LiveInputs:
    """The newest /joint_states, camera frames and (for a policy that takes the environment state)
    /cube/pose, with the wall time each arrived."""

    def __init__(self, node, prefix: str, cameras: dict[str, str], cube_pose: bool = False):
        from geometry_msgs.msg import PoseStamped
        from rclpy.qos import qos_profile_sensor_data
        from sensor_msgs.msg import CompressedImage, Image, JointState

        self.state: tuple[float, object] | None = None
        self.cube: tuple[float, object] | None = None
        self.wants_cube = cube_pose
        self.frames: dict[str, tuple[float, object]] = {}
        # The topic of each input, by the name stale() gives it.
        self.topics = {"/joint_states": f"{prefix}/{contract.JOINT_STATES}", **{f"camera {n}": t for n, t in cameras.items()}}
        if cube_pose:
            self.topics["/cube/pose"] = f"{prefix}/{contract.CUBE_POSE}"
            node.create_subscription(
                PoseStamped, f"{prefix}/{contract.CUBE_POSE}", lambda msg: setattr(self, "cube", (time.monotonic(), msg)), 10
            )
        # Best effort matches reliable and best-effort writers; only the newest message matters.
        node.create_subscription(JointState, f"{prefix}/{contract.JOINT_STATES}", self._on_state, qos_profile_sensor_data)
        for name, topic in cameras.items():
            # A camera's JPEG frames (so101_camera_node publishes those by default) or its rgb8 ones.
            kind = CompressedImage if topic.endswith("/compressed") else Image
            node.create_subscription(kind, topic, lambda msg, name=name: self._on_frame(name, msg), qos_profile_sensor_data)

    def _on_state(self, msg) -> None:
        if joint_positions(msg) is not None:
            self.state = (time.monotonic(), msg)

    def _on_frame(self, name: str, msg) -> None:
        self.frames[name] = (time.monotonic(), msg)

    def cube_pose(self) -> np.ndarray | None:
        """The newest cube pose as [x y z qw qx qy qz], or None."""
        return None if self.cube is None else cube_pose_vector(self.cube[1].pose)

    def stale(self, cameras: list[str], max_age: float) -> list[str]:
        """The inputs missing or older than max_age seconds."""
        now = time.monotonic()
        inputs = {"/joint_states": self.state, **{f"camera {name}": self.frames.get(name) for name in cameras}}
        if self.wants_cube:
            inputs["/cube/pose"] = self.cube
        return [what for what, entry in inputs.items() if entry is None or now - entry[0] > max_age]


class LiveNode:
    """The runner's rclpy node with its inputs and command publisher, on a DDS participant that
    wait_for_inputs() replaces when it is blind to the arm's node (so101.stack.discovery)."""

    def __init__(self, prefix: str, cameras: dict[str, str], cube_pose: bool):
        self._prefix, self._cameras, self._cube_pose = prefix, cameras, cube_pose
        self._open()

    def _open(self) -> None:
        import rclpy
        from sensor_msgs.msg import JointState

        rclpy.init()
        self.node = rclpy.create_node("so101_policy_runner")
        self.inputs = LiveInputs(self.node, self._prefix, self._cameras, cube_pose=self._cube_pose)
        self.commands = self.node.create_publisher(JointState, f"{self._prefix}/{contract.JOINT_COMMANDS}", 10)
        self.opened = time.monotonic()

    def close(self) -> None:
        import rclpy

        self.node.destroy_node()
        rclpy.try_shutdown()

    def wait_for_inputs(self, cameras: list[str], max_age: float, timeout: float) -> bool:
        """Spins until every input is fresh; False when `timeout` seconds pass first. A participant
        that has discovered no publisher of a missing input after REDISCOVER_AFTER_S is replaced."""
        import rclpy

        from ..stack.discovery import REDISCOVER_AFTER_S, blind_to

        deadline = time.monotonic() + timeout
        while missing := self.inputs.stale(cameras, max_age):
            if time.monotonic() > deadline:
                return False
            if unseen := blind_to(self.node, [self.inputs.topics[what] for what in missing], self.opened):
                log.warning(
                    "no publisher of %s discovered in %.0f s: starting a fresh DDS participant",
                    ", ".join(unseen),
                    REDISCOVER_AFTER_S,
                )
                self.close()
                self._open()
            rclpy.spin_once(self.node, timeout_sec=0.05)
        return True


def run_live(args, policy: StackPolicy) -> int:
    import rclpy
    from sensor_msgs.msg import JointState
    from std_srvs.srv import Trigger

    prefix = "/" + args.namespace.strip("/") if args.namespace.strip("/") else ""
    leaf = contract.IMAGE_COMPRESSED if args.compressed else contract.IMAGE_RAW
    topics = {camera.name: f"{prefix}/{contract.camera_topic(camera.name, leaf)}" for camera in policy.cameras}
    topics.update(dict(item.split("=", 1) for item in args.camera))
    live = LiveNode(prefix, topics, cube_pose=policy.needs_environment_state)
    camera_names = [camera.name for camera in policy.cameras]
    period = 1.0 / args.fps
    steps = held = 0
    clock: PeriodClock | None = None
    inference: list[float] = []
    try:
        waiting_since = time.monotonic()
        # The inputs first: a participant that hears them has discovered the arm's node.
        if not live.wait_for_inputs(camera_names, args.max_age, args.startup_timeout):
            missing = live.inputs.stale(camera_names, args.max_age)
            raise SystemExit(
                f"so101-run-policy: nothing from {', '.join(missing)} within {args.startup_timeout:.0f} s "
                "(is the arm's node running, with these cameras?)"
            )
        node, inputs, commands = live.node, live.inputs, live.commands
        remaining = max(0.0, args.startup_timeout - (time.monotonic() - waiting_since))  # the reset's time aside
        if args.reset:
            client = node.create_client(Trigger, f"{prefix}/{contract.SIM_RESET}")
            if not spin_until(node, client.service_is_ready, 20.0):
                raise SystemExit(f"so101-run-policy: no {prefix}/sim/reset service within 20 s")
            future = client.call_async(Trigger.Request())
            if not spin_until(node, future.done, 10.0) or not future.result().success:
                raise SystemExit(f"so101-run-policy: {prefix}/sim/reset did not succeed")
        # The arm's node must hear the first command: wait until it has matched the publisher.
        if not spin_until(node, lambda: commands.get_subscription_count() > 0, remaining):
            raise SystemExit(
                f"so101-run-policy: no subscriber of {prefix}/joint_commands within "
                f"{args.startup_timeout:.0f} s (is the arm's node running?)"
            )
        # One inference before the clock starts: the first one (allocation, kernels) is slow.
        policy.act(
            policy.observation(
                joint_positions(inputs.state[1]),
                {name: rgb_image(inputs.frames[name][1]) for name in camera_names},
                inputs.cube_pose(),
            )
        )
        policy.reset()
        log.info("running at %.1f Hz%s", args.fps, f" for {args.duration:.0f} s" if args.duration else " until Ctrl-C")
        clock = PeriodClock(period, time.monotonic())
        while not args.duration or clock.elapsed() < args.duration:
            missing = inputs.stale(camera_names, args.max_age)
            if missing:
                held += 1
                if held == 1 or held % max(1, int(args.fps * 5)) == 0:
                    log.warning("holding the arm: %s stale (> %.2f s)", ", ".join(missing), args.max_age)
            else:
                started = time.monotonic()
                positions = joint_positions(inputs.state[1])
                images = {name: rgb_image(inputs.frames[name][1]) for name in camera_names}
                # The arm's node clamps too; never send past the model's limits from here either.
                observation = policy.observation(positions, images, inputs.cube_pose())
                target = np.clip(policy.act(observation), JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])
                inference.append(time.monotonic() - started)
                msg = JointState(name=JOINT_NAMES, position=[float(v) for v in target])
                msg.header.stamp = node.get_clock().now().to_msg()
                commands.publish(msg)
                steps += 1
            tick = clock.next_period(time.monotonic())
            while (wait := tick - time.monotonic()) > 0:
                rclpy.spin_once(node, timeout_sec=wait)
    except KeyboardInterrupt:
        pass
    finally:
        live.close()
    mean_ms = 1000 * float(np.mean(inference)) if inference else 0.0
    # The accounting adds up: (commands + held periods) / fps + lost = the run's length, within a period.
    late, lost = (clock.late, clock.lost) if clock else (0, 0.0)
    print(
        f"{steps} commands at {args.fps:.0f} Hz, inference {mean_ms:.1f} ms mean, {late} late periods "
        f"({lost:.2f} s lost), {held} held{ee_report(policy)}"
    )
    return 0


def ee_report(policy: StackPolicy) -> str:
    """How many of an end-effector policy's targets were out of reach (clamped by the IK)."""
    if policy.action_space != "ee":
        return ""
    return f", {policy.ee_clamped} of {policy.ee_steps} end-effector targets out of reach (nearest pose commanded)"


# =========================================================================== evaluation
def evaluate(args, policy: StackPolicy) -> int:
    """--eval: the episodes in this process with `policy`, or over --workers processes (each loads
    the policy itself)."""
    from . import parallel
    from .episodes import summarize, write_report

    cameras = {camera.name: (camera.height, camera.width) for camera in policy.cameras}
    # The video shows the policy's cameras, or --video-camera; a policy without cameras is filmed
    # from the front.
    video_camera = args.video_camera or (None if cameras else "front")
    video_cameras = [video_camera] if video_camera else list(cameras)
    filmed_cameras = dict(cameras)
    if video_camera and video_camera not in cameras:
        filmed_cameras[video_camera] = (240, 320)
    seeds = [args.seed + index for index in range(args.eval)]
    filmed = len(seeds) if args.videos is None else min(args.videos, len(seeds))
    # Episodes past --videos run on a sim without the extra video camera: rendering it would cost
    # more than the rest of the step.
    batches = [(0, seeds[:filmed], filmed_cameras, video_cameras), (filmed, seeds[filmed:], cameras, [])]
    jobs = [
        (args, first_index, share, env_cameras, filmed_now)
        for first, batch_seeds, env_cameras, filmed_now in batches
        for first_index, share in parallel.split(batch_seeds, first, args.workers)
        if share
    ]
    if args.workers > 1:
        results = parallel.run_shares(evaluate_share, jobs, args.workers)
    else:
        results = [result for job in jobs for result in run_share(policy, *job)]
    summary = summarize(
        results,
        policy=args.policy,
        reward=args.reward,
        backend=args.backend,
        fps=args.fps,
        episode_time_s=args.episode_time,
        servo_params=args.servo_params,
        randomize=args.randomize,
        camera_poses=args.camera_poses,
        task=args.sim_task,
        task_text=policy.task,
    )
    write_report(Path(args.output), summary, results)
    return 0


def load_policy(args) -> StackPolicy:
    task = args.task or contract.TASKS[args.sim_task].description
    return StackPolicy(args.policy, units=args.units, device=args.device, task=task, action_space=args.action_space)


def evaluate_share(args, first_index: int, seeds: list[int], env_cameras: dict, filmed_now: list[str]):
    """A worker's share of --eval: its own policy, torch threads and simulation."""
    import torch

    from . import parallel

    torch.set_num_threads(parallel.threads_per_worker(args.workers))
    return run_share(load_policy(args), args, first_index, seeds, env_cameras, filmed_now)


def run_share(policy: StackPolicy, args, first_index: int, seeds: list[int], env_cameras: dict, filmed_now: list[str]):
    from ..envs import make_env
    from .episodes import run_episodes

    env = make_env(
        args.sim_task,
        backend=args.backend,
        control_rate=args.fps,
        lite=args.lite,
        cameras=env_cameras or None,
        dense_reward=args.reward == "dense",
        servo_params=args.servo_params,
        randomize=args.randomize,
        camera_poses=args.camera_poses,
    )
    try:
        results = run_episodes(
            env,
            policy.act_on_env,
            lambda _observation: policy.reset(),
            seeds=seeds,
            max_steps=int(round(args.episode_time * args.fps)),
            video_cameras=filmed_now,
            output=Path(args.output),
            fps=args.fps,
            # Workers' bars would interleave: the parent reports.
            quiet=args.quiet or args.workers > 1,
            first_index=first_index,
        )
        if report := ee_report(policy):
            log.info("episodes %d-%d%s", first_index, first_index + len(seeds) - 1, report)
        return results
    finally:
        env.close()


# =========================================================================== entry point
def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="so101-run-policy", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("policy", help="a LeRobot policy: a pretrained_model directory or a Hugging Face Hub id")
    p.add_argument(
        "--fps", type=float, default=contract.CONTROL_RATE, help="control rate: the fps of the policy's training dataset"
    )
    p.add_argument(
        "--units",
        choices=["lerobot", "radians"],
        default="lerobot",
        help="joint units the policy was trained in (so101-bag-to-lerobot's default is lerobot)",
    )
    p.add_argument(
        "--action-space",
        choices=["auto", "joint", "ee"],
        default="auto",
        help="what the policy's actions are: joint targets, or end-effector targets (x y z m, pitch roll rad, "
        "gripper; so101.ee) turned into joint targets by the IK; auto: ee when the policy reads "
        "observation.ee_state (a dataset converted with --action-space ee)",
    )
    p.add_argument(
        "--task", default=None, help="task text for language-conditioned policies (default: the --sim-task's description)"
    )
    p.add_argument("--device", default=None, help="torch device (default: cuda when available, else cpu)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    live = p.add_argument_group("live")
    live.add_argument("--namespace", default="", help="the arm's namespace (topics under /NAMESPACE/)")
    live.add_argument(
        "--camera",
        action="append",
        default=[],
        metavar="NAME=TOPIC",
        help="take the policy's camera NAME from TOPIC (default /camera/NAME/image_raw; a TOPIC ending in "
        "/compressed carries JPEG frames)",
    )
    live.add_argument(
        "--compressed",
        action="store_true",
        help="take every camera's JPEG frames from /camera/NAME/image_raw/compressed (what so101_camera_node "
        "publishes unless started with --raw)",
    )
    live.add_argument("--duration", type=float, default=0.0, help="stop after this many seconds (0: at Ctrl-C)")
    live.add_argument("--max-age", type=float, default=0.5, help="inputs older than this (s) hold the arm")
    live.add_argument("--startup-timeout", type=float, default=30.0, help="seconds to wait for the first inputs")
    live.add_argument("--reset", action="store_true", help="call /sim/reset first (simulation)")
    ev = p.add_argument_group("evaluation (own sim in lockstep)")
    ev.add_argument("--eval", type=int, default=0, metavar="N", help="evaluate over N seeded episodes instead")
    ev.add_argument("--seed", type=int, default=0, help="seed of the first episode (then seed+1, ...)")
    ev.add_argument(
        "--episode-time",
        type=float,
        default=None,
        help="sim seconds before an episode counts as failed (default: the --sim-task's episode length)",
    )
    ev.add_argument(
        "--sim-task",
        default="cube_to_bin",
        choices=list(contract.TASKS),
        help="the sim's task (its description: --task's default)",
    )
    ev.add_argument(
        "--backend",
        default="ros",
        choices=["ros", "inprocess"],
        help="ros: so101_sim_node in lockstep through the topic contract (the stack's real interface); "
        "inprocess: the same simulation core in this process (faster, no ROS)",
    )
    ev.add_argument(
        "--reward",
        choices=["dense", "sparse"],
        default=None,
        help="the sim's reward, one the task offers (contract.TASKS); default: dense where the task has it, "
        "which shows how close a failed episode came",
    )
    ev.add_argument("--lite", action="store_true", help="sim without meshes (faster to render on a CPU)")
    sim_options.add_arguments(ev)
    ev.add_argument(
        "--video-camera",
        default=None,
        help="film this camera (320x240) instead of the policy's cameras (default for a policy without cameras: front)",
    )
    ev.add_argument(
        "--videos", type=int, default=None, metavar="K", help="film only the first K episodes (default: every episode)"
    )
    ev.add_argument(
        "--workers",
        type=int,
        default=1,
        metavar="K",
        help="split the episodes over K processes, each with its own policy and sim (--backend inprocess); "
        "eval_info.json is the same as one process's",
    )
    ev.add_argument("--output", default="eval", help="directory for eval_info.json and videos/")
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    for item in args.camera:
        if "=" not in item:
            raise SystemExit(f"so101-run-policy: --camera {item!r}: expected NAME=TOPIC")
    if args.fps <= 0:
        raise SystemExit("so101-run-policy: --fps must be positive")
    if args.videos is not None and args.videos < 0:
        raise SystemExit("so101-run-policy: --videos must not be negative")
    if args.episode_time is None:
        facts = contract.TASKS[args.sim_task]
        args.episode_time = facts.episode_steps / facts.control_rate
    if args.episode_time <= 0:
        raise SystemExit("so101-run-policy: --episode-time must be positive")
    if args.workers < 1:
        raise SystemExit("so101-run-policy: --workers must be at least 1")
    if args.workers > 1 and args.backend != "inprocess":
        raise SystemExit("so101-run-policy: --workers needs --backend inprocess (each worker simulates in its own process)")
    modes = contract.TASKS[args.sim_task].reward_modes
    args.reward = args.reward or reward_mode(args.sim_task, dense_reward=True)
    if args.reward not in modes:
        raise SystemExit(f"so101-run-policy: {args.sim_task} has no {args.reward} reward (it offers: {', '.join(modes)})")
    if args.eval > 0 and args.workers > 1:
        from . import parallel

        # The workers' imports (LeRobot, torch: seconds of CPU) beside this process's own.
        parallel.start_fork_server(evaluate_share, preload=("lerobot.policies.factory",))
    try:
        policy = load_policy(args)
        return evaluate(args, policy) if args.eval > 0 else run_live(args, policy)
    except PolicyError as error:
        # Loading or a non-finite action: the runner stops sending, the arm's node holds.
        raise SystemExit(f"so101-run-policy: {error}") from error


if __name__ == "__main__":
    sys.exit(main())
