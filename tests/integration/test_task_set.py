"""The task set through the stack: the main job records tasks other than cube_to_bin
(`so101-learn demos --task lift_cube|place_cube|push_cube|stack_cube`: so101-launch with the sim
scoring it, teleop_node's expert playing it, the recorder's episodes carrying its text), and the
in-process door records the same task alike; LeRobot reads both datasets back with the task's text
and successful episodes that end as the task asks (the cube held up, let go on the pad, pushed onto
the target, or let go on top of the green cube)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from so101 import contract

VENV_BIN = Path(sys.executable).parent
# The expert without noise, failures kept: the stack's path follows ROS's timing, so whether its
# expert succeeds is so101-bench expert's measure (docs/benchmarks.md), not this test's.
QUIET = ["--waypoint-noise", "0", "--action-noise", "0", "--keep-failures"]


@pytest.mark.parametrize("task", ["lift_cube", "place_cube", "push_cube", "stack_cube"])
def test_the_main_job_and_the_in_process_door_record_the_task(task, tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    env = {**os.environ, "HF_HUB_OFFLINE": "1"}
    for backend, extra in (("ros", ["--speed", "2"]), ("inprocess", ["--backend", "inprocess"])):
        output = tmp_path / backend
        done = subprocess.run(
            [VENV_BIN / "so101-learn", "demos", "--task", task, "--episodes", "2", "--seed", "3", *QUIET, *extra,
             "--repo-id", f"local/{task}_{backend}", "--output", output],
            capture_output=True, text=True, timeout=240, env=env,
        )  # fmt: skip
        assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
        if backend == "inprocess":  # deterministic: this seed's episodes succeed
            assert "2 successful" in done.stdout, done.stdout[-3000:]
        dataset = LeRobotDataset(f"local/{task}_{backend}", root=output / "dataset")
        assert dataset.num_episodes == 2
        text = contract.TASKS[task].description
        assert list(dataset.meta.tasks.index) == [text]
        succeeded = 0
        for start_index, stop in zip(dataset.meta.episodes["dataset_from_index"], dataset.meta.episodes["dataset_to_index"]):
            first, last = dataset[int(start_index)], dataset[int(stop) - 1]
            assert last["task"] == text
            if not bool(last["next.success"]):
                continue
            succeeded += 1
            cube, start = last["observation.environment_state"].numpy(), first["observation.environment_state"].numpy()
            if task == "lift_cube":
                # Held up at the end: the cube well above where it lay, the jaws closed on it.
                assert cube[2] > start[2] + 0.05 and float(last["observation.state"][5]) < 40.0
            elif task == "place_cube":
                # Let go on the pad, left of the arm: resting as low as it started, the jaws open.
                assert abs(cube[1] - 0.18) < 0.025 and abs(cube[2] - start[2]) < 0.003
                assert float(last["observation.state"][5]) > 40.0
            elif task == "push_cube":
                # Slid onto the round target (x 0.26, y 0.13 m, 3 cm radius), never lifted.
                assert np.hypot(cube[0] - 0.26, cube[1] - 0.13) < 0.03 and abs(cube[2] - start[2]) < 0.003
                states = dataset.hf_dataset[int(start_index) : int(stop)]["observation.environment_state"]
                assert max(float(state[2]) for state in states) < start[2] + 0.01
            else:
                # On top of the green cube (x 0.20, y 0.18 m): one 3 cm edge above where it lay.
                assert np.hypot(cube[0] - 0.20, cube[1] - 0.18) < 0.03 and abs(cube[2] - start[2] - 0.03) < 0.003
            assert np.isfinite(last["action"].numpy()).all()
        assert succeeded >= 1, f"no {task} episode of {backend} succeeded"


def test_the_readmes_main_job_records_another_task_with_end_effector_actions(tmp_path):
    """scripts/record_dataset.sh --task lift-cube --action-space ee: the task the contract names is
    scored, played and recorded (its text on the episode, the dataset named after it), and the
    converter writes end-effector actions and state beside the joints."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from so101.ee import EE_FEATURE_NAMES
    from so101.paths import repo_root

    output = tmp_path / "run"
    done = subprocess.run(
        [repo_root() / "scripts" / "record_dataset.sh", "--task", "lift-cube", "--action-space", "ee",
         "--episodes", "1", "--seed", "3", "--lite", "--cameras", "top:64x48", "--output", output],
        capture_output=True, text=True, timeout=300, env={**os.environ, "HF_HUB_OFFLINE": "1"},
    )  # fmt: skip
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert "repo id local/so101_lift_cube, ee actions" in done.stdout, done.stdout[-3000:]
    assert "so101-learn demos --task lift_cube" in done.stdout
    dataset = LeRobotDataset("local/so101_lift_cube", root=output / "dataset")
    assert dataset.num_episodes == 1
    assert list(dataset.meta.tasks.index) == [contract.TASKS["lift_cube"].description]
    features = dataset.meta.features
    assert features["action"]["names"] == EE_FEATURE_NAMES
    assert features["observation.ee_state"]["names"] == EE_FEATURE_NAMES
    assert features["observation.images.top"]["shape"] == (48, 64, 3)
    # lift_cube's episode is 300 periods at most: the sim ran the task asked, not cube_to_bin's 600.
    assert 0 < dataset.num_frames <= contract.TASKS["lift_cube"].episode_steps
    assert np.isfinite(dataset[0]["action"].numpy()).all()
