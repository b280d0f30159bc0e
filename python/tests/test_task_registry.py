"""Tasks are facts of the generated contract (so101.contract.TASKS, from so101_core): every place
that lists tasks or applies a task rule reads them, so a task added in Rust needs no Python edit.

For every task of contract.TASKS, nothing written out here: its in-process Gymnasium id (with the
task's episode length), LeRobot's env type so101_sim (its gym id, its config, its task text),
so101-run-policy's --sim-task, so101-learn eval's --sim-task, SAC's --task (tasks with a dense
reward), the learning wrappers' episode lengths, and termination on success as the task says.
The last test runs all of these again in a fresh interpreter whose contract holds one task more
than the generated one: a table typed out by hand anywhere fails it.

The simulation core is a stand-in here (FakeNative): the termination rule is the Python side's,
and these tests need no built extension."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import types
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import so101  # noqa: F401  (registers the environments)
from so101 import contract

# The env var under which the fresh interpreter of the last test runs this module, and the task
# its contract has in addition (terminating on success, with both rewards).
EXTRA_TASK_RUN = "SO101_TEST_EXTRA_TASK"
EXTRA_TASK = dict(
    name="reach_test_only",
    gym_id="so101/ReachTestOnly-v0",
    description="a task only this test knows",
    episode_steps=123,
    terminates_on_success=True,
    reward_modes=("dense", "sparse"),
    control_rate=contract.CONTROL_RATE,
)
TASKS = list(contract.TASKS.values())


class FakeWorld:
    """so101_native.World's interface: every step succeeds."""

    def __init__(
        self,
        scene,
        lite=True,
        task="",
        control_rate=0.0,
        dense_reward=False,
        servo_params="sts3215",
        randomize="off",
        camera_poses=None,
    ):
        self.task, self.control_rate, self.success, self.cameras = task, control_rate, False, {}
        self.episode_settings = json.dumps({"servo_model": servo_params, "draw": None})

    def enable_cameras(self, cameras, renderer="auto"):
        self.cameras = dict(cameras)

    def reset(self, seed):
        self.success = False
        return (0.2, 0.0, 0.0)

    def step(self, action):
        self.success = True

    def observe(self):
        return np.zeros(19), 0.0, self.success

    def render(self):
        return {name: np.zeros((h, w, 3), dtype=np.uint8) for name, (h, w) in self.cameras.items()}


class FakeWorldBatch:
    """so101_native.WorldBatch's interface: every stepped world succeeds."""

    def __init__(
        self,
        num_envs,
        scene,
        lite=True,
        task="",
        control_rate=0.0,
        dense_reward=False,
        threads=0,
        servo_params="sts3215",
        randomize="off",
        camera_poses=None,
    ):
        self.task, self.control_rate = task, control_rate
        self.successes = np.zeros(num_envs, dtype=bool)

    def enable_cameras(self, cameras, renderer="auto"):
        raise AssertionError("no cameras in these tests")

    def reset_all(self, seeds):
        self.successes[:] = False

    def reset(self, index):
        self.successes[index] = False

    def step(self, actions, active=None):
        self.successes[:] = True if active is None else np.asarray(active, dtype=bool)

    def observe(self):
        n = len(self.successes)
        return np.zeros((n, 19)), np.zeros(n), self.successes.copy()


@pytest.fixture
def fake_native(monkeypatch):
    monkeypatch.setitem(sys.modules, "so101_native", types.SimpleNamespace(World=FakeWorld, WorldBatch=FakeWorldBatch))


def choices(parser: argparse.ArgumentParser, dest: str) -> list[str]:
    return list(next(action for action in parser._actions if action.dest == dest).choices)


def subcommand(parser: argparse.ArgumentParser, name: str) -> argparse.ArgumentParser:
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[name]


def lerobot_env_config():
    from lerobot.envs.configs import EnvConfig
    from lerobot.utils.import_utils import register_third_party_plugins

    register_third_party_plugins()
    return EnvConfig.get_choice_class("so101_sim")


def test_the_contract_names_each_task_once():
    assert TASKS, "the generated contract lists no task"
    assert all(name == task.name for name, task in contract.TASKS.items())
    assert len({task.gym_id for task in TASKS}) == len(TASKS)
    assert all(task.reward_modes and set(task.reward_modes) <= {"sparse", "dense"} for task in TASKS)


@pytest.mark.parametrize("task", TASKS, ids=lambda task: task.name)
def test_gymnasium_registers_the_task_in_process(task):
    spec = gym.spec(task.gym_id)
    assert spec.entry_point == "so101.envs.registry:make_env"
    assert spec.vector_entry_point == "so101.envs.registry:make_vector_env"
    assert spec.kwargs == {"task": task.name} and spec.max_episode_steps == task.episode_steps


@pytest.mark.parametrize("task", TASKS, ids=lambda task: task.name)
def test_lerobots_env_type_knows_the_task(task):
    cls = lerobot_env_config()
    config = cls(task=task.name)
    spec = gym.spec(config.gym_id)
    assert config.gym_id == f"lerobot_env_so101_sim/{task.name}"
    assert spec.entry_point == "so101.lerobot.adapter:So101LeRobotEnv" and spec.kwargs == {"task": task.name}
    assert spec.max_episode_steps == task.episode_steps
    assert config.gym_kwargs["task_description"] == task.description and config.fps == round(task.control_rate)


@pytest.mark.parametrize("task", TASKS, ids=lambda task: task.name)
def test_the_commands_offer_the_task(task):
    from so101.evaluate import run_policy
    from so101.learn import cli, wrappers

    assert task.name in choices(run_policy.parser(), "sim_task")
    learn = cli.parser()
    assert task.name in choices(subcommand(learn, "eval"), "sim_task")
    # SAC learns from the dense reward: it offers exactly the tasks that have one.
    assert (task.name in choices(subcommand(learn, "sac"), "task")) == ("dense" in task.reward_modes)
    assert wrappers.EPISODE_STEPS[task.name] == task.episode_steps
    assert wrappers.EnvSettings(task=task.name).episode_steps == task.episode_steps


@pytest.mark.parametrize("task", TASKS, ids=lambda task: task.name)
def test_an_episode_terminates_on_success_as_the_task_says(task, fake_native):
    env = gym.make(task.gym_id)
    assert env.unwrapped.world.task == task.name and env.unwrapped.world.control_rate == task.control_rate
    env.reset(seed=0)
    _, _, terminated, truncated, info = env.step(np.zeros(6, dtype=np.float32))
    assert info["is_success"] and terminated == task.terminates_on_success and not truncated
    env.close()

    vector = gym.make_vec(task.gym_id, num_envs=2)
    vector.reset(seed=0)
    _, _, terminated, _, info = vector.step(np.zeros((2, 6)))
    assert info["is_success"].all() and list(terminated) == [task.terminates_on_success] * 2
    vector.close()

    # LeRobot's env type: the same rule through the adapter.
    config = lerobot_env_config()(task=task.name)
    env = gym.make(config.gym_id, disable_env_checker=True, **config.gym_kwargs)
    env.reset(seed=0)
    _, _, terminated, _, info = env.step(np.zeros(6, dtype=np.float32))
    assert info["is_success"] and terminated == task.terminates_on_success
    env.close()


def test_tasks_are_not_written_out_anywhere():
    """This module again, in an interpreter whose contract has one task more: it passes only if
    every table above is derived from contract.TASKS."""
    if os.environ.get(EXTRA_TASK_RUN):
        assert EXTRA_TASK["name"] in contract.TASKS, "the contract lacks the added task"
        return
    # The generated contract loaded first, plus one task, before anything in so101 reads it.
    program = f"""
import importlib.util, sys
import pytest
spec = importlib.util.spec_from_file_location("so101.contract", {str(Path(contract.__file__))!r})
module = importlib.util.module_from_spec(spec)
spec.loader.exec_module(module)
module.TASKS[{EXTRA_TASK["name"]!r}] = module.Task(**{EXTRA_TASK!r})
sys.modules["so101.contract"] = module
sys.exit(pytest.main(["-q", "-p", "no:cacheprovider", {__file__!r}]))
"""
    done = subprocess.run(
        [sys.executable, "-c", program], env={**os.environ, EXTRA_TASK_RUN: "1"}, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]


NOT_OFFERED = [(task.name, mode) for task in TASKS for mode in ("dense", "sparse") if mode not in task.reward_modes]


@pytest.mark.parametrize(("task", "mode"), NOT_OFFERED)
def test_run_policy_refuses_a_reward_the_task_does_not_offer(task, mode):
    from so101.evaluate import run_policy

    with pytest.raises(SystemExit, match=f"{task} has no {mode} reward"):
        run_policy.main(["no_such_policy", "--eval", "1", "--sim-task", task, "--reward", mode])
