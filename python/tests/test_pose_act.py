"""pose_act (so101.policies.pose_act): LeRobot finds it as a policy type, it trains its estimator on
the recorded cube pose, acts from the cameras alone, and saves and loads through LeRobot's own
from_pretrained and processors."""

from __future__ import annotations

import json

import pytest
import torch
from lerobot.configs import FeatureType, PolicyFeature
from lerobot.policies.factory import get_policy_class, make_pre_post_processors
from lerobot.utils.constants import ACTION, OBS_ENV_STATE, OBS_STATE

from so101.policies.pose_act import PoseACTConfig

CAMERAS = ("observation.images.top", "observation.images.wrist")
FRAME = (3, 24, 32)


def features() -> dict:
    inputs = {OBS_STATE: PolicyFeature(FeatureType.STATE, (6,)), OBS_ENV_STATE: PolicyFeature(FeatureType.ENV, (7,))}
    inputs.update({key: PolicyFeature(FeatureType.VISUAL, FRAME) for key in CAMERAS})
    return inputs


def stats() -> dict:
    shapes = {OBS_STATE: (6,), OBS_ENV_STATE: (7,), ACTION: (6,), **{key: (3, 1, 1) for key in CAMERAS}}
    out = {key: {"mean": torch.zeros(shape), "std": torch.ones(shape)} for key, shape in shapes.items()}
    out[OBS_ENV_STATE] = {"mean": torch.tensor([0.2, 0.0, 0.77, 1.0, 0.0, 0.0, 0.0]), "std": torch.full((7,), 0.1)}
    return out


def small_config(**overrides) -> PoseACTConfig:
    settings = dict(
        input_features=features(),
        output_features={ACTION: PolicyFeature(FeatureType.ACTION, (6,))},
        device="cpu",
        use_vae=False,
        dim_model=32,
        n_heads=2,
        dim_feedforward=64,
        n_encoder_layers=1,
        n_decoder_layers=1,
        chunk_size=4,
        n_action_steps=4,
        estimator_channels=8,
        estimator_keypoints=4,
        estimator_hidden=16,
        estimator_warmup_steps=0,
        pretrained_backbone_weights=None,
    )
    settings.update(overrides)
    return PoseACTConfig(**settings)


def batch(size: int = 4, pose: torch.Tensor | None = None) -> dict:
    generator = torch.Generator().manual_seed(0)
    out = {OBS_STATE: torch.randn(size, 6, generator=generator)}
    out.update({key: torch.rand(size, *FRAME, generator=generator) for key in CAMERAS})
    out[OBS_ENV_STATE] = pose if pose is not None else torch.randn(size, 7, generator=generator) * 0.1 + 0.5
    out[ACTION] = torch.randn(size, 4, 6, generator=generator)
    out["action_is_pad"] = torch.zeros(size, 4, dtype=torch.bool)
    return out


def test_lerobot_finds_the_type_and_its_policy_class():
    assert get_policy_class("pose_act").__name__ == "PoseACTPolicy"


def test_the_pose_is_a_training_target_not_an_input():
    config = small_config()
    policy = get_policy_class("pose_act")(config, dataset_stats=stats())
    assert OBS_ENV_STATE not in config.input_features
    assert set(config.image_features) == set(CAMERAS)
    assert torch.allclose(policy.pose_mean, stats()[OBS_ENV_STATE]["mean"])
    # The state ACT inside acts on the joints and a pose, and sees no camera.
    assert set(policy.act.config.input_features) == {OBS_STATE, OBS_ENV_STATE}


def test_a_dataset_without_cameras_is_refused():
    config = small_config(input_features={OBS_STATE: features()[OBS_STATE], OBS_ENV_STATE: features()[OBS_ENV_STATE]})
    with pytest.raises(ValueError, match="cameras"):
        get_policy_class("pose_act")(config, dataset_stats=stats())


def test_training_without_the_recorded_pose_is_refused():
    policy = get_policy_class("pose_act")(small_config(), dataset_stats=stats())
    incomplete = batch()
    del incomplete[OBS_ENV_STATE]
    with pytest.raises(ValueError, match="environment_state"):
        policy.forward(incomplete)


def test_training_brings_the_estimate_to_the_recorded_pose():
    torch.manual_seed(0)
    policy = get_policy_class("pose_act")(small_config(estimator_lr=3e-3), dataset_stats=stats())
    # The pose is in the pictures: a bright square on the top camera, its column the cube's x.
    # The cube lies flat at the mean pose but for its x.
    data = batch(16, pose=stats()[OBS_ENV_STATE]["mean"].repeat(16, 1))
    data[OBS_ENV_STATE][:, 0] = torch.linspace(0.1, 0.3, 16)
    data[OBS_STATE] = torch.zeros(16, 6)  # the arm still: the gripper in one place
    data[CAMERAS[0]] = torch.zeros(16, *FRAME)
    for row, column in enumerate(range(4, 4 + 16 + 8, 1)[:16]):
        data[CAMERAS[0]][row, :, 10:14, column : column + 4] = 1.0
    optimizer = torch.optim.AdamW(policy.get_optim_params(), lr=1e-3)
    policy.train()
    first = None
    for _ in range(400):
        loss, losses = policy.forward(data)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        first = losses["pose_loss"] if first is None else first
    assert losses["pose_loss"] < 0.1 * first
    assert int(policy.trained_steps) == 400
    policy.eval()
    with torch.no_grad():
        estimate = policy.estimated_pose(data)
    assert (estimate[:, 0] - data[OBS_ENV_STATE][:, 0]).abs().max() < 0.02


def test_actions_come_from_the_cameras_whatever_pose_is_given():
    policy = get_policy_class("pose_act")(small_config(), dataset_stats=stats())
    policy.eval()
    observation = batch(1)
    without = {key: value for key, value in observation.items() if key != OBS_ENV_STATE}
    chunk = policy.predict_action_chunk(without)
    observation[OBS_ENV_STATE] = torch.full((1, 7), 99.0)
    assert torch.equal(policy.predict_action_chunk(observation), chunk)
    policy.reset()
    assert policy.select_action(without).shape == (1, 6)


def test_saved_and_loaded_by_lerobot_with_the_same_actions(tmp_path):
    config = small_config()
    policy = get_policy_class("pose_act")(config, dataset_stats=stats())
    policy.eval()
    preprocessor, postprocessor = make_pre_post_processors(config, dataset_stats=stats())
    policy.save_pretrained(tmp_path)
    preprocessor.save_pretrained(tmp_path)
    postprocessor.save_pretrained(tmp_path)
    saved = json.loads((tmp_path / "config.json").read_text())
    assert saved["type"] == "pose_act" and OBS_ENV_STATE not in saved["input_features"]

    loaded = get_policy_class("pose_act").from_pretrained(tmp_path)
    loaded.eval()
    assert torch.equal(loaded.pose_mean, policy.pose_mean)
    pre, _ = make_pre_post_processors(loaded.config, pretrained_path=str(tmp_path))
    observation = {key: value for key, value in batch(1).items() if key in (OBS_STATE, *CAMERAS)}
    assert torch.equal(loaded.predict_action_chunk(pre(observation)), policy.predict_action_chunk(preprocessor(observation)))


def test_lerobots_plugin_discovery_registers_the_type_in_a_fresh_process():
    import subprocess
    import sys

    probe = (
        "from lerobot.configs import PreTrainedConfig\n"
        "before = 'pose_act' in PreTrainedConfig.get_known_choices()\n"
        "from lerobot.utils.import_utils import register_third_party_plugins\n"
        "register_third_party_plugins()\n"
        "print(before, 'pose_act' in PreTrainedConfig.get_known_choices())\n"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["False", "True"]


def test_the_estimator_reads_the_joints_beside_the_cameras():
    observation = batch(2)
    moved = dict(observation)
    moved[OBS_STATE] = observation[OBS_STATE] + 1.0  # the same pictures, the arm elsewhere
    for reads, differs in ((True, True), (False, False)):
        torch.manual_seed(0)
        policy = get_policy_class("pose_act")(small_config(estimator_reads_joints=reads), dataset_stats=stats())
        policy.eval()
        with torch.no_grad():
            relative = [policy._estimate(data) for data in (observation, moved)]
        assert (not torch.allclose(*relative)) is differs


def test_an_estimator_that_reads_joints_refuses_pictures_alone():
    from so101.policies.pose_act.estimator import CubePoseEstimator

    estimator = CubePoseEstimator([FRAME], pose_dim=7, channels=8, keypoints=4, hidden=16, joints=6)
    with pytest.raises(ValueError, match="6 joints"):
        estimator([torch.rand(1, *FRAME)])
