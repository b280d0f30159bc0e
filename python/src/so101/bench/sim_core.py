#!/usr/bin/env python3
"""Benchmark of the simulation core's front doors: Gymnasium env steps per second at 30 Hz control,
each compared in the same run with its anchor, as a ratio.

Rows (no camera; one 64x48 camera; one 320x240 camera):
- in-process env (`gym.make("so101/CubeToBin-v0")`, so101_native) against (a) the same lite scene
  stepped in-process with MuJoCo's own Python bindings (the `mujoco` wheel; the same physics steps
  per control period, ctrl written and qpos read every period, mujoco.Renderer for the camera),
  and (b) lerobot-env-so101 0.4.0 from PyPI (its pick-cube env at control_dt 1/30 s, 16 physics
  steps of 2 ms; installed on first use into ~/.cache/so101/bench-packages without its
  dependencies, so it never joins the venv's LeRobot plugins);
- the native batch (`gym.make_vec(..., num_envs=N)`) against the single in-process env;
- the ROS backend (so101_sim_node in lockstep over DDS, driven by rclpy) after (--step-on-command)
  and before (the previous protocol: the command, a 2 ms head start, then a /sim/step call).

Each measurement runs in a process of its own (two MuJoCo libraries never share one). DDS peers:
run inside scripts/isolated (scripts/bench.sh does). Targets: in-process >= 1.0x (a); batch >= 1.7x
the single env; ROS lockstep >= 1,000 env steps/s.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from so101 import contract
from so101.bench import common as bench_common
from so101.subcommands import Subcommand, run_alone

LERE_PACKAGE = "lerobot-env-so101==0.4.0"
CAMERAS = {"none": None, "64x48": (48, 64), "320x240": (240, 320)}
RATE = contract.CONTROL_RATE


def packages_dir() -> Path:
    return Path.home() / ".cache" / "so101" / "bench-packages"


def ensure_lerobot_env_so101() -> Path:
    target = packages_dir()
    if not (target / "lerobot_env_so101").is_dir():
        subprocess.run(
            [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(target), LERE_PACKAGE], check=True
        )
    return target


def timed(step, steps: int, warmup: int = 30) -> float:
    for _ in range(warmup):
        step()
    started = time.perf_counter()
    for _ in range(steps):
        step()
    return steps / (time.perf_counter() - started)


def random_actions(low, high, count: int, seed: int = 0) -> np.ndarray:
    """Targets that move the arm around (each held 15 periods), the same for every contender."""
    rng = np.random.default_rng(seed)
    waypoints = rng.uniform(low, high, size=(count // 15 + 1, len(low)))
    return np.repeat(waypoints, 15, axis=0)[:count]


# ---------------------------------------------------------------- contenders (one per process)
def measure_inprocess(camera, steps: int) -> float:
    import gymnasium as gym

    import so101  # noqa: F401

    cameras = {"top": camera} if camera else None
    env = gym.make("so101/CubeToBin-v0", cameras=cameras, max_episode_steps=None)
    env.reset(seed=0)
    actions = random_actions(env.action_space.low, env.action_space.high, steps + 30).astype(np.float32)
    index = iter(range(len(actions)))
    rate = timed(lambda: env.step(actions[next(index)]), steps)
    env.close()
    return rate


def measure_batch(camera, steps: int, num_envs: int) -> float:
    import gymnasium as gym

    import so101  # noqa: F401

    cameras = {"top": camera} if camera else None
    env = gym.make_vec("so101/CubeToBin-v0", num_envs=num_envs, cameras=cameras)
    env.reset(seed=0)
    low, high = env.single_action_space.low, env.single_action_space.high
    actions = np.stack([random_actions(low, high, steps + 30, seed) for seed in range(num_envs)], axis=1)
    index = iter(range(len(actions)))
    rate = timed(lambda: env.step(actions[next(index)]), steps)
    env.close()
    return rate * num_envs


def measure_mujoco_bindings(camera, steps: int) -> float:
    os.environ.setdefault("MUJOCO_GL", "egl")
    import mujoco
    import so101_native

    from so101.paths import asset
    from so101.units import JOINT_NAMES

    # The same lite scene text the in-process world loads, compiled by the wheel's MuJoCo.
    scene = asset("so101_cube_to_bin.xml")
    model = mujoco.MjModel.from_xml_string(so101_native.scene_xml(str(scene), lite=True))
    data = mujoco.MjData(model)
    qpos = [model.jnt_qposadr[model.joint(name).id] for name in JOINT_NAMES]
    actuators = [model.actuator(name).id for name in JOINT_NAMES]
    timestep = model.opt.timestep
    renderer = None
    if camera:
        model.vis.global_.offwidth = max(model.vis.global_.offwidth, camera[1])
        model.vis.global_.offheight = max(model.vis.global_.offheight, camera[0])
        renderer = mujoco.Renderer(model, camera[0], camera[1])
        # As the in-process world renders: no shadows, no reflections.
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
    low, high = model.jnt_range[[model.joint(name).id for name in JOINT_NAMES]].T
    actions = random_actions(low, high, steps + 30)
    period = [0]

    def step():
        k = period[0]
        # As so101_sim's timing: period k ends at the physics step nearest (k + 1) / rate.
        substeps = round((k + 1) / RATE / timestep) - round(k / RATE / timestep)
        data.ctrl[actuators] = actions[k]
        mujoco.mj_step(model, data, nstep=substeps)
        mujoco.mj_kinematics(model, data)
        state = np.concatenate([data.qpos[qpos], data.qvel[: len(qpos)]])
        if renderer is not None:
            renderer.update_scene(data, camera="top")
            renderer.render()
        period[0] = k + 1
        return state

    return timed(step, steps)


def measure_lerobot_env_so101(camera, steps: int) -> float:
    # Its renderer draws the full meshes with MuJoCo's defaults: about a second a frame on a CPU
    # rasteriser, so few steps are measured with a camera.
    steps = min(steps, 20) if camera else steps
    sys.path.insert(0, str(ensure_lerobot_env_so101()))
    os.environ.setdefault("MUJOCO_GL", "egl")
    from lerobot_env_so101 import GymRenderingSpec, SO101PickCubeGymEnv

    spec = GymRenderingSpec(height=camera[0], width=camera[1]) if camera else GymRenderingSpec()
    env = SO101PickCubeGymEnv(control_dt=1.0 / RATE, physics_dt=0.002, render_spec=spec, image_obs=bool(camera))
    env.reset(seed=0)
    actions = random_actions(env.action_space.low, env.action_space.high, steps + 30).astype(np.float32)
    index = iter(range(len(actions)))
    return timed(lambda: env.step(actions[next(index)]), steps, warmup=2 if camera else 30)


def measure_ros(camera, steps: int, protocol: str) -> float:
    import gymnasium as gym

    import so101  # noqa: F401

    cameras = {"top": camera} if camera else None
    env = gym.make("so101/CubeToBin-v0", backend="ros", cameras=cameras, max_episode_steps=None)
    if protocol == "before":
        previous_protocol(env.unwrapped)
    env.reset(seed=0)
    actions = random_actions(env.action_space.low, env.action_space.high, steps + 30).astype(np.float32)
    index = iter(range(len(actions)))
    rate = timed(lambda: env.step(actions[next(index)]), steps, warmup=10)
    env.close()
    return rate


def previous_protocol(env) -> None:
    """The ROS backend as it stepped before --step-on-command: the node in plain lockstep; each
    step publishes the command, gives it a 2 ms head start, then calls /sim/step."""
    from sensor_msgs.msg import JointState
    from std_srvs.srv import Trigger

    from so101 import contract
    from so101.units import JOINT_NAMES

    env.node_flags = []
    client = env._node.create_client(Trigger, f"/{env._namespace}/{contract.SIM_STEP}")

    def step(action):
        counts = dict(env._counts)
        env._commands.publish(JointState(name=JOINT_NAMES, position=[float(v) for v in action]))
        time.sleep(0.002)
        env._call(client, "/sim/step")
        observation = env._observe(counts)
        return observation, float(env._latest["reward"].data), False, False, {}

    env.step = step


def testspeed_env_steps(steps: int = 20000) -> float:
    """Env steps/s at 30 Hz that the scene's raw physics allows in Debian's libmujoco (the engine
    the core runs on), from MuJoCo's own C benchmark `mujoco-testspeed` on the same lite scene."""
    import re
    import tempfile

    import so101_native

    from so101.paths import asset

    scene = asset("so101_cube_to_bin.xml")
    with tempfile.NamedTemporaryFile("w", suffix=".xml", dir=scene.parent) as lite:
        lite.write(so101_native.scene_xml(str(scene), lite=True))
        lite.flush()
        out = subprocess.run(
            ["mujoco-testspeed", lite.name, str(steps), "1", "0"], check=True, capture_output=True, text=True
        ).stdout
    physics_steps = float(re.search(r"Steps per second\s*:\s*([0-9.]+)", out).group(1))
    return physics_steps * 0.002 * RATE


# ---------------------------------------------------------------- orchestration
def run_child(args: list[str]) -> float:
    out = subprocess.run(
        [sys.executable, "-m", "so101.bench.sim_core", "--child", *args], check=True, capture_output=True, text=True
    )
    return float(out.stdout.strip().splitlines()[-1])


def child(argv: list[str]) -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("contender")
    parser.add_argument("camera")
    parser.add_argument("steps", type=int)
    parser.add_argument("extra", nargs="?")
    args = parser.parse_args(argv)
    camera = CAMERAS[args.camera]
    if args.contender == "inprocess":
        rate = measure_inprocess(camera, args.steps)
    elif args.contender == "batch":
        rate = measure_batch(camera, args.steps, int(args.extra))
    elif args.contender == "mujoco":
        rate = measure_mujoco_bindings(camera, args.steps)
    elif args.contender == "lerobot_env_so101":
        rate = measure_lerobot_env_so101(camera, args.steps)
    else:
        rate = measure_ros(camera, args.steps, args.extra)
    print(rate)
    return 0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--bin-dir", type=Path, help="directory of the release binaries (so101_sim_node)")
    parser.add_argument("--steps", type=int, default=3000, help="env steps measured per contender (ROS: a fifth)")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each contender; the median is reported")
    parser.add_argument("--num-envs", type=int, default=8, help="worlds in the batch")
    parser.add_argument("--cameras", default="none,64x48,320x240", help="camera cases, comma-separated")
    parser.add_argument("--skip-ros", action="store_true", help="leave out the ROS rows (no namespace needed)")
    parser.add_argument("--json", type=Path, help="write the raw numbers here")


def run(args: argparse.Namespace) -> int:
    if args.bin_dir:
        os.environ["SO101_BIN_DIR"] = str(args.bin_dir)
    ensure_lerobot_env_so101()

    def median(contender: str, camera: str, steps: int, extra: str = "") -> float:
        rates = [run_child([contender, camera, str(steps), *([extra] if extra else [])]) for _ in range(args.repeats)]
        return float(np.median(rates))

    results: dict = {"steps": args.steps, "repeats": args.repeats, "num_envs": args.num_envs, "cases": {}}
    results["engine_ceiling"] = float(np.median([testspeed_env_steps() for _ in range(args.repeats)]))
    lines = [
        "| case | in-process env steps/s | MuJoCo bindings (a) | ratio | lerobot-env-so101 (b) | ratio "
        f"| batch of {args.num_envs} | batch / single | ROS before | ROS after | after / before |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for camera in args.cameras.split(","):
        case = {
            "inprocess": median("inprocess", camera, args.steps),
            "mujoco": median("mujoco", camera, args.steps),
            "lerobot_env_so101": median("lerobot_env_so101", camera, args.steps),
            "batch": median("batch", camera, args.steps // 2, str(args.num_envs)),
        }
        if not args.skip_ros:
            ros_steps = max(200, args.steps // 5)
            case["ros_before"] = median("ros", camera, ros_steps, "before")
            case["ros_after"] = median("ros", camera, ros_steps, "after")
        results["cases"][camera] = case
        ros = (
            f"{case['ros_before']:.0f} | {case['ros_after']:.0f} | {case['ros_after'] / case['ros_before']:.2f}x"
            if "ros_after" in case
            else "- | - | -"
        )
        lines.append(
            f"| {camera} | {case['inprocess']:.0f} | {case['mujoco']:.0f} | {case['inprocess'] / case['mujoco']:.2f}x "
            f"| {case['lerobot_env_so101']:.0f} | {case['inprocess'] / case['lerobot_env_so101']:.2f}x "
            f"| {case['batch']:.0f} | {case['batch'] / case['inprocess']:.2f}x | {ros} |"
        )
        print(lines[-1], file=sys.stderr, flush=True)
    lines.append("")
    lines.append(
        f"Engine ceiling (mujoco-testspeed, Debian's libmujoco {results['engine_ceiling']:.0f} env steps/s at 30 Hz): "
        f"the in-process env without cameras runs at {results['cases'].get('none', {}).get('inprocess', float('nan')) / results['engine_ceiling']:.2f}x of it."
    )
    return bench_common.report(lines, results, args.json)


SUBCOMMAND = Subcommand(
    "Gymnasium env steps/s of the in-process envs, the batch and the ROS backend against MuJoCo's own",
    add_arguments,
    run,
    __doc__.split("\n\n")[0],
)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--child"]:
        return child(argv[1:])
    return run_alone("so101-bench sim_core", SUBCOMMAND, argv)


if __name__ == "__main__":
    sys.exit(main())
