"""Sim-to-real as a user meets it: domain randomization drawn the same through both doors and
recorded with the demonstrations; the expert still succeeding under the default ranges; and
`so101-sysid` recovering the servo parameters of an emulated arm whose truth is known.

    SO101_BIN_DIR=$CARGO_TARGET_DIR/release scripts/isolated .venv/bin/python -m pytest tests/integration/test_sim_to_real.py
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import yaml

import so101  # noqa: F401 - registers the envs
from so101 import contract
from so101.evaluate.expert import ExpertPolicy

VENV_BIN = Path(sys.executable).parent
ACTION = np.array([0.3, -0.2, 0.2, 0.5, 0.1, 0.4], dtype=np.float32)


def run(argv: list, timeout: float) -> subprocess.CompletedProcess:
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "WANDB_MODE": "disabled"}
    done = subprocess.run([str(a) for a in argv], capture_output=True, text=True, timeout=timeout, env=env)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return done


# =========================================================================== randomization
def rollout(backend: str, seed: int, steps: int = 20) -> tuple[list[dict], np.ndarray]:
    env = gym.make("so101/CubeToBin-v0", backend=backend, randomize="default")
    try:
        observation, info = env.reset(seed=seed)
        draws = [info["episode_settings"]["draw"]]
        positions = [observation["agent_pos"]]
        for _ in range(steps):
            observation, *_ = env.step(ACTION)
            positions.append(observation["agent_pos"])
        _, info = env.reset()
        draws.append(info["episode_settings"]["draw"])
        return draws, np.array(positions)
    finally:
        env.close()


def test_a_seed_draws_the_same_randomized_episodes_through_both_doors():
    inprocess_draws, inprocess_positions = rollout("inprocess", seed=11)
    ros_draws, ros_positions = rollout("ros", seed=11)
    assert inprocess_draws == ros_draws
    # The same physics on the same draw: the joints move identically (observation noise included).
    np.testing.assert_array_equal(inprocess_positions, ros_positions)
    # Consecutive episodes and other seeds draw differently.
    assert inprocess_draws[0] != inprocess_draws[1]
    assert rollout("inprocess", seed=12, steps=0)[0][0] != inprocess_draws[0]


def test_randomization_changes_what_the_cameras_see():
    def top_frame(randomize: str, seed: int) -> np.ndarray:
        env = gym.make("so101/CubeToBin-v0", randomize=randomize, cameras={"top": (72, 96)})
        try:
            observation, _ = env.reset(seed=seed)
            return observation["pixels"]["top"].astype(float)
        finally:
            env.close()

    nominal = top_frame("off", 3)
    assert np.array_equal(nominal, top_frame("off", 3))
    first, second = top_frame("default", 3), top_frame("default", 4)
    # Colours, lights and the camera's pose changed: the picture differs well beyond noise.
    assert np.abs(first - nominal).mean() > 3.0
    assert np.abs(second - first).mean() > 3.0


def test_the_expert_still_succeeds_under_the_default_ranges():
    env = gym.make("so101/CubeToBin-v0", randomize="default")
    successes = 0
    try:
        for episode in range(20):
            observation, _ = env.reset(seed=9000 + episode)
            expert = ExpertPolicy(seed=episode)
            expert.reset(observation)
            for _ in range(contract.TASKS["cube_to_bin"].episode_steps):
                observation, _, terminated, truncated, info = env.step(expert(observation))
                if terminated or truncated:
                    break
            successes += bool(info["is_success"])
    finally:
        env.close()
    # 200 of 200 over seeds 5000-5199 (docs/benchmarks.md); a regression shows as several failures.
    assert successes >= 19, f"{successes} of 20"


def test_randomized_demonstrations_say_what_they_were_simulated_with(tmp_path):
    output = tmp_path / "demos"
    run([VENV_BIN / "so101-learn", "demos", "--episodes", "2", "--seed", "4", "--randomize", "--output", output], timeout=240)
    draws = []
    for metadata in sorted((output / "bags").glob("episode_*/metadata.yaml")):
        custom = yaml.safe_load(metadata.read_text())["rosbag2_bagfile_information"]["custom_data"]
        settings = json.loads(custom[contract.CUSTOM_SIMULATION])
        assert settings["servo_model"] == "sts3215"
        assert settings["randomization"]["cube"]["mass_scale"] == [0.6, 1.6]
        draws.append(settings["draw"])
    # Each bag holds its own episode's draw: the sim (seed 4) drew them at its resets, in order,
    # as an in-process world of the same seed does.
    import so101_native

    from so101.envs.inprocess import default_scene

    world = so101_native.World(default_scene(), seed=4, randomize="default")
    expected = []
    for _ in range(2):
        world.reset()
        expected.append(json.loads(world.episode_settings)["draw"])
    assert draws == expected
    kept = json.loads((output / "dataset" / "meta" / "so101_simulation.json").read_text())["episodes"]
    assert [entry["episode_index"] for entry in kept] == list(range(len(kept))) and kept
    assert all(entry["simulation"]["draw"] in draws for entry in kept)


# =========================================================================== identification
def test_sysid_recovers_the_emulated_arms_servo_parameters(tmp_path):
    """The emulator, its servos moving as the STS3215 model with known non-default parameters,
    is the arm: record (through the driver) and fit find the parameters, and the fit replays the
    held-out motions as closely as the truth does."""
    from so101.bench.sysid import relative_errors, truth_params

    truth = truth_params()
    (tmp_path / "truth.json").write_text(json.dumps(truth))
    bags, fitted_file = tmp_path / "bags", tmp_path / "fit.json"
    sysid = [VENV_BIN / "so101-sysid"]
    done = run(
        [
            *sysid,
            "record",
            "--emulate",
            "--emulator-servo-params",
            tmp_path / "truth.json",
            "--joints",
            "shoulder_lift,gripper",
            "--held-out",
            "--bags",
            bags,
        ],
        timeout=180,
    )
    assert done.stdout.count("so101-sysid: recorded") == 4, done.stdout
    done = run([*sysid, "fit", bags, "--output", fitted_file], timeout=120)
    assert "| shoulder_lift |" in done.stdout and "| gripper |" in done.stdout, done.stdout
    fitted = json.loads(fitted_file.read_text())
    # How close each parameter comes depends on the driver's cycle jitter, i.e. on how busy the
    # machine is (1.3-2x the quiet errors beside a training run): `scripts/bench.sh sysid`
    # measures it (docs/benchmarks.md). Here: the fit moved the recorded joints off the preset,
    # the armature (within 5 % on a quiet machine) comes out well even on a busy one, and below,
    # what the fit is for: it replays held-out motions as the truth does.
    preset = json.loads(__import__("so101_native").servo_params_json("sts3215"))["joints"]
    errors = relative_errors(fitted, truth)
    for joint in ("shoulder_lift", "gripper"):
        assert fitted["joints"][joint] != preset[joint], errors
        assert errors[joint]["armature"] <= 0.2, errors
    # Joints not recorded keep the preset.
    assert fitted["joints"]["elbow_flex"] == preset["elbow_flex"]

    models = ["sts3215", fitted_file, tmp_path / "truth.json"]
    gaps_file = tmp_path / "gaps.json"
    run(
        [
            *sysid,
            "compare",
            bags,
            "--tasks",
            "so101-sysid",
            *[a for m in models for a in ("--servo-params", m)],
            "--json",
            gaps_file,
        ],
        timeout=120,
    )
    gaps = json.loads(gaps_file.read_text())
    held_out = {r["task"].split()[1]: r for r in gaps.values() if r["task"].endswith("held-out")}
    assert set(held_out) == {"shoulder_lift", "gripper"}
    for joint, result in held_out.items():
        index = contract.JOINT_NAMES.index(joint)
        before, after, exact = (result[str(m)]["rms_rad"][index] for m in models)
        # The fit tracks the held-out motion as the truth does, far better than the preset. The
        # truth's own error is the recording's (the driver's cycle jitter: 0.0007 rad here, and
        # 0.0115 in a CI run where a stall disturbed the held-out motion, the preset's 0.0128
        # then mostly the same disturbance): a model's error beyond it, in quadrature, is what
        # the servo model adds.
        tick = 2 * np.pi / contract.ENCODER_TICKS_PER_REVOLUTION
        assert after <= max(1.5 * exact, exact + 0.5 * tick), (joint, before, after, exact)

        def beyond_truth(error: float) -> float:
            return float(np.sqrt(max(error**2 - exact**2, 0.0)))

        assert beyond_truth(after) <= 0.4 * beyond_truth(before), (joint, before, after, exact)
