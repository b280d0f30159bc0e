"""`so101-learn demos --driver CKPT`: a policy sends the arm, the dataset keeps the expert's targets
from the states the arm lands in (so101.learn.dagger), played through the in-process env with the
real expert and a stand-in policy that holds the arm where it starts."""

from __future__ import annotations

import numpy as np
import pytest
from recording_env import Sent

from so101 import contract
from so101.envs import So101InProcessEnv
from so101.evaluate.expert import ExpertPolicy
from so101.learn import demos
from so101.learn.dagger import PolicyDriver, blended, check_share
from so101.learn.demos_inprocess import play_episode

LOW, HIGH = np.asarray(contract.JOINT_LIMITS).T


def test_the_sent_target_moves_the_share_of_the_way_to_the_policys_inside_the_limits():
    expert, policy = np.zeros(6), np.full(6, 0.2)
    assert np.allclose(blended(expert, policy, 0.0), expert)
    assert np.allclose(blended(expert, policy, 1.0), policy)
    assert np.allclose(blended(expert, policy, 0.25), 0.05)
    assert blended(expert, policy, 1.0).dtype == np.float32
    beyond = blended(HIGH, HIGH + 1.0, 1.0)
    assert np.all(beyond <= HIGH.astype(np.float32)), "a policy's target past a limit is sent at the limit"
    for share in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="--driver-share"):
            check_share(share)


class HoldingPolicy:
    """StackPolicy's interface: asks for the joints it saw first in the episode, every period."""

    needs_environment_state = False

    def __init__(self):
        self.first, self.resets, self.calls = None, 0, 0

    def reset(self):
        self.first, self.resets = None, self.resets + 1

    def observation(self, positions, images, cube_pose=None):
        return {"positions": np.array(positions)}

    def act(self, observation):
        self.calls += 1
        if self.first is None:
            self.first = observation["positions"]
        return self.first


def test_a_driven_episode_sends_the_policys_targets_and_records_the_experts():
    env = So101InProcessEnv(task="cube_to_bin", lite=True)
    observation, _ = env.reset(seed=4)
    start = np.asarray(observation["agent_pos"], dtype=np.float64)
    expert = ExpertPolicy(seed=4)
    expert.reset(observation)
    policy = HoldingPolicy()
    driver = PolicyDriver(policy, share=1.0)
    driver.reset()
    sent = Sent(env)
    frames, success = play_episode(sent, expert, observation, 0.0, False, 300, driver)
    states, recorded = np.array(frames["state"]), np.array(frames["action"])
    assert policy.resets == 1 and policy.calls == len(sent.actions)
    assert not success, "an arm held at its start puts no cube in the bin"
    # The env got the policy's targets (the start), the dataset the expert's, which go to the cube.
    assert np.allclose(np.array(sent.actions), start.astype(np.float32), atol=1e-6)
    assert np.abs(recorded - start).max() > 0.2
    assert np.abs(states - start).max() < 0.05, "the arm stayed where the policy held it"


def test_half_a_share_sends_the_midpoint_of_the_two_targets():
    env = So101InProcessEnv(task="cube_to_bin", lite=True)
    observation, _ = env.reset(seed=4)
    expert = ExpertPolicy(seed=4)
    expert.reset(observation)
    policy = HoldingPolicy()
    sent = Sent(env)
    frames, _ = play_episode(sent, expert, observation, 0.0, False, 60, PolicyDriver(policy, share=0.5))
    recorded = np.array(frames["action"])[: len(sent.actions)]
    assert np.allclose(np.array(sent.actions), (recorded + policy.first) / 2, atol=1e-5)


def demos_args(*argv: str):
    import argparse

    parser = argparse.ArgumentParser()
    demos.add_arguments(parser)
    return parser.parse_args(list(argv))


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--driver", "ckpt"], "--driver works in-process only"),
        (["--after", "dataset"], "--after works in-process only"),
        (["--backend", "inprocess", "--driver", "ckpt", "--perturb", "0.05"], "not both"),
        (["--backend", "inprocess", "--driver", "ckpt", "--driver-share", "2"], "--driver-share 2.0"),
    ],
)
def test_driving_options_that_cannot_work_are_refused_before_anything_runs(argv, message, tmp_path):
    with pytest.raises(SystemExit, match=message):
        demos.run(demos_args(*argv, "--output", str(tmp_path / "out")))
    assert not (tmp_path / "out").exists()
