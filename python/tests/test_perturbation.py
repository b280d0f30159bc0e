"""`so101-learn demos --perturb`: the arm pushed off the expert's path by smooth bumps while the
jaws are open, the dataset keeping the expert's own targets (so101.learn.perturbation), played
through the in-process env with the real expert."""

from __future__ import annotations

import numpy as np
import pytest
import so101_native
from recording_env import Sent

from so101 import contract
from so101.envs import So101InProcessEnv
from so101.evaluate.expert import ExpertPolicy
from so101.learn.demos_inprocess import play_episode
from so101.learn.perturbation import JOINT_WEIGHTS, Perturbation

OPEN = np.array([0.3, -0.2, 0.2, 0.5, 0.0, so101_native.EXPERT_GRIPPER_OPEN])
CLOSED = np.array([*OPEN[:5], so101_native.EXPERT_GRIPPER_CLOSED])


def offsets(perturbation: Perturbation, targets) -> np.ndarray:
    return np.array([perturbation.offset(target) for target in targets])


def test_bumps_are_smooth_and_leave_the_wrist_roll_and_the_jaws_alone():
    sigma = 0.08
    pushed = offsets(Perturbation(sigma, seed=3), [OPEN] * 600)
    moved = np.abs(pushed).max(axis=0)
    for joint, weight in enumerate(JOINT_WEIGHTS):
        if weight == 0:
            assert moved[joint] == 0, contract.JOINT_NAMES[joint]
        else:
            assert moved[joint] > 0.2 * sigma * weight, contract.JOINT_NAMES[joint]
    # sin^2 over 30 periods: a bump of amplitude A moves at most A*pi/30 a period.
    largest = np.abs(pushed).max()
    assert np.abs(np.diff(pushed, axis=0)).max() <= largest * np.pi / 30 + 1e-12
    # Bumps with pauses between them: the arm is on the expert's path part of the time.
    resting = np.all(pushed == 0, axis=1)
    assert 0.1 < resting.mean() < 0.7


def test_no_bump_starts_while_the_jaws_are_closed():
    perturbation = Perturbation(0.08, seed=5)
    closed = offsets(perturbation, [CLOSED] * 300)
    assert np.all(closed == 0)
    reopened = offsets(perturbation, [OPEN] * 60)
    assert np.abs(reopened).max() > 0


def test_a_seed_repeats_its_bumps_and_sigma_zero_is_the_experts_path():
    one, two = (offsets(Perturbation(0.05, seed=(7, 2)), [OPEN] * 200) for _ in range(2))
    assert np.array_equal(one, two)
    assert not np.array_equal(one, offsets(Perturbation(0.05, seed=(7, 3)), [OPEN] * 200))
    quiet = Perturbation(0.0, seed=1)
    assert np.array_equal(quiet(OPEN), OPEN.astype(np.float32))
    with pytest.raises(ValueError, match="amplitude"):
        Perturbation(float("nan"), seed=1)


def test_executed_targets_stay_inside_the_joint_limits():
    low, high = np.asarray(contract.JOINT_LIMITS).T
    at_limit = high.copy()
    at_limit[-1] = so101_native.EXPERT_GRIPPER_OPEN
    perturbation = Perturbation(0.5, seed=11)
    executed = np.array([perturbation(at_limit) for _ in range(300)])
    assert np.all(executed >= low.astype(np.float32)) and np.all(executed <= high.astype(np.float32))


def test_a_perturbed_episode_records_the_experts_targets_and_the_expert_still_succeeds():
    seed = 4
    env = So101InProcessEnv(task="cube_to_bin", lite=True)
    played = {}
    for sigma in (0.0, 0.06):
        observation, info = env.reset(seed=seed)
        expert = ExpertPolicy(seed=seed)
        expert.reset(observation)
        sent = Sent(env)
        perturbation = Perturbation(sigma, seed=seed) if sigma else None
        frames, success = play_episode(sent, expert, observation, 0.0, False, 1200, perturbation)
        played[sigma] = (np.array(frames["state"]), np.array(frames["action"]), np.array(sent.actions), success)
    states, recorded, sent_actions, success = played[0.06]
    assert success, "the expert comes back to its path and puts the cube in the bin"
    assert played[0.0][3]
    # Unperturbed, the env gets what the dataset records; perturbed, it gets the pushed targets.
    assert np.array_equal(played[0.0][1][: len(played[0.0][2])], played[0.0][2])
    difference = sent_actions - recorded[: len(sent_actions)]
    assert np.abs(difference).max() > 0.01
    assert np.all(difference[:, 4:] == 0), "the wrist roll and the jaws are sent as the expert gives them"
    # The arm really went where the expert's path is not.
    frames = min(len(states), len(played[0.0][0]))
    assert np.abs(states[:frames, :4] - played[0.0][0][:frames, :4]).max() > 0.02
