#!/usr/bin/env python3
"""The sim demo: start so101_sim_node with its demo and watch it from an rclpy node.

Prints once a second what a ROS 2 user would see on the topics: sim time, joint positions, the
cube's position, the task's reward and success, and the frames per second of each camera. Must run inside a private network namespace
(scripts/run_sim_demo.sh takes care of it).
"""

import argparse
import signal
import sys
import time

import rclpy
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from sensor_msgs.msg import Image, JointState
from std_msgs.msg import Bool, Float64

from so101 import contract
from so101.contract import CAMERA_NAMES
from so101.messages import stamp_seconds
from so101.paths import node_environment
from so101.stack import process

CAMERAS = CAMERA_NAMES
SHORT_NAMES = {
    "shoulder_pan": "pan",
    "shoulder_lift": "lift",
    "elbow_flex": "elbow",
    "wrist_flex": "wrist",
    "wrist_roll": "roll",
    "gripper": "grip",
}


class Watcher(Node):
    def __init__(self):
        super().__init__("sim_watcher")
        self.joints = None
        self.cube = None
        self.reward = None
        self.success = False
        self.successes = 0
        self.create_subscription(JointState, f"/{contract.JOINT_STATES}", self._on_joints, 10)
        self.create_subscription(PoseStamped, f"/{contract.CUBE_POSE}", self._on_cube, 10)
        self.create_subscription(Float64, f"/{contract.TASK_REWARD}", self._on_reward, 10)
        self.create_subscription(Bool, f"/{contract.TASK_SUCCESS}", self._on_success, 10)
        self.frames = {name: 0 for name in CAMERAS}
        self.frames_at_last_line = dict(self.frames)
        for name in CAMERAS:
            self.create_subscription(Image, f"/{contract.camera_topic(name)}", lambda _msg, n=name: self._on_frame(n), 2)

    def _on_frame(self, name):
        self.frames[name] += 1

    def _on_joints(self, msg):
        self.joints = msg

    def _on_cube(self, msg):
        self.cube = msg.pose.position

    def _on_reward(self, msg):
        self.reward = msg.data

    def _on_success(self, msg):
        if msg.data and not self.success:
            self.successes += 1
        self.success = msg.data

    def line(self):
        if self.joints is None:
            return "waiting for /joint_states ..."
        stamp = stamp_seconds(self.joints)
        joints = " ".join(f"{SHORT_NAMES.get(n, n)}={p:+.2f}" for n, p in zip(self.joints.name, self.joints.position))
        cube = f"cube=({self.cube.x:.3f},{self.cube.y:.3f},{self.cube.z:.3f})" if self.cube else "cube=?"
        cameras = " ".join(f"{name}={self.frames[name] - self.frames_at_last_line[name]}" for name in CAMERAS)
        self.frames_at_last_line = dict(self.frames)
        return (
            f"t={stamp:7.2f}s {joints} {cube} reward={self.reward if self.reward is not None else float('nan'):.2f}"
            f" in_bin={self.success} drops_in_bin={self.successes} frames/s: {cameras}"
        )


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--node", required=True, help="path of the so101_sim_node binary")
    parser.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    args, node_flags = parser.parse_known_args()

    sim = process.start([args.node, "--demo", *node_flags], env=node_environment(), stdin=None)
    rclpy.init()
    watcher = Watcher()
    stop = {"now": False}
    signal.signal(signal.SIGINT, lambda *_: stop.update(now=True))
    signal.signal(signal.SIGTERM, lambda *_: stop.update(now=True))
    start = next_print = time.monotonic()
    try:
        while not stop["now"] and sim.poll() is None:
            rclpy.spin_once(watcher, timeout_sec=0.1)
            if time.monotonic() >= next_print:
                print(watcher.line(), flush=True)
                next_print += 1.0
            if args.duration is not None and time.monotonic() - start > args.duration:
                break
    finally:
        code = process.stop(sim)
        watcher.destroy_node()
        rclpy.shutdown()
    frames = ", ".join(f"{name} {count}" for name, count in watcher.frames.items())
    print(
        f"so101_sim_node exited with {code}; cube dropped in the bin {watcher.successes} time(s); camera frames received: {frames}"
    )
    return 0 if code == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
