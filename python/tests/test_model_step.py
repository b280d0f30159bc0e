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


def test_the_policy_is_the_recipes(tmp_path):
    shapes = model_step.camera_shapes(camera_dataset(tmp_path, cameras=("top",), height=24, width=32))
    config = model_step.build_policy(shapes).config
    assert (config.use_vae, config.dim_model, config.n_encoder_layers, config.chunk_size) == (False, 256, 2, 20)
    assert config.pretrained_backbone_weights is None and config.vision_backbone == "resnet18"
    assert model_step.measure("channels-last", shapes, batch_size=2, steps=1) > 0


def test_a_dataset_without_cameras_is_refused(tmp_path):
    with pytest.raises(SystemExit, match="no cameras"):
        model_step.camera_shapes(camera_dataset(tmp_path, cameras=()))
