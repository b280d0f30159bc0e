"""The calibration board of so101-camera-align and where it lies relative to the arm.

A ChArUco board (OpenCV's aruco module): a chessboard whose white squares hold ArUco markers, so
each inner corner is identified even when the arm or the edge of the picture hides part of it.
`so101-camera-align board` prints it; docs/sim_to_real.md says how to lay it.

Where it lies: face up on the table, the edge the sheet's caption marks "toward the arm" nearest
the arm and square to the arm's x axis (the direction the arm points at zero pan), centred on that
axis, the pattern's near edge NEAR_EDGE_X from the base's pan axis. In the board's own frame
(OpenCV's: origin at the pattern's top-left corner, x along the top edge, y down the sheet, z into
the table), the sheet's x runs along the base's +y and its y along the base's +x."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

# The boards by the paper they are printed on (landscape): columns and rows of squares, a square's
# side as printed at 100 % (m), the page (mm). A3's pattern (400 x 280 mm) fills more of a camera's
# view than A4's (245 x 175 mm): from a camera 0.8 m above the table at 640x480 it places the camera
# within 5 mm and 0.3 degrees where A4's leaves up to 2 cm and 1.3 degrees (docs/benchmarks.md).
LAYOUTS = {
    "a3": ((10, 7), 0.040, (420.0, 297.0)),
    "a4": ((7, 5), 0.035, (297.0, 210.0)),
    "letter": ((7, 5), 0.035, (279.4, 215.9)),
}
DEFAULT_LAYOUT = "a3"
MARKER_RATIO = 0.75  # marker side / square side
DICTIONARY = cv2.aruco.DICT_4X4_50  # few, large bits: read from 2.5 px per bit; 50 >= A3's 35 markers
NEAR_EDGE_X = 0.10  # base-frame x of the pattern's edge nearest the arm (m)

# Columns: the board's x, y and z axes in the arm's base frame (see the module's docstring).
BOARD_AXES_IN_BASE = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


@dataclass(frozen=True)
class Board:
    """The board as printed (`layout`, and `square_m`: a square's side as measured on the sheet;
    None: the layout's) and laid (`near_edge_x`, and `lateral`: the pattern's centre off the arm's
    x axis, toward +y)."""

    layout: str = DEFAULT_LAYOUT
    square_m: float | None = None
    near_edge_x: float = NEAR_EDGE_X
    lateral: float = 0.0

    def __post_init__(self):
        if self.layout not in LAYOUTS:
            raise ValueError(f"board {self.layout!r}: one of {', '.join(LAYOUTS)}")
        if self.square_m is None:
            object.__setattr__(self, "square_m", LAYOUTS[self.layout][1])
        if not 0.005 <= self.square_m <= 0.2:
            raise ValueError(f"a square of {self.square_m * 1000:g} mm: measure it on the sheet, 5 to 200 mm")

    @property
    def squares(self) -> tuple[int, int]:
        """(columns, rows) of squares."""
        return LAYOUTS[self.layout][0]

    @property
    def page_mm(self) -> tuple[float, float]:
        return LAYOUTS[self.layout][2]

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) of the pattern: along its top edge, down the sheet."""
        return self.squares[0] * self.square_m, self.squares[1] * self.square_m

    def charuco(self) -> cv2.aruco.CharucoBoard:
        dictionary = cv2.aruco.getPredefinedDictionary(DICTIONARY)
        return cv2.aruco.CharucoBoard(self.squares, self.square_m, self.square_m * MARKER_RATIO, dictionary)

    def origin_in_base(self) -> np.ndarray:
        """The pattern's top-left corner (the board frame's origin) in the base frame (m)."""
        width, _height = self.size_m
        return np.array([self.near_edge_x, self.lateral - width / 2, 0.0])

    def to_base(self, points: np.ndarray) -> np.ndarray:
        """Points (N, 3) from the board's frame into the arm's base frame."""
        return points @ BOARD_AXES_IN_BASE.T + self.origin_in_base()

    def pattern(self, pixels_per_metre: float) -> np.ndarray:
        """The pattern alone, grayscale, edge to edge (what the sim's texture shows)."""
        width, height = self.size_m
        size = (round(width * pixels_per_metre), round(height * pixels_per_metre))
        return self.charuco().generateImage(size, marginSize=0, borderBits=1)


def sheet(board: Board, dpi: int = 300) -> np.ndarray:
    """The printable page of the board's layout (grayscale, landscape) with the pattern centred and
    a caption in the top margin saying which edge goes toward the arm and how long a square must
    measure."""
    pixels_per_metre = dpi / 0.0254
    page_mm = board.page_mm
    page = np.full((round(page_mm[1] / 1000 * pixels_per_metre), round(page_mm[0] / 1000 * pixels_per_metre)), 255, np.uint8)
    pattern = board.pattern(pixels_per_metre)
    if pattern.shape[0] > page.shape[0] or pattern.shape[1] > page.shape[1]:
        raise ValueError(f"a {board.square_m * 1000:g} mm square does not fit the {board.layout} page")
    top = (page.shape[0] - pattern.shape[0]) // 2
    left = (page.shape[1] - pattern.shape[1]) // 2
    page[top : top + pattern.shape[0], left : left + pattern.shape[1]] = pattern
    caption = f"so101-camera-align board: THIS EDGE TOWARD THE ARM. Print at 100 %: a square is {board.square_m * 1000:g} mm."
    scale = dpi / 300
    (text_width, text_height), _ = cv2.getTextSize(caption, cv2.FONT_HERSHEY_SIMPLEX, scale, max(1, round(2 * scale)))
    baseline_y = max(text_height + 4, top - round(0.004 * pixels_per_metre))
    cv2.putText(
        page,
        caption,
        ((page.shape[1] - text_width) // 2, baseline_y),
        cv2.FONT_HERSHEY_SIMPLEX,
        scale,
        0,
        max(1, round(2 * scale)),
        cv2.LINE_AA,
    )
    return page
