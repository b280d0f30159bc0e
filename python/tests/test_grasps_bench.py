"""so101-bench grasps' account of an episode: closings counted from the gripper command, each
failure told apart by where the jaws first shut, and the real expert's own episodes through the
replay (the in-process sim, the native forward kinematics)."""

from __future__ import annotations

import numpy as np

from so101.bench.grasps import KINDS, closings, grasp_episode, replay, summary

CUBE = np.array([0.20, -0.05, 0.765])


def episode(success: bool, closing_offset, lift: bool = False, end_open_away: bool = False):
    """A 30-step episode: the jaws open for 10 steps, commanded shut at step 10 with the grasp point
    `closing_offset` from the cube (or never, for None)."""
    steps = 30
    cubes = np.tile(CUBE, (steps, 1))
    if lift:
        cubes[20:, 2] += 0.05
    points = np.tile(CUBE + np.array([0.0, 0.0, 0.10]), (steps, 1))
    commands = np.full(steps, 0.9)
    if closing_offset is not None:
        points[10:] = CUBE + np.asarray(closing_offset)
        commands[10:] = -0.17
    states = commands.copy()
    if end_open_away:
        states[-1], points[-1] = 0.9, CUBE + np.array([0.0, 0.3, 0.1])
    return grasp_episode(7, success, points, cubes, states, commands)


def test_closings_are_commands_to_shut_after_the_jaws_were_open():
    # Closed at the start (the arm's rest), opened, shut, shut still, opened, shut again.
    commands = [0.0, 0.1, 0.6, 0.9, 0.2, -0.1, -0.17, 0.7, 0.4, 0.25, 0.1]
    assert closings(np.array(commands)) == [4, 9]
    assert closings(np.array([0.0, 0.2, 0.4])) == []


def test_each_failure_is_told_apart_by_where_the_jaws_shut():
    missed = episode(False, [0.03, 0.0, 0.0], end_open_away=True)
    assert missed.kind == "missed the cube" and missed.first_closing == [0.03, 0.0, 0.0]
    assert missed.closings == 1 and missed.ended_open_away and not missed.lifted
    assert episode(False, None).kind == "never closed"
    assert episode(False, [0.003, 0.0, 0.0], lift=True).kind == "lost the cube"
    assert episode(False, [0.003, 0.0, 0.0]).kind == "other failure"
    held = episode(True, [0.002, 0.0, 0.0], lift=True)
    assert held.kind == "success" and held.closest < 0.003 and not held.ended_open_away

    counted = summary([missed, held, episode(False, None)])
    assert counted["episodes"] == 3 and sum(counted["kinds"].values()) == 3 and set(counted["kinds"]) == set(KINDS)
    assert counted["kinds"]["missed the cube"] == 1 and counted["kinds"]["never closed"] == 1
    assert abs(counted["median_first_closing_m"] - 0.016) < 1e-9  # of 0.03 and 0.002
    assert abs(counted["median_first_closing_of_failures_m"] - 0.03) < 1e-9
    # The miss waited away from the cube; the episode that never shut hovered 10 cm above it.
    assert counted["ended_open_away"] == 2


def test_the_experts_grasps_land_on_the_cube():
    from so101.envs import make_env
    from so101.evaluate.expert import ExpertPolicy

    env = make_env("cube_to_bin", backend="inprocess", lite=True)
    expert = ExpertPolicy()
    try:
        (account,) = replay(expert, expert.reset, env, [5], 600)
    finally:
        env.close()
    # The noiseless expert succeeds on this seed, its jaws shut within millimetres of the cube's centre.
    assert account.success and account.kind == "success" and account.lifted, account
    assert account.closings >= 1 and np.linalg.norm(account.first_closing) < 0.01, account
