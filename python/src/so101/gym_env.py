"""Gymnasium environments over so101_sim_node in lockstep: `so101/CubeToBin-v0` and
`so101/TouchCube-v0`, registered by `import so101`
(`gym.make("so101:so101/CubeToBin-v0")` imports it by itself). Each environment
starts its own sim node, under a namespace of its own, and talks to it through rclpy: a step publishes the action on /joint_commands and calls
/sim/step, so Stable-Baselines3, imitation and the like run against the stack's real interface.

Must run inside the network namespace of scripts/isolated (DDS traffic stays on the machine).
Observation (float32[19]): joint positions (6, rad), joint velocities (6, rad/s), cube position
(3, m, world), cube orientation (4, w x y z). With `cameras={"top": (height, width), ...}` the
observation is a dict: {"state": that vector, "pixels": {camera: uint8[H, W, 3]}}, each camera
rendered by the sim at the instant of the state. Action (float32[6]): joint position targets (rad),
within the joint limits. Reward: /task/reward; terminated: /task/success (cube_to_bin); episodes
are truncated by the registration's max_episode_steps.
"""

from __future__ import annotations

import os
import subprocess
import tempfile
import time
import uuid

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from . import contract, process
from .messages import joint_positions, rgb_image
from .paths import node_binary, node_environment
from .units import JOINT_LIMITS, JOINT_NAMES


class So101SimEnv(gym.Env):
    metadata = {"render_modes": []}

    def __init__(
        self,
        task: str = "cube_to_bin",
        control_rate: float = 30.0,
        lite: bool = True,
        timeout: float = 20.0,
        cameras: dict[str, tuple[int, int]] | None = None,
        dense_reward: bool = False,
    ):
        import rclpy
        from geometry_msgs.msg import PoseStamped
        from rclpy.executors import SingleThreadedExecutor
        from sensor_msgs.msg import Image, JointState
        from std_msgs.msg import Bool, Float64
        from std_srvs.srv import Trigger

        self.action_space = spaces.Box(
            JOINT_LIMITS[:, 0].astype(np.float32), JOINT_LIMITS[:, 1].astype(np.float32), dtype=np.float32
        )
        state_space = spaces.Box(-np.inf, np.inf, shape=(19,), dtype=np.float32)
        self._cameras = dict(cameras or {})
        if self._cameras:
            pixels = {name: spaces.Box(0, 255, shape=(h, w, 3), dtype=np.uint8) for name, (h, w) in self._cameras.items()}
            self.observation_space = spaces.Dict({"state": state_space, "pixels": spaces.Dict(pixels)})
        else:
            self.observation_space = state_space
        self._task, self._rate, self._lite, self._timeout = task, control_rate, lite, timeout
        self._dense_reward = dense_reward
        self._namespace = f"gym_{os.getpid()}_{uuid.uuid4().hex[:8]}"
        self._process: subprocess.Popen | None = None
        self._log = tempfile.NamedTemporaryFile(prefix="so101_gym_sim_", suffix=".log", delete=False)
        self._context = rclpy.Context()
        rclpy.init(context=self._context)
        self._node = rclpy.create_node("so101_gym", context=self._context, start_parameter_services=False)
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self._node)
        ns = f"/{self._namespace}"
        self._latest: dict = {}
        self._counts = {"state": 0, "cube": 0, "reward": 0, "success": 0}
        self._counts.update({f"camera/{name}": 0 for name in self._cameras})

        def keep(key):
            def callback(msg):
                self._latest[key] = msg
                if key in self._counts:
                    self._counts[key] += 1

            return callback

        self._node.create_subscription(JointState, f"{ns}/{contract.JOINT_STATES}", keep("state"), 10)
        self._node.create_subscription(PoseStamped, f"{ns}/{contract.CUBE_POSE}", keep("cube"), 10)
        self._node.create_subscription(Float64, f"{ns}/{contract.TASK_REWARD}", keep("reward"), 10)
        self._node.create_subscription(Bool, f"{ns}/{contract.TASK_SUCCESS}", keep("success"), 10)
        for name in self._cameras:
            self._node.create_subscription(Image, f"{ns}/{contract.camera_topic(name)}", keep(f"camera/{name}"), 10)
        self._commands = self._node.create_publisher(JointState, f"{ns}/{contract.JOINT_COMMANDS}", 10)
        self._step_client = self._node.create_client(Trigger, f"{ns}/{contract.SIM_STEP}")
        self._reset_client = self._node.create_client(Trigger, f"{ns}/{contract.SIM_RESET}")
        self._trigger = Trigger.Request
        self._head_start = 0.002  # s between a command and its step call, doubled when one is late
        self._sent = 0  # commands published to the current sim
        self.late_commands = 0  # steps that ran before their command arrived
        self._JointState = JointState

    # ------------------------------------------------------------------ plumbing
    def _spin_until(self, predicate, what: str) -> None:
        deadline = time.monotonic() + self._timeout
        while not predicate():
            if self._process is not None and self._process.poll() is not None:
                raise RuntimeError(f"so101_sim_node exited with {self._process.returncode} (log: {self._log.name})")
            if time.monotonic() > deadline:
                raise TimeoutError(f"no {what} from so101_sim_node within {self._timeout} s (log: {self._log.name})")
            self._executor.spin_once(timeout_sec=0.01)

    def _call(self, client, what: str):
        future = client.call_async(self._trigger())
        self._spin_until(future.done, what)
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
        ]
        if self._lite:
            command.append("--lite")
        if self._dense_reward:
            command.append("--dense-reward")
        self._sent = 0
        self._process = process.start(command, env=node_environment(), stdout=self._log, stderr=self._log)
        self._spin_until(lambda: self._step_client.service_is_ready() and self._reset_client.service_is_ready(), "services")
        self._spin_until(lambda: self._commands.get_subscription_count() > 0, "/joint_commands subscription")
        # Both directions of each service matched, and the start-up state taken in.
        settle = time.monotonic() + 0.5
        while time.monotonic() < settle:
            self._executor.spin_once(timeout_sec=0.01)

    def _stop_sim(self) -> None:
        if self._process is not None:
            process.stop(self._process)
        self._process = None
        self._latest.clear()

    def _observe(self, counts: dict):
        """The observation of what the sim published after `counts` (the counters before a step or
        reset): in lockstep nothing else is published in between."""
        self._spin_until(lambda: all(self._counts[key] > counts[key] for key in self._counts), "state of the step")
        state, cube = self._latest["state"], self._latest["cube"].pose
        velocity_of = dict(zip(state.name, state.velocity))
        positions = joint_positions(state)
        if positions is None:
            raise RuntimeError(f"/joint_states names {list(state.name)}, not the six joints")
        velocities = [velocity_of.get(name, 0.0) for name in JOINT_NAMES]
        p, q = cube.position, cube.orientation
        vector = np.array([*positions, *velocities, p.x, p.y, p.z, q.w, q.x, q.y, q.z], dtype=np.float32)
        if not self._cameras:
            return vector
        pixels = {}
        for name, (h, w) in self._cameras.items():
            image = rgb_image(self._latest[f"camera/{name}"])
            if image.shape != (h, w, 3):
                raise RuntimeError(f"camera {name}: {image.shape[1]}x{image.shape[0]} frame, expected {w}x{h}")
            pixels[name] = image
        return {"state": vector, "pixels": pixels}

    # ------------------------------------------------------------------ gymnasium
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if seed is not None or self._process is None:
            # A seed restarts the sim with it, so the same seed gives the same episodes.
            self._start_sim(seed if seed is not None else 0)
        counts = dict(self._counts)
        self._call(self._reset_client, "/sim/reset")
        return self._observe(counts), {}

    def step(self, action):
        action = np.asarray(action, dtype=np.float64)
        if action.shape != (6,) or not np.all(np.isfinite(action)):
            raise ValueError(f"an action is six finite joint targets, not {action}")
        action = np.clip(action, JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])
        counts = dict(self._counts)
        self._commands.publish(self._JointState(name=JOINT_NAMES, position=[float(v) for v in action]))
        self._sent += 1
        # A topic and a service are not ordered: give the command a head start over the step
        # call, and check in the answer (commands taken so far) that it made it into this step.
        time.sleep(self._head_start)
        answer = self._call(self._step_client, "/sim/step")
        taken = int(answer.message.rsplit("commands=", 1)[-1]) if "commands=" in answer.message else self._sent
        late = taken < self._sent
        if late:
            # The step ran with the previous action; a loaded machine: give commands longer.
            self.late_commands += 1
            self._head_start = min(0.02, self._head_start * 2)
            self._sent = taken + 1  # the late one is taken with the next step
        observation = self._observe(counts)
        success = bool(self._latest["success"].data)
        terminated = success and self._task == "cube_to_bin"
        return observation, float(self._latest["reward"].data), terminated, False, {"success": success, "command_late": late}

    def close(self):
        import rclpy

        self._stop_sim()
        if self._context.ok():
            self._executor.shutdown(timeout_sec=1)
            self._node.destroy_node()
            rclpy.try_shutdown(context=self._context)
        self._log.close()


def register_envs() -> None:
    """Registers the environments (`import so101` does)."""
    ids = {"so101/CubeToBin-v0": ("cube_to_bin", 600), "so101/TouchCube-v0": ("touch_cube", 300)}
    for env_id, (task, steps) in ids.items():
        if env_id not in gym.registry:
            gym.register(env_id, entry_point="so101.gym_env:So101SimEnv", kwargs={"task": task}, max_episode_steps=steps)
