"""The package as a user meets it: `import so101` registers the Gymnasium environments, the units
follow the generated contract, every console entry point answers --help."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import so101  # noqa: F401  (registers the environments)
from so101 import contract, units


def test_import_registers_the_gymnasium_environments():
    for env_id in ("so101/CubeToBin-v0", "so101/TouchCube-v0"):
        assert env_id in gym.registry, env_id


def test_units_use_the_contract_joint_order_and_limits():
    assert units.JOINT_NAMES == list(contract.JOINT_NAMES)
    assert units.FEATURE_NAMES[0] == "shoulder_pan.pos" and len(units.FEATURE_NAMES) == 6
    assert np.array_equal(units.JOINT_LIMITS, np.array(contract.JOINT_LIMITS))
    assert (units.GRIPPER_CLOSED, units.GRIPPER_OPEN) == contract.JOINT_LIMITS[-1]


def test_camera_topics_follow_the_contract():
    assert contract.camera_topic("top") == "camera/top/image_raw"
    assert contract.camera_topic("wrist", contract.CAMERA_INFO) == "camera/wrist/camera_info"


@pytest.mark.parametrize(
    "tool",
    [
        "so101-bag-to-lerobot",
        "so101-replay",
        "so101-run-policy",
        "so101-launch",
        "so101-bench",
        "so101-watch-sim",
        "so101-dataset-check",
        "so101-learn",
        "so101-sysid",
        "so101-description",
        "so101-camera-align",
    ],
)
def test_every_console_entry_point_answers_help(tool):
    done = subprocess.run([str(Path(sys.executable).parent / tool), "--help"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "usage" in (done.stdout + done.stderr).lower()
