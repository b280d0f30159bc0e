"""so101-camera-align: place the simulation's cameras where your real ones stand. Print the board
(`board`), lay it in front of the arm, take one picture per camera and run `estimate` once per
camera; hand the file it writes to the sim (so101_sim_node --camera-poses, the envs' and LeRobot's
camera_poses). See docs/sim_to_real.md."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2

from .. import contract, subcommands
from ..subcommands import Subcommand
from .board import DEFAULT_LAYOUT, LAYOUTS, NEAR_EDGE_X, Board, sheet
from .placement import AlignError, Calibration, estimate, read_placements, write_placements


def add_layout_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--board",
        choices=list(LAYOUTS),
        default=DEFAULT_LAYOUT,
        help=f"the paper the board is printed on, landscape (default {DEFAULT_LAYOUT}: the larger board places a camera "
        "looking down from afar more precisely)",
    )


def add_board_arguments(p: argparse.ArgumentParser) -> None:
    add_layout_argument(p)
    p.add_argument("--output", type=Path, default=Path("so101_board.png"), help="the page to print (PNG)")
    p.add_argument("--dpi", type=int, default=300, help="print resolution the PNG is made for (default 300)")


def run_board(args: argparse.Namespace) -> int:
    from PIL import Image

    board = Board(args.board)
    Image.fromarray(sheet(board, dpi=args.dpi)).save(args.output, dpi=(args.dpi, args.dpi))
    print(
        f"{args.output}: print at 100 % (no 'fit to page') on {args.board.upper()} landscape, then measure a square: "
        f"{board.square_m * 1000:g} mm expected (pass what you measure as --square-mm)."
    )
    return 0


def add_estimate_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--camera", required=True, help="the sim camera this real one is (e.g. top, front)")
    p.add_argument("--image", type=Path, required=True, help="one picture of the board from this camera")
    p.add_argument(
        "--calibration",
        type=Path,
        required=True,
        help="the camera's calibration (ROS camera_calibration's YAML, what so101_camera_node loads), same size as the picture",
    )
    p.add_argument("--output", type=Path, default=Path("camera_poses.toml"), help="placements file, updated per camera")
    add_layout_argument(p)
    p.add_argument(
        "--square-mm", type=float, default=None, help="a square's side as measured on your print (default: the board's)"
    )
    p.add_argument(
        "--near-edge-x",
        type=float,
        default=NEAR_EDGE_X,
        help=f"the board's near edge from the base's pan axis along the arm's x axis, m (default {NEAR_EDGE_X})",
    )
    p.add_argument("--lateral", type=float, default=0.0, help="the board's centre off the arm's x axis toward +y (its left), m")


def run_estimate(args: argparse.Namespace) -> int:
    if args.camera in contract.CAMERAS_ON_THE_ARM:
        print(f"{args.camera} rides the arm: a board on the table cannot place it", file=sys.stderr)
        return 2
    image = cv2.imread(str(args.image), cv2.IMREAD_COLOR)
    if image is None:
        print(f"{args.image}: not a picture OpenCV can read", file=sys.stderr)
        return 2
    try:
        square_m = None if args.square_mm is None else args.square_mm / 1000
        board = Board(args.board, square_m, near_edge_x=args.near_edge_x, lateral=args.lateral)
        placement = estimate(image, Calibration.load(args.calibration), board)
        placements = read_placements(args.output)
    except (AlignError, ValueError) as error:
        print(f"{args.camera}: {error}", file=sys.stderr)
        return 1
    placement.estimate["image"] = str(args.image)
    placements[args.camera] = placement
    write_placements(args.output, placements)
    x, y, z = placement.position
    print(
        f"{args.camera}: at ({x:.3f}, {y:.3f}, {z:.3f}) m in the arm's base frame, fovy {placement.fovy:.1f} deg, "
        f"{placement.estimate['corners']} corners, reprojection {placement.estimate['reprojection_rms_px']:.2f} px RMS; "
        f"written to {args.output}"
    )
    if placement.estimate["reprojection_rms_px"] > 2.0:
        print("warning: over 2 px of reprojection error: check the calibration and that the board lies flat", file=sys.stderr)
    return 0


COMMANDS = {
    "board": Subcommand("write the printable calibration board (PNG)", add_board_arguments, run_board),
    "estimate": Subcommand(
        "one camera's place from one picture of the board; added to the placements file",
        add_estimate_arguments,
        run_estimate,
    ),
}


def main(argv: list[str] | None = None) -> int:
    return subcommands.main("so101-camera-align", __doc__, COMMANDS, argv)


if __name__ == "__main__":
    sys.exit(main())
