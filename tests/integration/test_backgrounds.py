"""Real backgrounds in sim frames, as a user gets them: stills of the (here: fake) cameras saved by
`so101_camera_node --snapshot`, named by a randomization file (`[scene] backgrounds = DIR`), shown
behind the arm, the cube and the bin by the fixed cameras, one picture drawn per episode and
camera, the same through both doors (in-process and the sim node); the wrist camera keeps the
sim's scenery. Pictures are decoded by Pillow.

    SO101_BIN_DIR=$CARGO_TARGET_DIR/release scripts/isolated .venv/bin/python -m pytest tests/integration/test_backgrounds.py
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from fake_camera import picture
from harness import node_binary, node_environment
from PIL import Image

import so101  # noqa: F401 - registers the envs

REPO = Path(__file__).resolve().parents[2]
SIZE = (72, 96)  # height, width
CAMERAS = {"top": SIZE, "front": SIZE, "wrist": SIZE}
# Uniform pictures: whatever the fitting, a background pixel is this colour (within JPEG's rounding).
COLOURS = {"top": [(200, 40, 200), (40, 200, 200)], "front": [(230, 150, 20), (90, 90, 230)]}


def uniform_backgrounds(folder: Path) -> Path:
    for camera, colours in COLOURS.items():
        (folder / "bg" / camera).mkdir(parents=True)
        for index, colour in enumerate(colours):
            Image.new("RGB", (640, 480), colour).save(folder / "bg" / camera / f"{index}.jpg", quality=95)
    return write_ranges(folder, "with.toml", 'backgrounds = "bg"')


def write_ranges(folder: Path, name: str, scene_line: str) -> Path:
    # The default ranges, and the scene section with or without backgrounds.
    path = folder / name
    path.write_text(f"[scene]\ntable_colour_jitter = 0.10\n{scene_line}\n")
    return path


def frames(randomize: Path, seed: int, backend: str = "inprocess") -> dict[str, np.ndarray]:
    env = gym.make("so101:so101/CubeToBin-v0", backend=backend, randomize=str(randomize), cameras=CAMERAS)
    try:
        observation, _ = env.reset(seed=seed)
        return {name: image.astype(int) for name, image in observation["pixels"].items()}
    finally:
        env.close()


def shown_colour(image: np.ndarray, plain: np.ndarray, camera: str) -> int:
    """Which of the camera's colours fills the pixels that differ from the plain render."""
    changed = image[np.any(image != plain, axis=-1)]
    distances = [np.abs(changed - np.array(colour)).max(axis=-1) for colour in COLOURS[camera]]
    index = int(np.argmin([np.median(d) for d in distances]))
    assert (distances[index] <= 3).all(), f"{camera}: pixels changed to something else than the picture"
    return index


def test_the_background_stands_behind_the_arm_cube_and_bin(tmp_path):
    with_backgrounds = uniform_backgrounds(tmp_path)
    without = write_ranges(tmp_path, "without.toml", "")
    # The same draw of everything else (the background is drawn last): the scene in front is the same.
    plain, keyed = frames(without, seed=5), frames(with_backgrounds, seed=5)
    for camera in ("top", "front"):
        changed = np.any(keyed[camera] != plain[camera], axis=-1)
        # Table, floor and sky replaced: most of the frame, yet not the arm, cube and bin.
        assert 0.6 < changed.mean() < 0.97, (camera, changed.mean())
        shown_colour(keyed[camera], plain[camera], camera)
        # The blue bin is still there, untouched (and the red cube, large enough from the front).
        r, g, b = (plain[camera][..., channel] for channel in range(3))
        blue = (b > r + 60) & (b > g + 30)
        assert blue.sum() > 10 and not changed[blue].any(), camera
        if camera == "front":
            red = (r > g + 120) & (r > b + 120)
            assert red.sum() > 3 and not changed[red].any(), camera
        # No key colour left over.
        assert not np.all(keyed[camera] == [0, 255, 0], axis=-1).any()
    # The wrist camera rides the arm: the sim's own scenery.
    np.testing.assert_array_equal(keyed["wrist"], plain["wrist"])


def test_each_episode_draws_a_picture_per_camera_the_same_through_both_doors(tmp_path):
    with_backgrounds = uniform_backgrounds(tmp_path)
    without = write_ranges(tmp_path, "without.toml", "")
    shown = {}
    for seed in range(6):
        plain, keyed = frames(without, seed), frames(with_backgrounds, seed)
        shown[seed] = {camera: shown_colour(keyed[camera], plain[camera], camera) for camera in COLOURS}
    for camera in COLOURS:
        assert {choice[camera] for choice in shown.values()} == {0, 1}, f"{camera} always shows the same picture"
    # The sim node draws the same picture for the same seed, and shows it the same way.
    for seed in (0, 1):
        plain = frames(without, seed)
        through_ros = frames(with_backgrounds, seed, backend="ros")
        in_process = frames(with_backgrounds, seed)
        for camera in COLOURS:
            assert shown_colour(through_ros[camera], plain[camera], camera) == shown[seed][camera]
            differ = np.any(through_ros[camera] != in_process[camera], axis=-1).mean()
            assert differ < 0.01, (camera, differ)


def test_a_camera_without_pictures_is_refused_with_what_to_do(tmp_path):
    (tmp_path / "bg" / "top").mkdir(parents=True)
    Image.new("RGB", (64, 48), (1, 2, 3)).save(tmp_path / "bg" / "top" / "a.jpg")
    ranges = write_ranges(tmp_path, "ranges.toml", 'backgrounds = "bg"')
    with pytest.raises(Exception, match=r"no picture for camera front.*--snapshot"):
        frames(ranges, seed=0)


def test_stills_of_the_cameras_become_the_sims_background(tmp_path):
    """--snapshot saves a still per camera (MJPEG passed through, YUYV encoded); a randomization
    file naming that folder shows them behind the sim's scene."""
    stills = tmp_path / "stills"
    done = subprocess.run(
        [str(node_binary("so101_camera_node")), "--camera", "top=fake:320x240@30", "--camera", "front=fake:yuyv,320x240@30",
         "--snapshot", str(stills)],
        env=node_environment(), capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    for camera in ("top", "front"):
        (path,) = sorted((stills / camera).glob("*.jpg"))
        assert f"{camera}: {path}" in done.stdout
        with Image.open(path) as still:
            image = np.asarray(still.convert("RGB")).astype(int)
        assert image.shape == (240, 320, 3)
        # The fake's picture (its blue channel counts frames): red across, green down.
        sequence = int(round(image[:, :, 2].mean() / 8))
        assert np.abs(image - picture(320, 240, sequence)).mean() < 4.0, camera
    ranges = write_ranges(tmp_path, "ranges.toml", f'backgrounds = "{stills}"')
    keyed = frames(ranges, seed=2)["top"]
    plain = frames(write_ranges(tmp_path, "plain.toml", ""), seed=2)["top"]
    changed = np.any(keyed != plain, axis=-1)
    # The still's gradient behind the scene: red grows to the right, green downwards.
    rows, columns = np.nonzero(changed)
    red, green = keyed[rows, columns, 0], keyed[rows, columns, 1]
    assert np.corrcoef(columns, red)[0, 1] > 0.95 and np.corrcoef(rows, green)[0, 1] > 0.95


def test_the_heldout_shift_set_shows_unseen_pictures_and_a_distractor(tmp_path):
    """`randomize="heldout"`: scikit-image's pictures behind the scene (fetched at set-up) and a
    distractor on the table that only the cameras see; the same file without the distractor draws
    the same episode, so the distractor is what differs, in one compact place of each view."""
    heldout = (REPO / "assets" / "randomization_heldout.toml").read_text()
    pictures = REPO / "assets" / "third_party" / "heldout_backgrounds"
    assert sorted(p.stem for p in (pictures / "top").glob("*.jpg")) == sorted(
        ["brick", "chelsea", "coffee", "grass", "gravel", "hubble_deep_field", "rocket"]
    )
    without = tmp_path / "no_distractor.toml"
    without.write_text(
        heldout.replace("distractor = true", "distractor = false").replace('"third_party/heldout_backgrounds"', f'"{pictures}"')
    )
    env = gym.make("so101:so101/CubeToBin-v0", randomize="heldout", cameras=CAMERAS)
    try:
        observation, info = env.reset(seed=7)
    finally:
        env.close()
    draw = info["episode_settings"]["draw"]
    assert draw["background"] is not None and draw["distractor"] is not None
    plain = frames(without, seed=7)
    for camera in ("top", "front"):
        changed = np.argwhere(np.any(observation["pixels"][camera].astype(int) != plain[camera], axis=-1))
        assert len(changed) > 10, camera
        (top, left), (bottom, right) = changed.min(axis=0), changed.max(axis=0)
        assert (bottom - top + 1) * (right - left + 1) < 0.15 * SIZE[0] * SIZE[1], (camera, top, left, bottom, right)
