"""so101-learn backgrounds: the pictures it draws (seeded, varied) and the folder it writes, as the
simulation shows it: each fixed camera's picture behind the scene, decoded by the simulation's own
reader and compared here with Pillow's decoding of the same file; the wrist camera untouched."""

from __future__ import annotations

import tomllib

import gymnasium as gym
import numpy as np
import pytest
from PIL import Image

import so101  # noqa: F401 - registers the envs
from so101.learn import cli, procedural_backgrounds
from so101.learn.procedural_backgrounds import draw_background, fixed_cameras

SIZE = (96, 72)  # width, height: the render's own, so fitting a picture to the frame changes nothing
CAMERAS = {name: (SIZE[1], SIZE[0]) for name in ("top", "front", "wrist")}


def test_the_same_numbers_draw_the_same_picture_and_other_numbers_others():
    first = draw_background(3, "top", 7, SIZE)
    assert first.shape == (72, 96, 3) and first.dtype == np.uint8
    np.testing.assert_array_equal(first, draw_background(3, "top", 7, SIZE))
    others = (draw_background(3, "top", 8, SIZE), draw_background(3, "front", 7, SIZE), draw_background(4, "top", 7, SIZE))
    for other in others:
        assert np.abs(first.astype(int) - other).mean() > 10


def test_pictures_vary_in_colour_and_each_has_structure():
    pictures = [draw_background(0, "front", number, SIZE).astype(float) for number in range(30)]
    # Each is more than a flat colour, and they are not one colour scheme.
    assert min(picture.std(axis=(0, 1)).max() for picture in pictures) > 3
    means = np.array([picture.mean(axis=(0, 1)) for picture in pictures])
    assert means.std(axis=0).min() > 15
    # Some are dark, some bright.
    brightness = means.mean(axis=1)
    assert brightness.min() < 90 and brightness.max() > 150


def frames(randomize, seed):
    env = gym.make("so101:so101/CubeToBin-v0", backend="inprocess", randomize=str(randomize), cameras=CAMERAS)
    try:
        observation, info = env.reset(seed=seed)
    finally:
        env.close()
    return {name: image.astype(int) for name, image in observation["pixels"].items()}, info["episode_settings"]["draw"]


def test_the_folder_written_is_shown_behind_the_fixed_cameras_scene(tmp_path, capsys):
    output = tmp_path / "scenes"
    assert cli.main(["backgrounds", "--output", str(output), "--count", "3", "--size", "96x72", "--seed", "5"]) == 0
    ranges = output / procedural_backgrounds.RANDOMIZATION_FILE
    assert f"--randomize {ranges}" in capsys.readouterr().out
    assert fixed_cameras() == ("top", "front")
    assert sorted(p.name for p in output.iterdir()) == ["front", "randomization.toml", "top"]
    pictures = {}
    for camera in fixed_cameras():
        files = sorted((output / camera).glob("*.jpg"))
        assert len(files) == 3
        pictures[camera] = [np.asarray(Image.open(path).convert("RGB")).astype(int) for path in files]
        assert all(picture.shape == (72, 96, 3) for picture in pictures[camera])
    assert tomllib.loads(ranges.read_text())["scene"] == {"backgrounds": ".", "distractor": True}

    # The same draws but the background and the distractor (drawn last): what differs is them.
    plain_ranges = tmp_path / "plain.toml"
    plain_ranges.write_text("[scene]\ntable_colour_jitter = 0.10\n")
    shown = {camera: set() for camera in fixed_cameras()}
    for seed in range(6):
        plain, _ = frames(plain_ranges, seed)
        keyed, draw = frames(ranges, seed)
        assert draw["background"] is not None and draw["distractor"] is not None
        for camera in fixed_cameras():
            changed = np.any(keyed[camera] != plain[camera], axis=-1)
            assert 0.5 < changed.mean() < 0.97, (camera, changed.mean())
            # Behind the scene stands one of the camera's pictures, pixel for pixel but for the
            # distractor's few and the two JPEG decoders' rounding.
            agree = [(np.abs(keyed[camera][changed] - picture[changed]).max(axis=-1) <= 6).mean() for picture in pictures[camera]]
            assert max(agree) > 0.9, (camera, agree)
            shown[camera].add(int(np.argmax(agree)))
    for camera, numbers in shown.items():
        assert len(numbers) > 1, f"{camera} showed the same picture in every episode"


def test_no_distractor_when_asked_and_the_wrist_camera_keeps_the_sims_scenery(tmp_path):
    procedural_backgrounds.write(tmp_path / "scenes", count=1, seed=0, size=SIZE, distractor=False)
    keyed, draw = frames(tmp_path / "scenes" / procedural_backgrounds.RANDOMIZATION_FILE, seed=0)
    assert draw["background"] is not None and draw["distractor"] is None
    plain_ranges = tmp_path / "plain.toml"
    plain_ranges.write_text("[scene]\ntable_colour_jitter = 0.10\n")
    plain, _ = frames(plain_ranges, seed=0)
    assert np.any(keyed["top"] != plain["top"])
    np.testing.assert_array_equal(keyed["wrist"], plain["wrist"])


def test_a_second_run_replaces_its_pictures_and_others_are_refused(tmp_path, capsys):
    procedural_backgrounds.write(tmp_path, count=3, seed=0, size=SIZE, distractor=True)
    procedural_backgrounds.write(tmp_path, count=1, seed=1, size=SIZE, distractor=True)
    for camera in fixed_cameras():
        (only,) = sorted((tmp_path / camera).glob("*.jpg"))
        written = np.asarray(Image.open(only)).astype(int)
        # The second run's picture (within JPEG's loss), not the first's.
        assert np.median(np.abs(written - draw_background(1, camera, 0, SIZE))) <= 4
        assert np.abs(written - draw_background(0, camera, 0, SIZE)).mean() > 20
    assert "--count 1 --seed 1 --size 96x72" in (tmp_path / procedural_backgrounds.RANDOMIZATION_FILE).read_text()
    Image.new("RGB", SIZE, (1, 2, 3)).save(tmp_path / "front" / "my_desk.jpg")
    assert cli.main(["backgrounds", "--output", str(tmp_path), "--count", "2", "--size", "96x72"]) == 2
    assert "my_desk.jpg" in capsys.readouterr().err
    assert len(list((tmp_path / "top").glob("*.jpg"))) == 1, "nothing is written when a folder is refused"


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["--count", "0"], "at least 1"),
        (["--seed", "-1"], "at least 0"),
        (["--size", "640"], "WIDTHxHEIGHT"),
        (["--size", "8x8"], "from 16 to 4096"),
    ],
)
def test_bad_arguments_are_refused(tmp_path, capsys, arguments, message):
    with pytest.raises(SystemExit) as refused:
        cli.main(["backgrounds", "--output", str(tmp_path / "x"), *arguments])
    assert refused.value.code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
