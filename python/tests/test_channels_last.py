"""so101.learn.channels_last: under mixed precision a camera policy LeRobot builds trains with its
convolutions in channels_last; a float32 one, or one without images, is left as LeRobot made it;
and the optimizer's channels_last moments, which safetensors refuses, are saved by LeRobot's own
saver once its save_file makes them contiguous, and read back by LeRobot's own loader."""

from __future__ import annotations

import pytest
import torch
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.optim import optimizers
from lerobot.optim.optimizers import load_optimizer_state, save_optimizer_state
from lerobot.policies.act.configuration_act import ACTConfig

from so101.learn.channels_last import contiguous_tensors, making_channels_last, saving_contiguous, wants_channels_last

STATE = {"observation.state": PolicyFeature(type=FeatureType.STATE, shape=(6,))}
CAMERA = {"observation.images.top": PolicyFeature(type=FeatureType.VISUAL, shape=(3, 24, 32))}
ACTION = {"action": PolicyFeature(type=FeatureType.ACTION, shape=(6,))}


def act_config(use_amp: bool, cameras: bool) -> ACTConfig:
    return ACTConfig(
        input_features=STATE | (CAMERA if cameras else {}),
        output_features=ACTION,
        use_amp=use_amp,
        pretrained_backbone_weights=None,
        device="cpu",
    )


@pytest.mark.parametrize(("use_amp", "cameras", "wanted"), [(True, True, True), (False, True, False), (True, False, False)])
def test_only_a_mixed_precision_policy_with_cameras_wants_channels_last(use_amp, cameras, wanted):
    assert wants_channels_last(act_config(use_amp, cameras)) is wanted


def convolutions_in(policy: torch.nn.Module) -> list[torch.Tensor]:
    return [parameter for parameter in policy.parameters() if parameter.dim() == 4]


@pytest.mark.parametrize("use_amp", [True, False])
def test_the_policy_lerobot_makes_is_turned_channels_last_under_mixed_precision_only(use_amp):
    from lerobot.policies.act.modeling_act import ACTPolicy

    config = act_config(use_amp, cameras=True)
    make = making_channels_last(lambda cfg, **_: ACTPolicy(cfg))
    policy = make(cfg=config, ds_meta=None)
    weights = convolutions_in(policy)
    assert weights  # ResNet-18's
    layout = torch.channels_last if use_amp else torch.contiguous_format
    assert all(weight.is_contiguous(memory_format=layout) for weight in weights)
    assert all(weight.is_contiguous() for weight in weights) is not use_amp


def stepped_optimizer() -> tuple[torch.nn.Module, torch.optim.Optimizer]:
    torch.manual_seed(0)
    model = torch.nn.Conv2d(3, 8, 3).to(memory_format=torch.channels_last)
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-3)
    model(torch.rand(2, 3, 12, 16)).square().mean().backward()
    optimizer.step()
    return model, optimizer


def test_lerobots_saver_refuses_channels_last_moments_and_takes_them_made_contiguous(tmp_path, monkeypatch):
    model, optimizer = stepped_optimizer()
    assert not optimizer.state[model.weight]["exp_avg"].is_contiguous()
    with pytest.raises(ValueError, match="contiguous"):
        save_optimizer_state(optimizer, tmp_path / "plain")
    monkeypatch.setattr(optimizers, "save_file", saving_contiguous(optimizers.save_file))
    saved = tmp_path / "contiguous"
    saved.mkdir()
    save_optimizer_state(optimizer, saved)

    _, fresh = stepped_optimizer()
    for state in fresh.state.values():
        for value in state.values():
            value.zero_()
    loaded = load_optimizer_state(fresh, saved)
    for name in ("exp_avg", "exp_avg_sq"):
        assert loaded.state[next(iter(loaded.state))][name].equal(optimizer.state[model.weight][name])


def test_a_dict_of_optimizers_is_saved_one_by_one_in_lerobots_layout(tmp_path, monkeypatch):
    _, first = stepped_optimizer()
    _, second = stepped_optimizer()
    monkeypatch.setattr(optimizers, "save_file", saving_contiguous(optimizers.save_file))
    save_optimizer_state({"policy": first, "critic": second}, tmp_path)
    assert {path.name for path in tmp_path.iterdir()} == {"policy", "critic"}
    assert all(any((tmp_path / name).iterdir()) for name in ("policy", "critic"))


def test_contiguous_tensors_makes_every_tensor_contiguous_with_its_values():
    strided = torch.rand(2, 3, 4, 5).to(memory_format=torch.channels_last)
    made = contiguous_tensors({"state.0.exp_avg": strided, "state.0.step": torch.tensor(1.0)})
    assert all(tensor.is_contiguous() for tensor in made.values())
    assert made["state.0.exp_avg"].equal(strided) and made["state.0.step"].item() == 1.0
