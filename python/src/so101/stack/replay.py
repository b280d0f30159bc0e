"""so101-replay: send the recorded actions of one episode, from a LeRobot dataset or an episode
bag, to the arm (the sim or the real driver) on /joint_commands, at their recorded rate.

The arm is first brought from where it is to the episode's first action in --ramp seconds, so
the replay never starts with a jump. Run it inside scripts/isolated with the arm's node.

With --lockstep (a dataset on the sim node started with --lockstep --step-on-command --rate FPS,
the dataset's fps), each action is one period of the sim, the next sent once that period's state
is in: the replay's physics is then the same whatever the machine's load.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from .. import contract
from ..messages import stamp_seconds
from ..units import JOINT_NAMES, radians_from_lerobot
from .rclpy_wait import spin_until

# Lockstep: how long a step's state may take to come back, and how long the last action is held
# after the episode (a sim in real time goes on by itself: a released cube still has to fall).
STEP_TIMEOUT_S = 5.0
HOLD_AFTER_S = 1.0
# A sim period further than this from the dataset's frame period is refused: at the first step (one
# 2 ms physics step, the sim's rounding of a rate that does not divide 500 Hz, and some), and on
# average over the first PERIOD_STEPS steps (where that rounding evens out).
PERIOD_TOLERANCE_S = 0.0025
PERIOD_STEPS = 10
MEAN_PERIOD_TOLERANCE_S = 0.0004
# After the reset, a sim that publishes a state within this long without a command is not in lockstep.
OWN_PACE_WAIT_S = 0.3


def actions_from_dataset(root: Path, repo_id: str, episode: int, units: str) -> tuple[np.ndarray, np.ndarray]:
    """(seconds from the episode's start, actions in radians [N, 6]) of a dataset episode."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    dataset = LeRobotDataset(repo_id, root=root, episodes=[episode])
    names = dataset.meta.features["action"]["names"] or []
    if any(str(name).startswith("ee.") for name in names):
        raise SystemExit(
            f"so101-replay: {root}'s actions are end-effector targets ({', '.join(names)}), not joint targets: "
            "replay a dataset converted without --action-space ee"
        )
    frames = dataset.hf_dataset.with_format("numpy")
    actions = np.asarray(frames["action"], dtype=np.float64)
    if len(actions) == 0:
        raise SystemExit(f"so101-replay: episode {episode} of {root} has no frames")
    if units == "lerobot":
        actions = radians_from_lerobot(actions)
    return np.arange(len(actions)) / dataset.fps, actions


def actions_from_bag(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(seconds from the first command, commands in radians [N, 6]) of an episode bag."""
    from ..dataset.bags import BagError, read_episode

    try:
        episode = read_episode(path, cameras=[])
    except BagError as error:
        raise SystemExit(f"so101-replay: {error}") from error
    times = np.asarray(episode.joint_commands.times)
    return times - times[0], np.stack(episode.joint_commands.values)


class LockstepSender:
    """Sends one action per sim period and waits for the state it leads to (newer stamp); refuses
    a sim whose period is not the dataset's frame period (another --rate)."""

    def __init__(self, node, send, latest: dict, frame: float):
        self.node, self.send, self.latest, self.frame = node, send, latest, frame
        self.first = self.last = stamp_seconds(latest["state"])
        self.steps = 0

    def __call__(self, action: np.ndarray) -> None:
        self.send(action)
        if not spin_until(self.node, lambda: stamp_seconds(self.latest["state"]) > self.last, STEP_TIMEOUT_S):
            raise SystemExit(
                f"so101-replay: no state came back within {STEP_TIMEOUT_S:g} s of a command: is the sim in "
                "--lockstep --step-on-command?"
            )
        now = stamp_seconds(self.latest["state"])
        self.steps += 1
        if self.steps == 1 and abs(now - self.last - self.frame) > PERIOD_TOLERANCE_S:
            self.refuse(now - self.last)
        if self.steps == PERIOD_STEPS and abs((now - self.first) / PERIOD_STEPS - self.frame) > MEAN_PERIOD_TOLERANCE_S:
            self.refuse((now - self.first) / PERIOD_STEPS)
        self.last = now

    def refuse(self, period: float) -> None:
        raise SystemExit(
            f"so101-replay: the sim stepped {period:.4f} s per command, the dataset's frames are {self.frame:.4f} s "
            f"apart: start the sim with --rate {1 / self.frame:g}"
        )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="so101-replay", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("source", type=Path, help="a LeRobot dataset root, or an episode bag directory")
    parser.add_argument("--episode", type=int, default=0, help="dataset episode index")
    parser.add_argument("--repo-id", default="local/so101_cube_to_bin", help="the dataset's repo id")
    parser.add_argument("--units", choices=["lerobot", "radians"], default="lerobot", help="the dataset's joint units")
    parser.add_argument("--namespace", default="", help="the arm's namespace (topics under /NAMESPACE/)")
    parser.add_argument("--ramp", type=float, default=2.0, help="seconds to move to the first action")
    parser.add_argument("--reset", action="store_true", help="call /sim/reset first (simulation)")
    parser.add_argument(
        "--lockstep",
        action="store_true",
        help="with --reset, a dataset on a sim started with --lockstep --step-on-command --rate FPS (the dataset's fps): one sim "
        "period per action, the next sent once its state is in, so the replay does not depend on the machine's load; "
        f"the last action is then held {HOLD_AFTER_S:g} s",
    )
    args = parser.parse_args(argv)
    if args.lockstep and not args.reset:
        parser.error("--lockstep needs --reset: a sim in lockstep publishes its state only when it steps or resets")

    if (args.source / "meta" / "info.json").is_file():
        offsets, actions = actions_from_dataset(args.source, args.repo_id, args.episode, args.units)
    elif args.lockstep:
        parser.error("--lockstep replays a dataset (one frame per sim period), not a bag's commands at their arrival times")
    else:
        offsets, actions = actions_from_bag(args.source)
    if args.lockstep and len(offsets) < 2:
        parser.error(f"--lockstep: episode {args.episode} has one frame, no frame period to step the sim by")

    import rclpy
    from sensor_msgs.msg import JointState
    from std_srvs.srv import Trigger

    prefix = "/" + args.namespace.strip("/") if args.namespace.strip("/") else ""
    rclpy.init()
    node = rclpy.create_node("so101_replay")
    publisher = node.create_publisher(JointState, f"{prefix}/{contract.JOINT_COMMANDS}", 10)
    latest: dict = {}
    node.create_subscription(JointState, f"{prefix}/{contract.JOINT_STATES}", lambda m: latest.__setitem__("state", m), 10)

    def wait_for(predicate, timeout: float, what: str):
        if not spin_until(node, predicate, timeout):
            raise SystemExit(f"so101-replay: no {what} within {timeout:.0f} s (is the arm's node running?)")

    try:
        if args.lockstep:
            # The sim's one state after the reset reaches only a subscription it has matched.
            topic = f"{prefix}/{contract.JOINT_STATES}"
            wait_for(lambda: node.count_publishers(topic) > 0, 20.0, "/joint_states publisher")
            wait_for(lambda: publisher.get_subscription_count() > 0, 20.0, "subscriber of /joint_commands")
        if args.reset:
            client = node.create_client(Trigger, f"{prefix}/{contract.SIM_RESET}")
            wait_for(client.service_is_ready, 20.0, "/sim/reset service")
            # A sim in lockstep publishes the new episode's state once, before it answers; one in
            # real time goes on publishing, the state before the reset too.
            if args.lockstep:
                latest.clear()
            future = client.call_async(Trigger.Request())
            wait_for(future.done, 10.0, "/sim/reset answer")
            if not args.lockstep:
                latest.clear()
        wait_for(lambda: "state" in latest, 20.0, "/joint_states")
        wait_for(lambda: publisher.get_subscription_count() > 0, 20.0, "subscriber of /joint_commands")
        positions = dict(zip(latest["state"].name, latest["state"].position))
        start = np.array([positions[name] for name in JOINT_NAMES])

        def send(values: np.ndarray):
            publisher.publish(JointState(name=JOINT_NAMES, position=[float(v) for v in values]))

        if args.lockstep:
            reset_state = stamp_seconds(latest["state"])
            spin_until(node, lambda: stamp_seconds(latest["state"]) > reset_state, OWN_PACE_WAIT_S)
            if stamp_seconds(latest["state"]) > reset_state:
                raise SystemExit("so101-replay: the sim steps on its own: start it with --lockstep --step-on-command")
            frame = float(offsets[1] - offsets[0])
            count = max(1, round(args.ramp / frame))
            ramp = [start + (actions[0] - start) * k / count for k in range(1, count + 1)]
            hold = [actions[-1]] * round(HOLD_AFTER_S / frame)
            step = LockstepSender(node, send, latest, frame)
            for action in [*ramp, *actions, *hold]:
                step(action)
        else:
            period = 1.0 / 50
            ramp_steps = max(1, int(args.ramp / period))
            begun = time.monotonic()
            for k in range(1, ramp_steps + 1):
                send(start + (actions[0] - start) * k / ramp_steps)
                rclpy.spin_once(node, timeout_sec=max(0.0, begun + k * period - time.monotonic()))
            begun = time.monotonic()
            for offset, action in zip(offsets, actions):
                while (wait := begun + offset - time.monotonic()) > 0:
                    rclpy.spin_once(node, timeout_sec=wait)
                send(action)
        print(f"replayed {len(actions)} actions over {offsets[-1]:.1f} s")
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
