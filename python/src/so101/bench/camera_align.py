"""How well so101-camera-align places a camera: the simulation as the "real" camera, the board laid
in the scene as the docs say (each --boards layout), each of the scene's fixed cameras moved to
--poses random poses the
estimate is not told (up to 4 cm, 6 degrees and 5 degrees of field of view from the scene's),
rendered at 640x480, placed from that one picture, and the frame rendered again from the estimate.
Reports the position and angle errors, the reprojection error of the fit and the overlay error
(how far the board's corners move between the original and the re-rendered frame).

    so101-bench camera_align [--poses 10] [--seed 2000] [--boards a3,a4]
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
from pathlib import Path

import cv2
import numpy as np

from ..cameras.board import Board
from ..cameras.placement import (
    AlignError,
    Placement,
    corners_by_point,
    estimate,
    matrix_from_quaternion,
    quaternion_from_matrix,
    write_placements,
)
from ..cameras.sim_board import ideal_calibration, picture, scene_cameras, scene_with_board
from ..envs.inprocess import default_scene
from ..subcommands import Subcommand, run_alone

SIZE = (480, 640)
MAX_SHIFT_M = 0.04
MAX_TURN_DEG = 6.0
MAX_FOVY_CHANGE_DEG = 5.0


def random_pose(rng: np.random.Generator, position, rotation, fovy) -> Placement:
    shift = rng.uniform(-1, 1, 3)
    shift *= MAX_SHIFT_M * rng.uniform() / max(np.linalg.norm(shift), 1e-9)
    axis = rng.normal(size=3)
    turn, _ = cv2.Rodrigues(axis / np.linalg.norm(axis) * math.radians(rng.uniform(0, MAX_TURN_DEG)))
    height, width = SIZE
    return Placement(
        position + shift, quaternion_from_matrix(turn @ rotation), fovy + rng.uniform(-1, 1) * MAX_FOVY_CHANGE_DEG, width, height
    )


def overlay_px(original: np.ndarray, again: np.ndarray, board: Board) -> float:
    """RMS distance (px) between the board corners both frames show."""
    before, after = corners_by_point(original, board), corners_by_point(again, board)
    common = before.keys() & after.keys()
    return math.sqrt(np.mean([np.sum((after[k] - before[k]) ** 2) for k in common]))


def measure(scene: Path, directory: Path, board: Board, camera: str, truth: Placement) -> dict:
    told = directory / "untold.toml"
    write_placements(told, {camera: truth})
    original = cv2.cvtColor(picture(scene, str(told), camera, SIZE), cv2.COLOR_RGB2BGR)
    placed = estimate(original, ideal_calibration(truth.fovy, truth.width, truth.height), board)
    found = directory / "found.toml"
    write_placements(found, {camera: placed})
    again = cv2.cvtColor(picture(scene, str(found), camera, SIZE), cv2.COLOR_RGB2BGR)
    turn, _ = cv2.Rodrigues(matrix_from_quaternion(placed.quaternion) @ matrix_from_quaternion(truth.quaternion).T)
    return {
        "position_mm": 1000 * float(np.linalg.norm(placed.position - truth.position)),
        "angle_deg": math.degrees(float(np.linalg.norm(turn))),
        "reprojection_px": placed.estimate["reprojection_rms_px"],
        "overlay_px": overlay_px(original, again, board),
        "corners": placed.estimate["corners"],
    }


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--bin-dir", type=Path, default=None, help="the built binaries (scripts/bench.sh passes it; unused)")
    p.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    p.add_argument("--poses", type=int, default=10, help="untold poses per camera")
    p.add_argument("--seed", type=int, default=2000, help="seed of the poses (kept apart from the test's)")
    p.add_argument("--boards", default="a3,a4", help="board layouts to lay, comma-separated (default a3,a4)")


def run(args: argparse.Namespace) -> int:
    results: dict[str, list[dict]] = {}
    failures: dict[str, int] = {}
    with tempfile.TemporaryDirectory(prefix="so101_camera_align_") as tmp:
        directory = Path(tmp)
        for layout in args.boards.split(","):
            board = Board(layout)
            scene = scene_with_board(default_scene(), directory, board)
            # The same poses for every board.
            rng = np.random.default_rng(args.seed)
            for camera, (position, rotation, fovy) in scene_cameras(default_scene()).items():
                key = f"{layout} {camera}"
                results[key], failures[key] = [], 0
                for _ in range(args.poses):
                    try:
                        results[key].append(measure(scene, directory, board, camera, random_pose(rng, position, rotation, fovy)))
                    except AlignError:
                        failures[key] += 1
    print(
        "| board, camera | poses placed | position error mm (mean / max) | angle error deg (mean / max) | reprojection px | overlay px (mean / max) |"
    )
    print("|---|---|---|---|---|---|")
    for key, rows in results.items():
        if not rows:
            print(f"| {key} | 0 of {failures[key]} | | | | |")
            continue
        column = {name: np.array([row[name] for row in rows]) for name in rows[0]}
        print(
            f"| {key} | {len(rows)} of {len(rows) + failures[key]} "
            f"| {column['position_mm'].mean():.2f} / {column['position_mm'].max():.2f} "
            f"| {column['angle_deg'].mean():.3f} / {column['angle_deg'].max():.3f} "
            f"| {column['reprojection_px'].mean():.2f} "
            f"| {column['overlay_px'].mean():.2f} / {column['overlay_px'].max():.2f} |"
        )
    for layout in args.boards.split(","):
        rows = [row for key, values in results.items() if key.startswith(f"{layout} ") for row in values]
        if rows:
            worst_mm = max(row["position_mm"] for row in rows)
            worst_deg = max(row["angle_deg"] for row in rows)
            mean_px = float(np.mean([row["reprojection_px"] for row in rows]))
            print(
                f"camera alignment error ({layout} board): {worst_mm:.1f} mm, {worst_deg:.2f} deg "
                f"(reprojection {mean_px:.2f} px), worst of {len(rows)} untold poses"
            )
    if args.json:
        args.json.write_text(json.dumps({"results": results, "failures": failures}, indent=2))
    return 0


SUBCOMMAND = Subcommand("camera placement from one picture of the board: errors on untold poses", add_arguments, run, __doc__)


def main(argv: list[str] | None = None) -> int:
    return run_alone("so101-bench camera_align", SUBCOMMAND, argv)


if __name__ == "__main__":
    raise SystemExit(main())
