"""The task set through the stack: the main job records a task other than cube_to_bin
(`so101-learn demos --task lift_cube`: so101-launch with the sim scoring it, teleop_node's expert
playing it, the recorder's episodes carrying its text), and the in-process door records the same
task alike; LeRobot reads both datasets back with the task's text and successful episodes that
end with the cube held up."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from so101 import contract

VENV_BIN = Path(sys.executable).parent


def test_the_main_job_and_the_in_process_door_record_lift_cube(tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    env = {**os.environ, "HF_HUB_OFFLINE": "1"}
    for backend, extra in (("ros", ["--speed", "2"]), ("inprocess", ["--backend", "inprocess"])):
        output = tmp_path / backend
        done = subprocess.run(
            [VENV_BIN / "so101-learn", "demos", "--task", "lift_cube", "--episodes", "2", "--seed", "3", *extra,
             "--repo-id", f"local/lift_{backend}", "--output", output],
            capture_output=True, text=True, timeout=240, env=env,
        )  # fmt: skip
        assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
        assert "2 successful" in done.stdout, done.stdout[-3000:]
        dataset = LeRobotDataset(f"local/lift_{backend}", root=output / "dataset")
        assert dataset.num_episodes == 2
        assert list(dataset.meta.tasks.index) == [contract.TASKS["lift_cube"].description]
        for start, stop in zip(dataset.meta.episodes["dataset_from_index"], dataset.meta.episodes["dataset_to_index"]):
            first, last = dataset[int(start)], dataset[int(stop) - 1]
            assert last["task"] == "lift the cube" and bool(last["next.success"])
            # Held up at the end: the cube well above where it lay, the jaws closed on it.
            assert float(last["observation.environment_state"][2]) > float(first["observation.environment_state"][2]) + 0.05
            assert float(last["observation.state"][5]) < 40.0  # gripper 0-100: closed on the cube
            assert np.isfinite(last["action"].numpy()).all()
