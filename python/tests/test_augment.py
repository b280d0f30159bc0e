"""so101-learn's image augmentation sets (so101.learn.augment), built by LeRobot as lerobot-train
builds them and applied to a camera frame."""

from __future__ import annotations

import json

import pytest
import torch

from so101.learn import augment, cli


def lerobot_transforms(sets: tuple[str, ...], at_once: int):
    """LeRobot's ImageTransforms from the settings the recipe passes to lerobot-train."""
    from lerobot.transforms.transforms import ImageTransformConfig, ImageTransforms, ImageTransformsConfig

    settings = augment.training_settings(sets)
    tfs = {name: ImageTransformConfig(**fields) for name, fields in json.loads(settings["dataset.image_transforms.tfs"]).items()}
    return ImageTransforms(ImageTransformsConfig(enable=True, max_num_transforms=at_once, tfs=tfs))


def test_sets_are_named_once_and_unknown_ones_refused(capsys):
    assert augment.parse_sets("colour, shift,colour") == ("colour", "shift")
    assert augment.parse_sets("none") == ()
    for wrong in ("wobble", "", "none,colour"):
        with pytest.raises(ValueError, match="unknown augmentation"):
            augment.parse_sets(wrong)
    with pytest.raises(SystemExit):
        cli.parser().parse_args(["act", "--augment", "colour,wobble"])
    assert "unknown augmentation wobble" in capsys.readouterr().err


def test_the_default_is_lerobots_colour_set_and_none_turns_it_off():
    colour = json.loads(augment.training_settings(("colour",))["dataset.image_transforms.tfs"])
    assert set(colour) == {"brightness", "contrast", "saturation", "hue", "sharpness"}
    assert augment.training_settings(()) == {"dataset.image_transforms.enable": "false"}


def test_every_set_transforms_a_frame_and_keeps_its_shape_and_range():
    frame = torch.rand(3, 72, 96)
    every = lerobot_transforms(augment.SETS, at_once=len(augment.transforms(augment.SETS)))
    out = every(frame)
    assert out.shape == frame.shape and out.dtype == frame.dtype
    assert float(out.min()) >= 0.0 and float(out.max()) <= 1.0
    assert not out.equal(frame)


def test_the_shift_moves_a_frame_by_at_most_two_pixels():
    frame = torch.zeros(3, 72, 96)
    frame[:, 36, 48] = 1.0  # one bright pixel in the middle
    shift = lerobot_transforms(("shift",), at_once=1)
    torch.manual_seed(0)
    moves = set()
    for _ in range(50):
        out = shift(frame)
        row, column = divmod(int(out[0].argmax()), 96)
        moves.add((row - 36, column - 48))
    assert all(abs(dy) <= 2 and abs(dx) <= 2 for dy, dx in moves), moves
    assert len(moves) > 3, moves  # it does move
