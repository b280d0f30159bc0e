"""The simulation's options as users write them (so101.sim_options): `randomize` as True/False,
"true"/"false"/"off"/"default" or a path, `servo_params` as a model's name or a path, str or
os.PathLike. Each spelling reaches the simulation as the one string it takes, through Gymnasium
(both envs and the vector env), LeRobot's env type and the CLIs; anything else is refused with the
accepted forms before a simulation is built. The core is a stand-in (test_task_registry's fakes)
that records what it was given."""

from __future__ import annotations

import sys
import types
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import pytest
from lerobot.envs.configs import EnvConfig
from test_task_registry import FakeWorld, FakeWorldBatch

import so101  # noqa: F401  (registers the environments)
from so101 import sim_options
from so101.sim_options import randomize_spec, servo_params_spec


@pytest.fixture
def ranges(tmp_path) -> Path:
    path = tmp_path / "ranges.toml"
    path.write_text("[cube]\n")
    return path


@pytest.fixture
def fit(tmp_path) -> Path:
    path = tmp_path / "fit.json"
    path.write_text("{}")
    return path


@pytest.mark.parametrize(
    "value, spec",
    [(True, "default"), (False, "off"), ("true", "default"), ("True", "default"), ("false", "off"), ("FALSE", "off")]
    + [("off", "off"), ("default", "default"), (" default ", "default"), ("heldout", "heldout"), ("HeldOut", "heldout")],
)
def test_randomize_words_and_booleans(value, spec):
    assert randomize_spec(value) == spec


def test_randomize_a_path_as_str_or_pathlike(ranges, monkeypatch):
    assert randomize_spec(ranges) == randomize_spec(str(ranges)) == str(ranges.resolve())
    # Relative to where the user is; absolute from then on, for a node started elsewhere.
    monkeypatch.chdir(ranges.parent)
    assert randomize_spec("ranges.toml") == str(ranges.resolve())


@pytest.mark.parametrize("value", ["maybe", "ranges.toml", ""])
def test_randomize_refuses_what_is_neither_a_word_nor_a_file(value, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ValueError, match="'default', 'heldout' or a .toml file"):
        randomize_spec(value)


@pytest.mark.parametrize("value", [None, 1, 0.5, ["default"]])
def test_randomize_refuses_other_types(value):
    with pytest.raises(TypeError, match=r"randomize=.*True, False, 'off', 'default'"):
        randomize_spec(value)


def test_servo_params_names_and_files(fit):
    assert servo_params_spec("sts3215") == "sts3215" and servo_params_spec("gain80") == "gain80"
    assert servo_params_spec(sim_options.DEFAULT_SERVO_MODEL) in sim_options.SERVO_MODELS
    assert servo_params_spec(fit) == servo_params_spec(str(fit)) == str(fit.resolve())


@pytest.mark.parametrize("value, error", [("sts3250", ValueError), ("missing.json", ValueError), (True, TypeError)])
def test_servo_params_refuses_unknown_models_missing_files_and_other_types(value, error, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(error, match="sts3215, gain80 or a so101-sysid fit file"):
        servo_params_spec(value)


class RecordingWorld(FakeWorld):
    made: list[dict] = []

    def __init__(self, scene, **options):
        type(self).made.append(options)
        super().__init__(scene, **options)


class RecordingBatch(FakeWorldBatch):
    made: list[dict] = []

    def __init__(self, num_envs, scene, **options):
        type(self).made.append(options)
        super().__init__(num_envs, scene, **options)


@pytest.fixture
def native(monkeypatch):
    RecordingWorld.made, RecordingBatch.made = [], []
    monkeypatch.setitem(sys.modules, "so101_native", types.SimpleNamespace(World=RecordingWorld, WorldBatch=RecordingBatch))
    return RecordingWorld.made, RecordingBatch.made


def test_gym_make_takes_randomize_true_and_false(native):
    worlds, batches = native
    for randomize, spec in ((True, "default"), (False, "off"), ("true", "default"), ("off", "off")):
        gym.make("so101/CubeToBin-v0", randomize=randomize).close()
        assert worlds[-1]["randomize"] == spec
        gym.make_vec("so101/CubeToBin-v0", num_envs=2, randomize=randomize).close()
        assert batches[-1]["randomize"] == spec


def test_gym_make_takes_paths_as_pathlike(native, ranges, fit):
    worlds, _ = native
    gym.make("so101/CubeToBin-v0", randomize=ranges, servo_params=fit).close()
    assert worlds[-1]["randomize"] == str(ranges.resolve()) and worlds[-1]["servo_params"] == str(fit.resolve())
    gym.make("so101/CubeToBin-v0").close()
    assert worlds[-1]["randomize"] == "off" and worlds[-1]["servo_params"] == sim_options.DEFAULT_SERVO_MODEL


def test_gym_make_refuses_a_bad_option_before_building_a_world(native):
    worlds, _ = native
    with pytest.raises(ValueError, match="randomize='sometimes'"):
        gym.make("so101/CubeToBin-v0", randomize="sometimes")
    with pytest.raises(TypeError, match="servo_params=3215"):
        gym.make("so101/CubeToBin-v0", servo_params=3215)
    assert worlds == []


def test_the_ros_env_refuses_a_bad_option_before_starting_anything():
    from so101.envs import So101RosEnv

    with pytest.raises(ValueError, match="randomize='sometimes'"):
        So101RosEnv(randomize="sometimes")


@dataclass
class EnvHolder:
    env: EnvConfig


@pytest.mark.parametrize("text, spec", [("true", "default"), ("false", "off"), ("default", "default"), ("off", "off")])
def test_lerobot_env_type_takes_randomize_as_written_on_the_command_line(text, spec, native):
    import draccus
    from lerobot.utils.import_utils import register_third_party_plugins

    register_third_party_plugins()
    env = draccus.parse(EnvHolder, args=["--env.type=so101_sim", f"--env.randomize={text}"]).env
    assert env.randomize == spec and env.gym_kwargs["randomize"] == spec
    gym.make(env.gym_id, **env.gym_kwargs).close()
    assert native[0][-1]["randomize"] == spec


def test_lerobot_env_type_refuses_a_bad_randomization():
    from so101.lerobot.env import So101SimEnvConfig

    with pytest.raises(ValueError, match="randomize='sometimes'"):
        So101SimEnvConfig(randomize="sometimes")


def test_so101_run_policy_reads_randomize_as_written(ranges, capsys):
    from so101.evaluate.run_policy import parser

    assert parser().parse_args(["P", "--randomize"]).randomize == "default"
    assert parser().parse_args(["P", "--randomize", "true"]).randomize == "default"
    assert parser().parse_args(["P", "--randomize", "false"]).randomize == "off"
    assert parser().parse_args(["P", "--randomize", str(ranges)]).randomize == str(ranges.resolve())
    assert parser().parse_args(["P"]).randomize == "off"
    with pytest.raises(SystemExit):
        parser().parse_args(["P", "--servo-params", "sts3250"])
    assert "sts3215, gain80 or a so101-sysid fit file" in capsys.readouterr().err


def test_camera_poses_none_empty_or_a_toml_file_reaches_every_door(native, tmp_path, monkeypatch):
    import draccus
    from lerobot.utils.import_utils import register_third_party_plugins

    from so101.evaluate.run_policy import parser
    from so101.sim_options import camera_poses_spec

    poses = tmp_path / "camera_poses.toml"
    poses.write_text("[top]\n")
    monkeypatch.chdir(tmp_path)
    assert camera_poses_spec(None) is None and camera_poses_spec("") is None
    assert camera_poses_spec("camera_poses.toml") == camera_poses_spec(poses) == str(poses.resolve())
    for bad, error in (("missing.toml", ValueError), ("ranges.json", ValueError), (3, TypeError)):
        with pytest.raises(error, match="so101-camera-align's file"):
            camera_poses_spec(bad)

    worlds, batches = native
    gym.make("so101/CubeToBin-v0", camera_poses=poses).close()
    assert worlds[-1]["camera_poses"] == str(poses.resolve())
    gym.make_vec("so101/CubeToBin-v0", num_envs=2).close()
    assert batches[-1]["camera_poses"] is None
    register_third_party_plugins()
    env = draccus.parse(EnvHolder, args=["--env.type=so101_sim", "--env.camera_poses=camera_poses.toml"]).env
    gym.make(env.gym_id, **env.gym_kwargs).close()
    assert worlds[-1]["camera_poses"] == str(poses.resolve())
    assert parser().parse_args(["P", "--camera-poses", "camera_poses.toml"]).camera_poses == str(poses.resolve())
    assert parser().parse_args(["P"]).camera_poses is None
