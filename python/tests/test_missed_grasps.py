"""`so101-learn demos --missed-grasps`: the expert told the cube lies a few centimetres off, its
grasp beside the cube, its own regrasp where the cube is, and the episode kept from the regrasp on
(so101.learn.missed_grasps), played through the in-process env with the real expert and written by
LeRobot's dataset writer."""

from __future__ import annotations

import json

import numpy as np
import pytest

from so101 import contract
from so101.envs import So101InProcessEnv
from so101.evaluate.expert import ExpertPolicy
from so101.learn import cli, demos
from so101.learn.demos_inprocess import Options, play_episode, record
from so101.learn.missed_grasps import OFFSET_RANGE, check_fraction, draw_offset, from_frame, recovery_start, told
from so101.learn.perturbation import jaws_open_above

GRIPPER = contract.JOINT_NAMES.index("gripper")


def test_the_share_of_told_misses_follows_the_fraction_and_the_episode_alone():
    draws = [draw_offset(0.3, 7, episode) for episode in range(2000)]
    told_count = sum(d is not None for d in draws)
    # Binomial(2000, 0.3): mean 600, standard deviation 20.5; 5 of them either side.
    assert 500 < told_count < 700, told_count
    radii = np.array([np.linalg.norm(d) for d in draws if d is not None])
    assert radii.min() >= OFFSET_RANGE[0] and radii.max() <= OFFSET_RANGE[1]
    angles = np.array([np.arctan2(d[1], d[0]) for d in draws if d is not None])
    assert np.histogram(angles, bins=4, range=(-np.pi, np.pi))[0].min() > 100, "every direction"
    # The same episode of the same seed draws the same, whichever worker plays it.
    assert all(np.array_equal(a, b) for a, b in zip(draws[:50], [draw_offset(0.3, 7, e) for e in range(50)]) if a is not None)
    assert all(draw_offset(0.0, 7, episode) is None for episode in range(200))
    assert all(draw_offset(1.0, 7, episode) is not None for episode in range(200))


@pytest.mark.parametrize("fraction", [-0.1, 1.5, float("nan")])
def test_a_fraction_outside_0_to_1_is_refused(fraction, tmp_path):
    with pytest.raises(ValueError, match="--missed-grasps"):
        check_fraction(fraction)
    args = cli.parser().parse_args(
        ["demos", "--backend", "inprocess", "--missed-grasps", str(fraction), "--output", str(tmp_path)]
    )
    with pytest.raises(SystemExit, match="--missed-grasps"):
        demos.run(args)
    assert not (tmp_path / "dataset").exists()


def test_told_misses_are_in_process_only(tmp_path):
    args = cli.parser().parse_args(["demos", "--missed-grasps", "0.3", "--output", str(tmp_path)])
    with pytest.raises(SystemExit, match="--missed-grasps works in-process only"):
        demos.run(args)


def play(env, seed: int, offset) -> tuple[dict, bool, int]:
    observation, _ = env.reset(seed=seed)
    expert = ExpertPolicy(seed=seed)
    expert.reset(observation if offset is None else told(observation, np.asarray(offset)))
    frames, success = play_episode(env, expert, observation, 0.0, False, 1200)
    return frames, success, expert.regrasps


@pytest.mark.parametrize(
    ("offset", "jaws_at_the_regrasp"),
    [
        ([0.03, 0.0], "shut"),  # beyond the cube, along the jaws' travel: they shut on nothing
        ([0.0, 0.03], "open"),  # beside it, across the jaws: the moving jaw lands on the cube
    ],
)
def test_the_expert_told_a_wrong_pose_grasps_beside_the_cube_then_where_it_is(offset, jaws_at_the_regrasp):
    seed = 4
    env = So101InProcessEnv(task="cube_to_bin", lite=True)
    _, truthful_success, truthful_regrasps = play(env, seed, None)
    assert truthful_success and truthful_regrasps == 0, "told the truth, the expert grasps once and succeeds"
    frames, success, regrasps = play(env, seed, offset)
    assert success and regrasps >= 1, "told 3 cm off, it grasps again where the cube is and succeeds"
    start = recovery_start(frames["regrasps"])
    assert start is not None and all(count == 0 for count in frames["regrasps"][:start])
    # Up to the regrasp the cube stays where it was placed: the told grasp did not take it.
    cubes = np.array(frames["cube"])
    assert np.abs(cubes[start, :3] - cubes[0, :3]).max() < 0.01, "the told grasp carried the cube away"
    gripper = np.array(frames["state"])[start, GRIPPER]
    assert (gripper < jaws_open_above()) == (jaws_at_the_regrasp == "shut"), gripper
    kept = from_frame(frames, start)
    assert {name: len(values) for name, values in kept.items()} == {name: len(frames["state"]) - start for name in frames}
    assert np.array_equal(kept["state"][0], frames["state"][start])


def test_a_recording_keeps_told_episodes_from_the_regrasp_and_says_so(tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    options = Options(
        seed=5,
        waypoint_noise=0.005,
        action_noise=0.01,
        cameras={},
        lite=True,
        environment_state=True,
        keep_failures=False,
        servo_params="sts3215",
        randomize="off",
        camera_poses=None,
        repo_id="local/missed",
        missed_grasps=1.0,
    )
    results = record(options, 2, 1, tmp_path / "dataset")
    kept = [r for r in results if r.kept]
    assert kept and all(r.missed_grasp is not None and r.regrasps >= 1 for r in kept), results
    facts = json.loads((tmp_path / "dataset" / "meta" / "so101_simulation.json").read_text())["episodes"]
    dataset = LeRobotDataset("local/missed", root=tmp_path / "dataset")
    for entry, result in zip(facts, kept):
        told_offset = np.linalg.norm(entry["missed_grasp"]["told_offset_m"])
        assert OFFSET_RANGE[0] - 1e-4 <= told_offset <= OFFSET_RANGE[1] + 1e-4
        assert entry["missed_grasp"]["from_frame"] > 30, "the approach to the told pose is left out"
        frames = dataset.meta.episodes[entry["episode_index"]]["length"]
        assert frames == result.frames
        # The episode opens at the cube, not at the arm's rest pose (LeRobot's degrees; rest: each under 1).
        first = dataset[int(dataset.meta.episodes[entry["episode_index"]]["dataset_from_index"])]
        assert first["frame_index"] == 0 and float(first["observation.state"][:4].abs().max()) > 10
