"""so101-bench model_step builds so101-learn act's camera policy and times one training step of it
under each lever."""

import json

import pytest

from so101.bench import model_step


def camera_dataset(tmp_path, cameras=("top", "front", "wrist"), height=72, width=96):
    """A dataset directory with only what the benchmark reads: meta/info.json's features."""
    features = {"observation.state": {"dtype": "float32", "shape": [6]}, "action": {"dtype": "float32", "shape": [6]}}
    features |= {f"observation.images.{name}": {"dtype": "video", "shape": [height, width, 3]} for name in cameras}
    (tmp_path / "meta").mkdir()
    (tmp_path / "meta" / "info.json").write_text(json.dumps({"features": features}))
    return tmp_path


def test_the_variants_see_the_datasets_cameras_or_fewer_and_smaller(tmp_path):
    shapes = model_step.camera_shapes(camera_dataset(tmp_path))
    assert shapes == {f"observation.images.{name}": (3, 72, 96) for name in ("top", "front", "wrist")}
    assert model_step.variant_shapes("recipe", shapes) == shapes
    assert set(model_step.variant_shapes("small-images", shapes).values()) == {(3, 48, 64)}
    assert list(model_step.variant_shapes("two-cameras", shapes)) == ["observation.images.top", "observation.images.wrist"]
    two = {key: shapes[key] for key in list(shapes)[:2]}
    with pytest.raises(ValueError, match="would measure the recipe again"):
        model_step.variant_shapes("two-cameras", two)


def test_the_policy_is_the_recipes_and_each_lever_is_applied(tmp_path):
    import torch

    shapes = model_step.camera_shapes(camera_dataset(tmp_path, cameras=("top",), height=24, width=32))
    recipe = model_step.prepare("recipe", shapes, batch_size=2)
    config = recipe.policy.config
    assert (config.use_vae, config.dim_model, config.n_encoder_layers, config.chunk_size) == (False, 256, 2, 20)
    assert config.pretrained_backbone_weights is None and config.vision_backbone == "resnet18"
    assert recipe.optimizer.defaults["weight_decay"] == 1e-4 and recipe.grad_clip_norm == 10

    def first_conv(step):
        return next(m for m in step.policy.modules() if isinstance(m, torch.nn.Conv2d)).weight

    layout = torch.channels_last
    assert not first_conv(recipe).is_contiguous(memory_format=layout)
    channels_last = model_step.prepare("channels-last", shapes, batch_size=2)
    assert first_conv(channels_last).is_contiguous(memory_format=layout)
    assert channels_last.batch["observation.images.top"].is_contiguous(memory_format=layout)
    bf16 = model_step.prepare("bf16-autocast", shapes, batch_size=2)
    assert isinstance(bf16.autocast, torch.autocast) and bf16.autocast.fast_dtype == torch.bfloat16
    assert not first_conv(bf16).is_contiguous(memory_format=layout)
    both = model_step.prepare("bf16-channels-last", shapes, batch_size=2)
    assert isinstance(both.autocast, torch.autocast) and both.autocast.fast_dtype == torch.bfloat16
    assert first_conv(both).is_contiguous(memory_format=layout)
    assert both.batch["observation.images.top"].is_contiguous(memory_format=layout)
    compiled = model_step.prepare("compile", shapes, batch_size=2)
    assert hasattr(compiled.forward, "_torchdynamo_orig_callable") and not hasattr(recipe.forward, "_torchdynamo_orig_callable")

    before = first_conv(channels_last).detach().clone()
    channels_last()
    assert not first_conv(channels_last).detach().equal(before)  # a step trains the backbone


def test_a_dataset_without_cameras_is_refused(tmp_path):
    with pytest.raises(SystemExit, match="no cameras"):
        model_step.camera_shapes(camera_dataset(tmp_path, cameras=()))
