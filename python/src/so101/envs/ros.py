"""The ROS backend of the Gymnasium environments (`gym.make("so101/CubeToBin-v0", backend="ros")`,
so101.envs.registry): so101_sim_node in lockstep, started by the environment under a namespace of
its own, driven through rclpy. Each action is published on /joint_commands; the node runs with
--step-on-command, so that message advances exactly one control period and the state it leads to
is published before the next command is taken (no /sim/step call, no waiting on a timer).
Stable-Baselines3, imitation and the like then run against the stack's real interface.

Must run inside the network namespace of scripts/isolated (DDS traffic stays on the machine).
Observations, actions, rewards, termination and info are those of the in-process backend
(so101.envs.spaces, so101.envs.inprocess), each camera rendered by the sim at the instant of the
state. A seeded reset restarts the node with the seed (the in-process backend restarts nothing).
rclpy is imported when an env is built, not with this module.
"""

from __future__ import annotations

import itertools
import json
import logging
import os
import subprocess
import tempfile
import time
import uuid

import gymnasium as gym
import numpy as np

from .. import contract
from ..messages import joint_positions, rgb_image
from ..paths import node_binary, node_environment
from ..sim_options import DEFAULT_SERVO_MODEL, camera_poses_spec, randomize_spec, servo_params_spec
from ..stack import process
from ..units import JOINT_NAMES
from .spaces import action_space, checked_action, observation_from_state, observation_space, task_facts

log = logging.getLogger(__name__)

# A node just started can run the first /sim/reset and lose its reply: the service's reply writer
# may not have matched this client yet (seen on a loaded 2-core machine, about once in 50
# episodes). Such a reset is retried on a restarted node with the same seed, so the episode is
# the same one.
FIRST_RESET_TIMEOUT_S = 5.0
FIRST_RESET_ATTEMPTS = 3


class So101RosEnv(gym.Env):
    metadata = {"render_modes": []}

    def __init__(
        self,
        task: str = "cube_to_bin",
        control_rate: float | None = None,  # None: the task's
        lite: bool = True,
        timeout: float = 20.0,
        cameras: dict[str, tuple[int, int]] | None = None,
        dense_reward: bool = False,
        servo_params: str | os.PathLike = DEFAULT_SERVO_MODEL,
        randomize: bool | str | os.PathLike = False,
        camera_poses: str | os.PathLike | None = None,
    ):
        # An unknown task or option is refused before anything starts.
        facts = task_facts(task)
        servo_params, randomize = servo_params_spec(servo_params), randomize_spec(randomize)
        self._camera_poses = camera_poses_spec(camera_poses)
        self.action_space = action_space()
        self._cameras = {name: (int(h), int(w)) for name, (h, w) in (cameras or {}).items()}
        self.observation_space = observation_space(self._cameras)
        self._task, self._rate, self._lite, self._timeout = (
            task,
            facts.control_rate if control_rate is None else control_rate,
            lite,
            timeout,
        )
        self._terminates_on_success = facts.terminates_on_success
        self._dense_reward = dense_reward
        self._servo_params, self._randomize = servo_params, randomize
        self._namespace = f"gym_{os.getpid()}_{uuid.uuid4().hex[:8]}"
        self._process: subprocess.Popen | None = None
        self._log = tempfile.NamedTemporaryFile(prefix="so101_gym_sim_", suffix=".log", delete=False)
        self._latest: dict = {}
        self._counts = {"state": 0, "cube": 0, "reward": 0, "success": 0}
        self._counts.update({f"camera/{name}": 0 for name in self._cameras})
        self._awaited = None  # (counts to exceed, future) of the observation being waited for
        self._episode_settings: list[str] = []  # /sim/episode messages, latest last
        self._open_ros()
        # Each command is one step (the node's --step-on-command); the benchmark's "before" row
        # clears it to measure the previous /sim/step protocol.
        self.node_flags = ["--step-on-command"]

    def _open_ros(self) -> None:
        """An rclpy context (its own DDS participant) with the env's subscriptions, command
        publisher and reset client."""
        import rclpy
        from geometry_msgs.msg import PoseStamped
        from rclpy.experimental import EventsExecutor
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import Image, JointState
        from std_msgs.msg import Bool, Float64, String
        from std_srvs.srv import Trigger

        self._context = rclpy.Context()
        rclpy.init(context=self._context)
        self._node = rclpy.create_node("so101_gym", context=self._context, start_parameter_services=False)
        self._executor = EventsExecutor(context=self._context)
        self._executor.add_node(self._node)
        ns = f"/{self._namespace}"

        def keep(key):
            def callback(msg):
                self._latest[key] = msg
                if key in self._counts:
                    self._counts[key] += 1
                    if self._awaited is not None and self._counted_past(self._awaited[0]):
                        self._awaited[1].set_result(True)

            return callback

        self._node.create_subscription(JointState, f"{ns}/{contract.JOINT_STATES}", keep("state"), 10)
        self._node.create_subscription(PoseStamped, f"{ns}/{contract.CUBE_POSE}", keep("cube"), 10)
        self._node.create_subscription(Float64, f"{ns}/{contract.TASK_REWARD}", keep("reward"), 10)
        self._node.create_subscription(Bool, f"{ns}/{contract.TASK_SUCCESS}", keep("success"), 10)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._node.create_subscription(
            String, f"{ns}/{contract.SIM_EPISODE}", lambda msg: self._episode_settings.append(msg.data), latched
        )
        for name in self._cameras:
            self._node.create_subscription(Image, f"{ns}/{contract.camera_topic(name)}", keep(f"camera/{name}"), 10)
        self._commands = self._node.create_publisher(JointState, f"{ns}/{contract.JOINT_COMMANDS}", 10)
        self._reset_client = self._node.create_client(Trigger, f"{ns}/{contract.SIM_RESET}")
        self._trigger = Trigger.Request
        self._JointState = JointState
        self._looking_since = time.monotonic()  # for the node's endpoints (_rediscover_if_blind)

    def _close_ros(self) -> None:
        import rclpy

        if self._context.ok():
            self._executor.shutdown(timeout_sec=1)
            self._node.destroy_node()
            rclpy.try_shutdown(context=self._context)

    def _reset_service_ready(self) -> bool:
        if self._reset_client.service_is_ready():
            return True
        self._rediscover_if_blind()
        return False

    def _rediscover_if_blind(self) -> bool:
        """Replaces the DDS participant when, REDISCOVER_AFTER_S after it opened or the node
        started, it has discovered no publisher of the node's /joint_states (so101.stack.discovery);
        True if it did."""
        from ..stack.discovery import blind_to

        if not blind_to(self._node, [f"/{self._namespace}/{contract.JOINT_STATES}"], self._looking_since):
            return False
        log.warning("no publisher of /%s/%s discovered: starting a fresh DDS participant", self._namespace, contract.JOINT_STATES)
        self._close_ros()
        self._open_ros()
        return True

    # ------------------------------------------------------------------ plumbing
    def _spin_until(self, predicate, what: str, timeout: float | None = None) -> None:
        timeout = self._timeout if timeout is None else timeout
        deadline = time.monotonic() + timeout
        while not predicate():
            if self._process is not None and self._process.poll() is not None:
                raise RuntimeError(f"so101_sim_node exited with {self._process.returncode} (log: {self._log.name})")
            if time.monotonic() > deadline:
                raise TimeoutError(f"no {what} from so101_sim_node within {timeout} s (log: {self._log.name})")
            self._executor.spin_once(timeout_sec=0.01)

    def _counted_past(self, counts: dict) -> bool:
        return all(self._counts[key] > counts[key] for key in self._counts)

    def _wait_for_messages(self, counts: dict, what: str) -> None:
        """Spins until every subscribed topic has a message after `counts`: one call into the
        executor per observation (its callbacks complete the future), not one per message."""
        from rclpy.task import Future

        if self._counted_past(counts):
            return
        future = Future()
        self._awaited = (counts, future)
        try:
            deadline = time.monotonic() + self._timeout
            while not future.done():
                if self._process is not None and self._process.poll() is not None:
                    raise RuntimeError(f"so101_sim_node exited with {self._process.returncode} (log: {self._log.name})")
                if time.monotonic() > deadline:
                    raise TimeoutError(f"no {what} from so101_sim_node within {self._timeout} s (log: {self._log.name})")
                self._executor.spin_until_future_complete(future, timeout_sec=0.5)
        finally:
            self._awaited = None

    def _call(self, client, what: str, timeout: float | None = None):
        future = client.call_async(self._trigger())
        self._spin_until(future.done, what, timeout)
        response = future.result()
        if not response.success:
            raise RuntimeError(f"{what} failed: {response.message}")
        return response

    def _start_sim(self, seed: int) -> None:
        self._stop_sim()
        binary = node_binary("so101_sim_node")
        cameras = ",".join(f"{name}:{w}x{h}" for name, (h, w) in self._cameras.items()) or "none"
        # One frame per camera per step: cameras render at the control rate, in lockstep at the
        # sim-time instant of each step's state.
        command = [
            str(binary),
            "--lockstep",
            *self.node_flags,
            "--rate",
            str(self._rate),
            "--task",
            self._task,
            "--seed",
            str(seed),
            "--cameras",
            cameras,
            "--camera-rate",
            str(self._rate),
            "--namespace",
            self._namespace,
            "--servo-params",
            self._servo_params,
            "--randomize",
            self._randomize,
        ]
        if self._lite:
            command.append("--lite")
        if self._camera_poses is not None:
            command += ["--camera-poses", self._camera_poses]
        if self._dense_reward:
            command.append("--dense-reward")
        self._process = process.start(command, env=node_environment(), stdout=self._log, stderr=self._log)
        self._looking_since = time.monotonic()
        self._spin_until(self._reset_service_ready, "/sim/reset")
        self._spin_until(lambda: self._commands.get_subscription_count() > 0, "/joint_commands subscription")
        # Both directions of each service matched, and the start-up state taken in.
        settle = time.monotonic() + 0.5
        while time.monotonic() < settle:
            self._executor.spin_once(timeout_sec=0.01)

    def _restart_and_reset(self, seed: int) -> dict:
        """Starts the sim with `seed` and resets it; the counters before the reset that answered."""
        for attempt in itertools.count(1):
            self._start_sim(seed)
            counts = dict(self._counts)
            try:
                self._call(self._reset_client, "/sim/reset", timeout=FIRST_RESET_TIMEOUT_S)
                return counts
            except TimeoutError:
                if attempt == FIRST_RESET_ATTEMPTS:
                    raise
                log.warning("no reply to the first /sim/reset of a new sim node (seed %d): restarting it", seed)

    def _stop_sim(self) -> None:
        if self._process is not None:
            process.stop(self._process)
        self._process = None
        self._latest.clear()

    def _observe(self, counts: dict):
        """The observation of what the sim published after `counts` (the counters before a step or
        reset): in lockstep nothing else is published in between."""
        self._wait_for_messages(counts, "state of the step")
        state, cube = self._latest["state"], self._latest["cube"].pose
        velocity_of = dict(zip(state.name, state.velocity))
        positions = joint_positions(state)
        if positions is None:
            raise RuntimeError(f"/joint_states names {list(state.name)}, not the six joints")
        velocities = [velocity_of.get(name, 0.0) for name in JOINT_NAMES]
        p, q = cube.position, cube.orientation
        vector = np.array([*positions, *velocities, p.x, p.y, p.z, q.w, q.x, q.y, q.z], dtype=np.float64)
        if not self._cameras:
            return observation_from_state(vector, None)
        pixels = {}
        for name, (h, w) in self._cameras.items():
            image = rgb_image(self._latest[f"camera/{name}"])
            if image.shape != (h, w, 3):
                raise RuntimeError(f"camera {name}: {image.shape[1]}x{image.shape[0]} frame, expected {w}x{h}")
            pixels[name] = image
        return observation_from_state(vector, pixels)

    # ------------------------------------------------------------------ gymnasium
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        settings_seen = len(self._episode_settings)
        if seed is not None or self._process is None:
            # A seed restarts the sim with it, so the same seed gives the same episodes. The
            # latched topic keeps one message: a subscriber matched late sees only the newest.
            self._episode_settings.clear()
            settings_seen = 0
            counts = self._restart_and_reset(seed if seed is not None else 0)
        else:
            counts = dict(self._counts)
            self._call(self._reset_client, "/sim/reset")
        observation = self._observe(counts)

        def reset_settings_arrived() -> bool:
            if len(self._episode_settings) <= settings_seen:
                return False
            # With randomization, the node's message from before any reset has no draw.
            return self._randomize == "off" or json.loads(self._episode_settings[-1])["draw"] is not None

        # The node publishes the episode's settings before it answers the reset.
        self._spin_until(reset_settings_arrived, "/sim/episode")
        settings = json.loads(self._episode_settings[-1])
        return observation, {"is_success": bool(self._latest["success"].data), "episode_settings": settings}

    def step(self, action):
        # Not clamped here: the node clamps to the scene's joint limits, as in-process.
        action = checked_action(action)
        counts = dict(self._counts)
        # With --step-on-command this message is the step: the node answers with its state.
        self._commands.publish(self._JointState(name=JOINT_NAMES, position=[float(v) for v in action]))
        observation = self._observe(counts)
        success = bool(self._latest["success"].data)
        terminated = success and self._terminates_on_success
        return observation, float(self._latest["reward"].data), terminated, False, {"is_success": success}

    def close(self):
        self._stop_sim()
        self._close_ros()
        self._log.close()
