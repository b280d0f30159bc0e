"""The converter's frame grid (so101.dataset.resample): a camera at the dataset's rate, its stamps jittered
as a real camera's are and at epoch times (where float64 resolves 0.2 us), gives one camera frame
per row, none repeated and none skipped, whichever stream started last."""

from __future__ import annotations

import numpy as np

from so101.dataset.resample import frame_times, sample_and_hold

FPS = 30.0
EPOCH = 1_795_640_370.0


def camera(start: float, count: int, jitter_s: float, seed: int) -> list[float]:
    rng = np.random.default_rng(seed)
    return sorted(start + k / FPS + rng.uniform(-jitter_s, jitter_s) for k in range(count))


def test_a_camera_at_the_dataset_rate_gives_one_frame_per_row_when_it_started_last():
    joints = [EPOCH + k / 100.0 for k in range(1000)]  # 100 Hz, from 0 s
    wrist = camera(EPOCH + 0.2, 250, jitter_s=0.0005, seed=1)  # the last to start: it sets the grid
    top = camera(EPOCH + 0.013, 255, jitter_s=0.0005, seed=2)
    instants = frame_times({"joints": joints, "wrist": wrist, "top": top}, FPS)
    assert len(instants) > 200
    assert instants[0] >= max(joints[0], wrist[0], top[0])
    for stamps in (wrist, top):
        held = sample_and_hold(stamps, instants)
        assert np.all(np.diff(held) == 1), f"rows repeat or skip frames: {np.diff(held)}"


def test_every_row_holds_a_value_and_none_past_the_shortest_stream():
    short = [EPOCH + k / FPS for k in range(10)]
    long = [EPOCH + k / 100.0 for k in range(100)]
    instants = frame_times({"short": short, "long": long}, FPS)
    assert instants[0] > short[0] and instants[-1] <= short[-1] + 1 / FPS
    assert sample_and_hold(short, instants).min() >= 0
