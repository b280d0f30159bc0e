"""The simulation's options as users write them, turned into the one spelling the simulation takes
(so101_native's World and WorldBatch, so101_sim_node's --randomize and --servo-params):

  randomize     True or "true" / "default": the default ranges (assets/randomization.toml);
                False or "false" / "off": none; "heldout": the held-out shift set for evaluation
                (assets/randomization_heldout.toml); a path (str or os.PathLike) to a .toml of ranges
  servo_params  a servo model by name (SERVO_MODELS) or a path to a so101-sysid fit file (.json)
  camera_poses  None (or "") for the scene's cameras, or a path to so101-camera-align's file
                (.toml) placing the cameras where the user's real ones stand

The Gymnasium envs, LeRobot's env type (`--env.randomize=true` arrives as the string "true") and
the CLIs all normalize here, so each spelling means the same everywhere and anything else is
refused with the accepted forms before a simulation starts."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from . import contract

# The servo models the simulation knows by name, and the one it uses unless told (so101_core::servo).
SERVO_MODELS = contract.SERVO_MODELS
DEFAULT_SERVO_MODEL = contract.DEFAULT_SERVO_MODEL

RANDOMIZE_OFF = "off"
RANDOMIZE_DEFAULT = "default"
RANDOMIZE_HELDOUT = "heldout"
_RANDOMIZE_WORDS = {
    "off": RANDOMIZE_OFF,
    "false": RANDOMIZE_OFF,
    "default": RANDOMIZE_DEFAULT,
    "true": RANDOMIZE_DEFAULT,
    "heldout": RANDOMIZE_HELDOUT,
}
_RANDOMIZE_FORMS = "True, False, 'off', 'default', 'heldout' or"


def randomize_spec(value: object) -> str:
    """`randomize` as the simulation takes it: "off", "default", "heldout" or the path of a .toml file."""
    if isinstance(value, bool):
        return RANDOMIZE_DEFAULT if value else RANDOMIZE_OFF
    if isinstance(value, str) and value.strip().lower() in _RANDOMIZE_WORDS:
        return _RANDOMIZE_WORDS[value.strip().lower()]
    if isinstance(value, (str, os.PathLike)):
        return _existing_file(value, None, "randomize", f"{_RANDOMIZE_FORMS} a .toml file of ranges")
    raise TypeError(f"randomize={value!r} ({type(value).__name__}): {_RANDOMIZE_FORMS} the path of a .toml file of ranges")


def servo_params_spec(value: object) -> str:
    """`servo_params` as the simulation takes it: a model's name or the path of a .json file."""
    if isinstance(value, str) and value.strip() in SERVO_MODELS:
        return value.strip()
    accepted = f"{', '.join(SERVO_MODELS)} or a so101-sysid fit file (.json)"
    if isinstance(value, (str, os.PathLike)):
        return _existing_file(value, ".json", "servo_params", accepted)
    raise TypeError(f"servo_params={value!r} ({type(value).__name__}): {accepted}")


def camera_poses_spec(value: object) -> str | None:
    """`camera_poses` as the simulation takes it: None or the path of a .toml file."""
    if value is None or (isinstance(value, str) and not value.strip()):
        return None
    accepted = "None or so101-camera-align's file of camera placements (.toml)"
    if isinstance(value, (str, os.PathLike)):
        return _existing_file(value, ".toml", "camera_poses", accepted)
    raise TypeError(f"camera_poses={value!r} ({type(value).__name__}): {accepted}")


def _existing_file(value: str | os.PathLike, suffix: str | None, option: str, accepted: str) -> str:
    path = Path(os.fspath(value)).expanduser()
    if suffix and path.suffix != suffix:
        raise ValueError(f"{option}={os.fspath(value)!r}: {accepted}")
    if not path.is_file():
        raise ValueError(f"{option}={os.fspath(value)!r}: no such file ({accepted})")
    # Absolute: a node started in another directory reads the same file.
    return str(path.resolve())


def add_arguments(parser: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """--servo-params, --randomize and --camera-poses as every CLI that starts a simulation takes
    them."""
    parser.add_argument(
        "--servo-params",
        type=servo_params_argument,
        default=DEFAULT_SERVO_MODEL,
        help=f"the sim's servo model: {', '.join(SERVO_MODELS)} or a so101-sysid fit file (default {DEFAULT_SERVO_MODEL})",
    )
    parser.add_argument(
        "--randomize",
        type=randomize_argument,
        nargs="?",
        const=RANDOMIZE_DEFAULT,
        default=RANDOMIZE_OFF,
        metavar="RANGES",
        help="domain randomization of every episode, seeded by its seed: the default ranges "
        "(assets/randomization.toml; also `true`), `off`/`false`, `heldout` (the held-out shift set, "
        "for evaluation: assets/randomization_heldout.toml), or a .toml of your own",
    )
    parser.add_argument(
        "--camera-poses",
        type=camera_poses_argument,
        default=None,
        metavar="FILE",
        help="place the sim's cameras where your real ones stand: the file of `so101-camera-align estimate` (.toml)",
    )


def randomize_argument(text: str) -> str:
    """argparse's `type` for --randomize: the error names the accepted forms."""
    return _argument(randomize_spec, text)


def servo_params_argument(text: str) -> str:
    """argparse's `type` for --servo-params."""
    return _argument(servo_params_spec, text)


def camera_poses_argument(text: str) -> str | None:
    """argparse's `type` for --camera-poses."""
    return _argument(camera_poses_spec, text)


def _argument(normalize, text: str):
    try:
        return normalize(text)
    except (TypeError, ValueError) as error:
        raise argparse.ArgumentTypeError(str(error)) from None
