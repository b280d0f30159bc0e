"""The converter on cameras recorded compressed (sensor_msgs/CompressedImage, JPEG and PNG, with the
`format` strings image_transport writes), in bags written by the independent writer (bag_writer.py,
no DDS): the dataset's frames are the recorded frames decoded, exactly those a whole-episode
resampling in memory picks (the converter streams); a frame that does not decode skips its
episode, or its part, with the reason while the rest is converted; a camera recorded both raw and
compressed is read raw."""

from __future__ import annotations

import io

import numpy as np
import pytest
from bag_writer import EpisodeBag
from PIL import Image

from so101.dataset.convert import main

FPS = 30
WIDTH, HEIGHT = 40, 32
FORMATS = {"jpeg": "rgb8; jpeg compressed bgr8", "png": "bgr8; png compressed bgr8", "plain-png": "png"}


def pixels(k: int, camera: str) -> np.ndarray:
    """Frame k of a camera: smooth gradients that move with k (JPEG-friendly), unlike any other."""
    y, x = np.mgrid[0:HEIGHT, 0:WIDTH]
    shift = 3 if camera == "top" else 11
    planes = [(x * 4 + k * shift) % 256, (y * 6 + k * 5) % 256, (x + y + k * shift * 2) % 256]
    return np.stack(planes, axis=-1).astype(np.uint8)


def encoded(image: np.ndarray, kind: str) -> bytes:
    out = io.BytesIO()
    if kind == "jpeg":
        Image.fromarray(image).save(out, format="JPEG", quality=90)
    else:
        Image.fromarray(image).save(out, format="PNG")
    return out.getvalue()


def decoded(data: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))


# Per camera: (rate, the frames' stamps) of every synthetic episode.
RATES = {"top": 30, "wrist": 15}


def episode(directory, kind: str, end: float = 2.0, damage=None, silent=None, raw_too: bool = False) -> dict:
    """An episode whose `top` camera (30 Hz) is recorded as `kind` (raw, jpeg, png, plain-png) and
    `wrist` (15 Hz) raw; joint states at 100 Hz, the cube at 30 Hz, one command at 0.05 s.
    `damage`: (frame k of top, how) with how "truncated" (half its bytes) or "garbage" (no image at
    all); `silent`: (from, to) s without top frames. Returns {camera: [(stamp, expected pixels)]}
    and {"end": end}."""
    bag = EpisodeBag(directory)
    for k in range(int(round(end * 100)) + 1):
        bag.joint_state(k / 100, [0.001 * k, 0.0, 0.0, 0.0, 0.0, 0.0])
    for k in range(int(round(end * FPS)) + 1):
        bag.cube(k / FPS)
    expected: dict[str, list] = {"top": [], "wrist": []}
    for camera, rate in RATES.items():
        for k in range(int(round(end * rate)) + 1):
            t = k / rate
            if camera == "top" and silent and silent[0] < t < silent[1]:
                continue
            image = pixels(k, camera)
            if camera == "wrist" or kind == "raw" or raw_too:
                bag.image(t, camera, WIDTH, HEIGHT, pixels=image.tobytes())
            if camera == "top" and kind != "raw":
                data = encoded(image, "jpeg" if kind == "jpeg" else "png")
                if damage and damage[0] == k:
                    # Truncated: cut within the compressed pixels (past the start-of-scan marker).
                    scan = data.index(b"\xff\xda")
                    data = data[: (scan + len(data)) // 2] if damage[1] == "truncated" else b"\x00" * 64
                bag.compressed_image(t, camera, data, FORMATS[kind])
                if not raw_too:
                    image = decoded(data) if not (damage and damage[0] == k) else None
            expected[camera].append((t, image))
    bag.array_command(0.05, [0.0, 0.0, 0.0, 0.0, 0.0, 0.5])
    bag.close()
    return expected | {"end": end}


def reference(expected: dict, start: float, count: int) -> dict[str, np.ndarray]:
    """The frames a whole-episode resampling picks: frame j holds each camera's latest frame at or
    before start + j / FPS (zero-order hold, as so101.dataset.resample defines it)."""
    out = {}
    for camera in RATES:
        frames = expected[camera]
        stamps = np.array([t for t, _ in frames])
        picked = [np.searchsorted(stamps, start + j / FPS + 1e-9, side="right") - 1 for j in range(count)]
        out[camera] = np.stack([frames[i][1] for i in picked])
    return out


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    import contextlib

    bags = tmp_path_factory.mktemp("bags")
    expected = {
        0: episode(bags / "episode_000000", "raw"),
        1: episode(bags / "episode_000001", "png"),
        2: episode(bags / "episode_000002", "jpeg"),
    }
    episode(bags / "episode_000003", "jpeg", damage=(20, "truncated"))  # decodes badly: skipped
    episode(bags / "episode_000004", "jpeg", damage=(20, "garbage"))  # no JPEG at all: skipped
    expected[5] = episode(bags / "episode_000005", "jpeg", raw_too=True)  # read raw
    # Split at a 1 s silence of `top` into two parts; a broken frame in the first leaves it out.
    expected[6] = episode(bags / "episode_000006", "jpeg", end=3.0, damage=(10, "truncated"), silent=(1.0, 2.0))
    expected[7] = episode(bags / "episode_000007", "plain-png")
    output = tmp_path_factory.mktemp("out") / "dataset"
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        status = main(
            [str(bags), "--output", str(output), "--no-videos", "--quiet", "--units", "radians", "--repo-id", "local/c"]
        )
    return status, out.getvalue(), output, expected


def test_corrupt_frames_are_reported_and_only_their_episode_or_part_is_left_out(converted):
    status, summary, _, _ = converted
    assert status == 0, summary
    skipped = [line.removeprefix("  skipped: ") for line in summary.splitlines() if line.startswith("  skipped: ")]
    assert len(skipped) == 3, summary
    assert skipped[0].startswith("episode_000003: camera 'top': the frame at t=0.667 s: JPEG image that does not decode")
    assert "truncated" in skipped[0], skipped[0]
    assert skipped[1].startswith("episode_000004: /camera/top/image_raw/compressed: 64 bytes that are no JPEG image"), skipped[1]
    assert skipped[2].startswith("episode_000006 part 1/2: camera 'top': the frame at t=0.333 s"), skipped[2]
    assert summary.startswith("6 episode(s)"), summary


# so101.dataset.resample: frame 0 is half a frame after every stream has started.
GRID_OFFSET = 0.5 / FPS


@pytest.mark.parametrize(
    ("index", "source", "start"),
    [(0, 0, 0.05), (1, 1, 0.05), (2, 2, 0.05), (3, 5, 0.05), (4, 6, 2.0), (5, 7, 0.05)],
    ids=["raw", "png", "jpeg", "raw-and-jpeg", "jpeg-second-part", "plain-png"],
)
def test_frames_are_the_recorded_frames_a_whole_episode_resampling_picks(converted, index, source, start):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    _, _, output, expected = converted
    dataset = LeRobotDataset("local/c", root=output)
    first, last = dataset.meta.episodes["dataset_from_index"][index], dataset.meta.episodes["dataset_to_index"][index]
    assert last - first >= 25
    frames = dataset.hf_dataset.with_format("numpy")[first:last]
    # The state's first joint is the joint state's index / 1000 (100 Hz): frame j at start + half a
    # frame + j / FPS, held.
    states = np.arange(int(round(expected[source]["end"] * 100)) + 1) / 100
    held = [np.searchsorted(states, start + GRID_OFFSET + j / FPS + 1e-9, side="right") - 1 for j in range(last - first)]
    np.testing.assert_allclose(np.stack(frames["observation.state"])[:, 0], np.array(held) / 1000, atol=1e-7)
    want = reference(expected[source], start + GRID_OFFSET, last - first)
    for camera in ("top", "wrist"):
        got = np.stack([np.asarray(dataset[first + j][f"observation.images.{camera}"]) for j in range(last - first)])
        got = np.round(got.transpose(0, 2, 3, 1) * 255).astype(np.uint8)
        assert np.array_equal(got, want[camera]), f"{camera}: frames differ from the recorded ones"
