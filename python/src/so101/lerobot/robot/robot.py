"""SO101ROS: the LeRobot Robot over the stack's topics (rclpy imported only in connect())."""

from __future__ import annotations

import gc
import logging
import threading
import time
from functools import cached_property
from typing import Any

import numpy as np
from lerobot.robots import Robot

from ...ee import EE_FEATURE_NAMES
from ...units import FEATURE_NAMES, JOINT_NAMES, lerobot_from_radians
from .actions import command_from_action, command_from_ee_action
from .config import SO101ROSConfig

log = logging.getLogger(__name__)


class SO101ROS(Robot):
    config_class = SO101ROSConfig
    name = "so101_ros"

    def __init__(self, config: SO101ROSConfig):
        super().__init__(config)
        self.config = config
        self.cameras = dict(config.cameras)  # lerobot-record takes len(robot.cameras)
        self._lock = threading.Lock()
        self._state: np.ndarray | None = None  # latest /joint_states, rad
        self._state_time = 0.0  # when it came (time.monotonic)
        self._frames: dict[str, Any] = {}  # latest sensor_msgs/Image per camera
        self._goal: np.ndarray | None = None  # last command sent, rad
        self._ee_target: np.ndarray | None = None  # action_space "ee": the last end-effector target asked for
        self._context = self._node = self._executor = self._thread = self._publisher = None
        self._froze_heap = False  # connect() froze the garbage collector's heap; disconnect() thaws it

    @cached_property
    def observation_features(self) -> dict:
        features: dict = {key: float for key in FEATURE_NAMES}
        features.update({name: (c.height, c.width, 3) for name, c in self.config.cameras.items()})
        return features

    @cached_property
    def action_features(self) -> dict:
        return {key: float for key in (EE_FEATURE_NAMES if self.config.action_space == "ee" else FEATURE_NAMES)}

    @property
    def is_connected(self) -> bool:
        return self._node is not None

    @property
    def is_calibrated(self) -> bool:
        return True  # the driver node owns the calibration

    def calibrate(self) -> None:
        pass

    def configure(self) -> None:
        pass

    # ---- connection
    def connect(self, calibrate: bool = True) -> None:
        if self.is_connected:
            raise RuntimeError(f"{self} is already connected")
        self._open()
        try:
            self._wait_for_inputs()
        except Exception:
            self.disconnect()
            raise
        self._freeze_heap()

    def _freeze_heap(self) -> None:
        """A control loop follows connect() (lerobot-record, -teleoperate, -replay, robot_client), on
        its own clock: one full collection of the heap torch, LeRobot and the dataset built (up to
        280 ms measured with both cores busy) stalls a period, and lerobot-record drops its frame.
        Collected once here, then frozen (gc.freeze), that heap is not scanned again."""
        gc.collect()
        gc.freeze()
        self._froze_heap = True

    def _open(self) -> None:
        """A fresh rclpy context (its own DDS participant) with this robot's subscriptions, its
        command publisher and a thread spinning them."""
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import qos_profile_sensor_data
        from sensor_msgs.msg import CompressedImage, Image, JointState

        from ...messages import joint_positions

        with self._lock:
            self._state, self._frames, self._goal, self._ee_target = None, {}, None, None
        self._context = rclpy.Context()
        rclpy.init(context=self._context)  # a private context installs no signal handlers
        node = rclpy.create_node(
            self.config.node_name, namespace=self.config.namespace or None, context=self._context, start_parameter_services=False
        )
        self._node = node

        def on_state(msg) -> None:
            positions = joint_positions(msg)
            if positions is not None:
                with self._lock:
                    self._state, self._state_time = positions, time.monotonic()

        def on_frame(name: str, msg) -> None:
            with self._lock:
                self._frames[name] = msg

        node.create_subscription(JointState, self.config.joint_states_topic, on_state, qos_profile_sensor_data)
        for name, camera in self.config.cameras.items():
            kind = CompressedImage if camera.compressed else Image
            node.create_subscription(kind, camera.topic, lambda msg, name=name: on_frame(name, msg), qos_profile_sensor_data)
        self._publisher = node.create_publisher(JointState, self.config.joint_commands_topic, 10)
        self._joint_state_type = JointState
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(node)
        self._thread = threading.Thread(target=self._spin, name="so101_ros-spin", daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        executor, context = self._executor, self._context
        while context.ok():
            try:
                executor.spin_once(timeout_sec=0.05)
            except Exception:  # noqa: BLE001 - the context is shutting down
                if not context.ok():
                    return
                raise

    def _missing_inputs(self) -> list[str]:
        with self._lock:
            missing = [] if self._state is not None else [self._resolved(self.config.joint_states_topic)]
            missing += [self._resolved(c.topic) for n, c in self.config.cameras.items() if n not in self._frames]
        return missing

    def _wait_for_inputs(self) -> None:
        from ...stack.discovery import REDISCOVER_AFTER_S, blind_to, publishers_seen

        deadline = time.monotonic() + self.config.connect_timeout_s
        opened, participants = time.monotonic(), 1
        while missing := self._missing_inputs():
            now = time.monotonic()
            if now > deadline:
                raise TimeoutError(
                    f"so101_ros: nothing on {', '.join(missing)} within {self.config.connect_timeout_s} s "
                    f"({publishers_seen(self._node, missing)}, by the last of {participants} DDS participant(s); "
                    "is so101_sim_node or so101_feetech_driver running in this namespace and ROS domain?)"
                )
            if unseen := blind_to(self._node, missing, opened):
                # The node may be absent, or this participant's discovery missed it (so101.stack.discovery).
                log.warning(
                    "so101_ros: no publisher of %s discovered in %.0f s: starting a fresh DDS participant",
                    ", ".join(unseen),
                    REDISCOVER_AFTER_S,
                )
                self.disconnect()
                self._open()
                opened, participants = time.monotonic(), participants + 1
            time.sleep(0.02)
        from ...messages import image_size

        for name, camera in self.config.cameras.items():
            width, height = image_size(self._frames[name])
            if (height, width) != (camera.height, camera.width):
                raise ValueError(
                    f"so101_ros: camera {name!r} ({self._resolved(camera.topic)}) sends {width}x{height} frames, "
                    f"the config declares {camera.width}x{camera.height}"
                )

    def _resolved(self, topic: str) -> str:
        return self._node.resolve_topic_name(topic) if self._node is not None else topic

    def disconnect(self) -> None:
        """Idempotent (replay, teleoperate and robot_client call it unconditionally)."""
        if self._node is None:
            return
        import rclpy

        context, self._context = self._context, None
        rclpy.try_shutdown(context=context)
        if self._thread is not None:
            self._thread.join(timeout=5)
        self._executor.shutdown(timeout_sec=1)
        self._node.destroy_node()
        self._node = self._executor = self._thread = self._publisher = None
        if self._froze_heap:
            gc.unfreeze()
            self._froze_heap = False

    # ---- I/O
    def get_observation(self) -> dict[str, Any]:
        if not self.is_connected:
            raise RuntimeError(f"{self} is not connected")
        from ...messages import rgb_image

        with self._lock:
            state, age, frames = self._state, time.monotonic() - self._state_time, dict(self._frames)
        if age > self.config.connect_timeout_s:
            raise TimeoutError(
                f"so101_ros: no {self._resolved(self.config.joint_states_topic)} for {age:.1f} s (did the sim or driver stop?)"
            )
        observation: dict[str, Any] = {key: float(value) for key, value in zip(FEATURE_NAMES, lerobot_from_radians(state))}
        for name in self.config.cameras:
            observation[name] = rgb_image(frames[name])
        return observation

    def send_action(self, action: dict[str, Any]) -> dict[str, float]:
        if not self.is_connected:
            raise RuntimeError(f"{self} is not connected")
        with self._lock:
            present = self._state
        hold = self._goal if self._goal is not None else present
        if self.config.action_space == "ee":
            command = command_from_ee_action(action, hold, present, self.config.max_relative_target, self._ee_target)
            if command.clamped:
                log.debug("so101_ros: end-effector action %s out of reach: the nearest pose commanded", action)
            radians, sent, self._ee_target = command.radians, command.sent, command.target
        else:
            radians, sent = command_from_action(action, hold, present, self.config.max_relative_target)
        msg = self._joint_state_type()
        msg.header.stamp = self._node.get_clock().now().to_msg()
        msg.name = list(JOINT_NAMES)
        msg.position = [float(value) for value in radians]
        self._publisher.publish(msg)
        self._goal = radians
        return sent
