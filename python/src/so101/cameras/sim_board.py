"""The board laid in the simulated scene where docs/sim_to_real.md tells a user to lay it on the
desk, so a sim camera can stand in for a real one: render the board from a pose the alignment is
not told, estimate the pose from that picture, compare (the test and the benchmark do)."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import cv2
import numpy as np

from ..contract import BASE_LINK
from .board import Board
from .placement import Calibration

TEXTURE_PIXELS_PER_METRE = 4000.0  # 4 px/mm: a marker bit spans 15 texels
NAME = "so101_align_board"
LIFT = 0.0002  # m above the table, so the board is drawn over the table top, not into it


def scene_with_board(scene: str | Path, directory: Path, board: Board | None = None) -> Path:
    """A copy of `scene` (an MJCF file) written into `directory`, with the board's texture beside
    it and the board lying on the table as documented; its path. The copy finds the original's
    meshes (its mesh directory made absolute), so it loads with or without lite."""
    board = board or Board()
    source = Path(scene)
    tree = ElementTree.parse(source)
    root = tree.getroot()
    compiler = root.find("compiler")
    if compiler is not None and compiler.get("meshdir") and not Path(compiler.get("meshdir")).is_absolute():
        compiler.set("meshdir", str((source.parent / compiler.get("meshdir")).resolve()))
    base_in_world = _base_in_world(root, source)

    texture = directory / f"{NAME}.png"
    cv2.imwrite(str(texture), board.pattern(TEXTURE_PIXELS_PER_METRE))
    asset = root.find("asset")
    if asset is None:
        asset = ElementTree.SubElement(root, "asset")
    ElementTree.SubElement(asset, "texture", name=NAME, type="2d", file=str(texture.resolve()))
    ElementTree.SubElement(
        asset, "material", name=NAME, texture=NAME, texrepeat="1 1", texuniform="false", specular="0", shininess="0"
    )

    width, height = board.size_m
    centre = board.to_base(np.array([[width / 2, height / 2, 0.0]]))[0] + base_in_world + [0.0, 0.0, LIFT]
    # The plane's x along the board's x (base +y), its y along the board's -y (base -x), so that its
    # normal (+z) faces up: a quarter turn about z.
    quarter = math.sqrt(0.5)
    ElementTree.SubElement(
        root.find("worldbody"),
        "geom",
        name=NAME,
        type="plane",
        size=f"{width / 2} {height / 2} 0.01",
        pos=" ".join(f"{v:.6f}" for v in centre),
        quat=f"{quarter} 0 0 {quarter}",
        material=NAME,
        contype="0",
        conaffinity="0",
    )
    path = directory / f"{source.stem}_with_board.xml"
    tree.write(path, encoding="unicode")
    return path


def _base_in_world(root: ElementTree.Element, source) -> np.ndarray:
    base = root.find(f".//body[@name='{BASE_LINK}']")
    if base is None:
        raise ValueError(f"{source}: no body {BASE_LINK!r} to lay the board in front of")
    return np.array([float(v) for v in base.get("pos", "0 0 0").split()])


def scene_cameras(scene: str | Path) -> dict[str, tuple[np.ndarray, np.ndarray, float]]:
    """The scene's cameras fixed in the world, as its MJCF places them: {name: (position in the
    base frame, rotation (columns: the camera's axes), fovy in degrees)}."""
    root = ElementTree.parse(scene).getroot()
    base_in_world = _base_in_world(root, scene)
    cameras = {}
    for camera in root.find("worldbody").findall("camera"):
        x, y = np.split(np.array([float(v) for v in camera.get("xyaxes").split()]), 2)
        x /= np.linalg.norm(x)
        y = y - x * (x @ y)
        y /= np.linalg.norm(y)
        position = np.array([float(v) for v in camera.get("pos").split()]) - base_in_world
        cameras[camera.get("name")] = (position, np.column_stack([x, y, np.cross(x, y)]), float(camera.get("fovy", 45)))
    return cameras


def picture(scene: str | Path, camera_poses: str | None, camera: str, size: tuple[int, int], seed: int = 7) -> np.ndarray:
    """One RGB frame (height, width, 3) of `camera` in `scene` placed by `camera_poses`, the arm
    turned aside out of the board's way (as the docs ask of a user)."""
    import so101_native

    world = so101_native.World(str(scene), lite=True, camera_poses=camera_poses)
    world.reset(seed)
    state, _reward, _success = world.observe()
    aside = np.array(state[:6])
    aside[0] = -1.5  # shoulder_pan: the arm along the base's +y, clear of the board
    world.place_arm(aside)
    world.enable_cameras([(camera, tuple(size))])
    return world.render()[camera]


def ideal_calibration(fovy: float, width: int, height: int) -> Calibration:
    """What a calibration of the sim's pinhole gives: square pixels, centred, no distortion."""
    f = 0.5 * height / math.tan(math.radians(fovy) / 2)
    k = np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1]])
    return Calibration(width, height, k, np.zeros(5))
