"""A camera's place from one picture of the board: the board's corners found in the picture, the
camera's pose solved from them (OpenCV's solvePnP with the camera's calibration), turned into the
arm's base frame, and written as the camera placements file the simulation loads
(so101_sim_node --camera-poses, the Gymnasium envs' and LeRobot's `camera_poses`).

The file holds one table per camera: `position` (m, base frame), `quaternion` (w, x, y, z:
MuJoCo's camera frame, which looks along -z with +y up, in the base frame), `fovy` (degrees, from
the calibration's vertical focal length), `width` and `height`, and an `estimate` table that
records how it was found (read by people, not by the simulation)."""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import yaml

from .board import BOARD_AXES_IN_BASE, Board

MIN_CORNERS = 6  # fewer inner corners leave the pose ill-determined
# cornerSubPix's search: a 9x9 window, to 0.01 px.
SUBPIXEL_WINDOW = (4, 4)
SUBPIXEL_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 0.01)
# OpenCV's camera frame (x right, y down, z forward) to MuJoCo's (x right, y up, z backward).
OPENCV_TO_MUJOCO = np.diag([1.0, -1.0, -1.0])


class AlignError(ValueError):
    """A picture, calibration or file that cannot give a placement; the message says why."""


@dataclass(frozen=True)
class Calibration:
    """The intrinsics of ROS's camera calibration file (what so101_camera_node loads)."""

    width: int
    height: int
    camera_matrix: np.ndarray  # K, 3x3
    distortion: np.ndarray  # plumb_bob (k1, k2, p1, p2, k3) or empty

    @classmethod
    def load(cls, path: str | os.PathLike) -> Calibration:
        try:
            data = yaml.safe_load(Path(path).read_text())
            k = np.array(data["camera_matrix"]["data"], dtype=float).reshape(3, 3)
            d = np.array(data.get("distortion_coefficients", {}).get("data", []), dtype=float)
            width, height = int(data["image_width"]), int(data["image_height"])
        except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError) as error:
            raise AlignError(f"{path}: not a camera calibration file ({type(error).__name__}: {error})") from None
        if not (np.isfinite(k).all() and k[0, 0] > 0 and k[1, 1] > 0 and width > 0 and height > 0):
            raise AlignError(f"{path}: the camera matrix or size is not a camera's")
        return cls(width, height, k, d)

    @property
    def fovy_degrees(self) -> float:
        """The vertical field of view a square-pixel pinhole of this height and fy has."""
        return math.degrees(2 * math.atan(0.5 * self.height / self.camera_matrix[1, 1]))


@dataclass
class Placement:
    position: np.ndarray  # (3,) m, base frame
    quaternion: np.ndarray  # (4,) w x y z, MuJoCo camera frame in the base frame
    fovy: float
    width: int
    height: int
    estimate: dict = field(default_factory=dict)


def find_corners(image: np.ndarray, board: Board) -> tuple[np.ndarray, np.ndarray]:
    """The board's inner corners found in `image` (BGR or grayscale): (N, 3) points in the board's
    frame (m) and (N, 2) pixels, sub-pixel refined."""
    gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    charuco = board.charuco()
    corners, ids, _markers, _marker_ids = cv2.aruco.CharucoDetector(charuco).detectBoard(gray)
    found = 0 if ids is None else len(ids)
    if found < MIN_CORNERS:
        raise AlignError(
            f"the picture shows {found} of the board's {len(charuco.getChessboardCorners())} corners "
            f"(at least {MIN_CORNERS} are needed): is the whole board in view, flat, lit and in focus?"
        )
    # CharucoDetector's corners sit +0.5 px off the saddle in OpenCV before 4.14 (opencv/opencv
    # issue 25539): refined again, from there, to where the image's gradients put them.
    corners = cv2.cornerSubPix(gray, corners.astype(np.float32), SUBPIXEL_WINDOW, (-1, -1), SUBPIXEL_CRITERIA)
    object_points, image_points = charuco.matchImagePoints(corners, ids)
    return object_points.reshape(-1, 3), image_points.reshape(-1, 2)


def corners_by_point(image: np.ndarray, board: Board) -> dict[tuple, np.ndarray]:
    """The board's corners found in `image`, each pixel keyed by its point on the board (m): two
    pictures of the board compare corner by corner."""
    objects, pixels = find_corners(image, board)
    return {tuple(np.round(point, 6)): pixel for point, pixel in zip(objects, pixels)}


def estimate(image: np.ndarray, calibration: Calibration, board: Board) -> Placement:
    """The camera's placement from one picture of the board laid as documented."""
    if image.shape[:2] != (calibration.height, calibration.width):
        raise AlignError(
            f"the picture is {image.shape[1]}x{image.shape[0]}, the calibration's camera "
            f"{calibration.width}x{calibration.height}: take them at the same size"
        )
    object_points, image_points = find_corners(image, board)
    k, d = calibration.camera_matrix, calibration.distortion
    solved, rvec, tvec = cv2.solvePnP(object_points, image_points, k, d, flags=cv2.SOLVEPNP_ITERATIVE)
    if not solved:
        raise AlignError("no camera pose fits the corners found")
    rvec, tvec = cv2.solvePnPRefineLM(object_points, image_points, k, d, rvec, tvec)
    projected, _ = cv2.projectPoints(object_points, rvec, tvec, k, d)
    residuals = projected.reshape(-1, 2) - image_points
    rms = float(np.sqrt(np.mean(np.sum(residuals**2, axis=1))))
    board_to_camera, _ = cv2.Rodrigues(rvec)
    # The camera in the board's frame, then in the base frame.
    camera_in_board = -board_to_camera.T @ tvec.reshape(3)
    position = board.to_base(camera_in_board[None, :])[0]
    rotation = BOARD_AXES_IN_BASE @ board_to_camera.T @ OPENCV_TO_MUJOCO
    return Placement(
        position=position,
        quaternion=quaternion_from_matrix(rotation),
        fovy=calibration.fovy_degrees,
        width=calibration.width,
        height=calibration.height,
        estimate={
            "corners": len(object_points),
            "reprojection_rms_px": rms,
            "fx": float(k[0, 0]),
            "fy": float(k[1, 1]),
            "cx": float(k[0, 2]),
            "cy": float(k[1, 2]),
            "board": board.layout,
            "square_mm": board.square_m * 1000,
            "near_edge_x": board.near_edge_x,
            "lateral": board.lateral,
        },
    )


def quaternion_from_matrix(rotation: np.ndarray) -> np.ndarray:
    """(w, x, y, z), w >= 0, of a rotation matrix (through OpenCV's axis-angle)."""
    axis_angle, _ = cv2.Rodrigues(np.asarray(rotation, dtype=float))
    angle = float(np.linalg.norm(axis_angle))
    axis = axis_angle.reshape(3) / angle if angle > 0 else np.zeros(3)
    return np.array([math.cos(angle / 2), *(axis * math.sin(angle / 2))])


def matrix_from_quaternion(quaternion) -> np.ndarray:
    """The rotation matrix of (w, x, y, z)."""
    w, x, y, z = np.asarray(quaternion, dtype=float) / np.linalg.norm(quaternion)
    angle = 2 * math.atan2(math.sqrt(x * x + y * y + z * z), w)
    axis = np.array([x, y, z])
    norm = np.linalg.norm(axis)
    rotation, _ = cv2.Rodrigues(axis / norm * angle if norm > 0 else np.zeros(3))
    return rotation


def read_placements(path: str | os.PathLike) -> dict[str, Placement]:
    """The cameras of a placements file ({} when there is none yet)."""
    path = Path(path)
    if not path.exists():
        return {}
    try:
        tables = tomllib.loads(path.read_text())
        return {
            name: Placement(
                np.array(t["position"], float),
                np.array(t["quaternion"], float),
                float(t["fovy"]),
                int(t["width"]),
                int(t["height"]),
                dict(t.get("estimate", {})),
            )
            for name, t in tables.items()
        }
    except (OSError, tomllib.TOMLDecodeError, KeyError, TypeError, ValueError, AttributeError) as error:
        raise AlignError(f"{path}: not a camera placements file ({type(error).__name__}: {error})") from None


def write_placements(path: str | os.PathLike, placements: dict[str, Placement]) -> None:
    """The file, one table per camera in name order (replaced whole: written beside, then moved)."""
    lines = ["# Where the real cameras stand: written by so101-camera-align estimate (see so101.cameras.placement).", ""]
    for name in sorted(placements):
        p = placements[name]
        lines += [
            f"[{name}]",
            f"position = [{', '.join(_number(v) for v in p.position)}]",
            f"quaternion = [{', '.join(_number(v) for v in p.quaternion)}]",
            f"fovy = {_number(p.fovy)}",
            f"width = {int(p.width)}",
            f"height = {int(p.height)}",
        ]
        if p.estimate:
            lines += ["", f"[{name}.estimate]"]
            lines += [f"{key} = {_value(value)}" for key, value in p.estimate.items()]
        lines.append("")
    path = Path(path)
    partial = path.with_name(path.name + ".partial")
    partial.write_text("\n".join(lines))
    partial.replace(path)


def _number(value: float) -> str:
    return repr(float(value))


def _value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return _number(value)
    return '"' + str(value).replace("\\", "\\\\").replace('"', '\\"') + '"'
