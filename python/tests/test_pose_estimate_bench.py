"""so101-bench pose_estimate's bookkeeping: each frame's error lands in the bin of the gripper's
distance to the cube, and the last row holds every frame."""

from __future__ import annotations

import numpy as np
import pytest

from so101.bench.pose_estimate import DISTANCE_BINS, EstimateLog, bin_labels, binned


def test_frames_are_binned_by_the_grippers_distance_to_the_cube():
    log = EstimateLog()
    cube = np.array([0.2, 0.0, 0.77, 1.0, 0.0, 0.0, 0.0])
    # (gripper's distance along x, the estimate's error along y), m
    for distance, error in [(0.01, 0.004), (0.015, 0.006), (0.03, 0.010), (0.2, 0.030)]:
        estimate = cube.copy()
        estimate[1] += error
        log.add(estimate, cube, cube[:3] + np.array([distance, 0.0, 0.0]))
    rows = binned(log)
    assert len(rows) == len(bin_labels()) + 1 == len(DISTANCE_BINS) + 2
    assert [row["frames"] for row in rows] == [2, 1, 0, 1, 4]
    assert rows[0]["mean_mm"] == pytest.approx(5.0) and rows[0]["median_mm"] == pytest.approx(5.0)
    assert rows[1]["median_mm"] == pytest.approx(10.0)
    assert rows[2]["mean_mm"] is None
    assert rows[3]["median_mm"] == pytest.approx(30.0)
    assert rows[4]["mean_mm"] == pytest.approx(12.5)


def test_the_labels_name_the_bins_edges():
    assert bin_labels() == ["< 2 cm", "2-5 cm", "5-10 cm", "> 10 cm"]
