"""so101-learn backgrounds: pictures drawn at random to train behind the simulated scene, and a
randomization file that shows them, so a camera policy learns to find the cube in front of rooms
nobody photographed for it.

    so101-learn backgrounds --output scenes            # scenes/top/*.jpg, scenes/front/*.jpg,
                                                       # scenes/randomization.toml
    so101-learn demos ... --randomize scenes/randomization.toml

Why: the default randomization only tints a uniform table; the held-out shift set (`--randomize
heldout`) shows photographs where the table, floor and sky were (cameras/backgrounds in so101_sim)
and a distractor on the table, and the robust recipe's policy that succeeded 89 % of the time under
the default randomization succeeded 33 % there. Domain randomization's answer is to show the policy
many random textures in training, so a real room is one more. These are drawn, not fetched:
nothing third-party, none of the held-out photographs (a held-out set must stay unseen), as many as
wanted. A user who can photograph their own workspace has better: docs/sim_to_real.md,
"Your own background behind the scene".

Each picture (determined by --seed, its camera's name and its number) layers what a desk and a room show:
- a base of fractal noise through a palette of 2-4 colours (wood, cloth, carpet, walls);
- in half of them, stripes or a checker at a random angle and period (grain, tiles, mats, shelves);
- 0-15 rectangles and ellipses of random colours and sizes (things on a desk, furniture);
- a lamp's light: a brightness gradient across the picture.

The file keeps every default range (assets/randomization.toml) and adds the pictures and, unless
--no-distractor, the distractor of the held-out set (a cylinder beside the cube's area that only the
cameras see). The wrist camera rides the arm and keeps the sim's scenery: it gets no pictures.
"""

from __future__ import annotations

import argparse
import sys
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .. import contract
from ..arguments import at_least, picture_size

RANDOMIZATION_FILE = "randomization.toml"
# The fixed cameras' 4:3, twice the robust recipe's 96x72 (each is fitted down to the render's
# size). Every env keeps all its pictures decoded: 200 per camera at this size take 33 MB, at
# 640x480 they would take 370 MB in each worker process.
DEFAULT_SIZE = (192, 144)
# Smaller pictures hold too few pixels for the noise's coarse octaves and the shapes.
MIN_SIDE = 16
# The pictures' file names: the ones a new run replaces (anything else in a camera's folder is
# refused, since the simulation would show it too).
PREFIX = "bg_"


def fixed_cameras() -> tuple[str, ...]:
    """The cameras that show a background: every camera of the contract but those on the arm."""
    return tuple(name for name in contract.CAMERA_NAMES if name not in contract.CAMERAS_ON_THE_ARM)


def fractal_noise(rng: np.random.Generator, width: int, height: int, octaves: int = 5) -> np.ndarray:
    """Smooth random values in [0, 1], (height, width): octaves of random grids, each twice as fine
    and half as strong as the one before, bicubically enlarged (Pillow's float images)."""
    from PIL import Image

    total = np.zeros((height, width), dtype=np.float32)
    coarsest = int(rng.integers(2, 6))
    for octave in range(octaves):
        cells = coarsest * 2**octave
        grid = rng.random((max(2, cells * height // width), cells), dtype=np.float32)
        enlarged = Image.fromarray(grid, mode="F").resize((width, height), Image.Resampling.BICUBIC)
        total += np.asarray(enlarged) * 0.5**octave
    low, high = total.min(), total.max()
    return (total - low) / max(high - low, 1e-6)


def palette(rng: np.random.Generator, count: int) -> np.ndarray:
    """`count` colours (rows of r, g, b in [0, 1]), from greyish to saturated."""
    grey = rng.random((count, 1))
    saturation = rng.uniform(0.1, 1.0)
    return np.clip(grey + saturation * (rng.random((count, 3)) - grey), 0.0, 1.0)


def through_palette(values: np.ndarray, colours: np.ndarray) -> np.ndarray:
    """Values in [0, 1] as colours: piecewise linear from the first colour to the last."""
    stops = np.linspace(0.0, 1.0, len(colours))
    return np.stack([np.interp(values, stops, colours[:, channel]) for channel in range(3)], axis=-1)


def pattern(rng: np.random.Generator, width: int, height: int) -> np.ndarray:
    """Stripes or a checker, (height, width) in [0, 1], at a random angle and period (pixels)."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    angle = rng.uniform(0.0, np.pi)
    period = rng.uniform(0.02, 0.25) * width
    along = (x * np.cos(angle) + y * np.sin(angle)) / period
    if rng.random() < 0.5:
        return 0.5 + 0.5 * np.sin(2.0 * np.pi * along)
    across = (-x * np.sin(angle) + y * np.cos(angle)) / period
    return ((np.floor(along) + np.floor(across)) % 2).astype(np.float32)


def draw_background(seed: int, camera: str, number: int, size: tuple[int, int] = DEFAULT_SIZE) -> np.ndarray:
    """Picture `number` of camera `camera` for `seed` (not negative): RGB, uint8, (height, width,
    3). The same arguments always draw the same picture."""
    from PIL import Image, ImageDraw

    width, height = size
    rng = np.random.default_rng((seed, zlib.crc32(camera.encode()), number, 0xB6))
    image = through_palette(fractal_noise(rng, width, height), palette(rng, int(rng.integers(2, 5))))
    if rng.random() < 0.5:
        strength = rng.uniform(0.2, 0.7) * pattern(rng, width, height)[..., None]
        image = image * (1.0 - strength) + palette(rng, 1)[0] * strength
    picture = Image.fromarray((image * 255.0).round().astype(np.uint8))
    sketch = ImageDraw.Draw(picture)
    for _ in range(int(rng.integers(0, 16))):
        centre = rng.random(2) * (width, height)
        half = rng.uniform(0.03, 0.3, size=2) * (width, height)
        fill = tuple(int(c) for c in (palette(rng, 1)[0] * 255.0).round())
        shape = sketch.ellipse if rng.random() < 0.4 else sketch.rectangle
        shape(tuple(int(v) for v in (*(centre - half), *(centre + half))), fill=fill)
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    toward = rng.uniform(-1.0, 1.0, size=2) / np.array([width, height])
    # From 0.6 to 1.4 across the picture at most, the whole 0.7 to 1.15 times as bright.
    lamp = 1.0 + rng.uniform(0.0, 0.4) * ((x - width / 2) * toward[0] + (y - height / 2) * toward[1])
    lit = np.asarray(picture, dtype=np.float32) * rng.uniform(0.7, 1.15) * lamp[..., None]
    return np.clip(lit, 0.0, 255.0).round().astype(np.uint8)


def randomization_text(count: int, seed: int, size: tuple[int, int], distractor: bool) -> str:
    """The randomization file beside the pictures: the default ranges, the pictures, a distractor."""
    options = f"--count {count} --seed {seed} --size {size[0]}x{size[1]}{'' if distractor else ' --no-distractor'}"
    return (
        f"# so101-learn backgrounds {options}:\n"
        "# the default ranges (assets/randomization.toml), these pictures behind the fixed cameras' scene\n"
        f"# and {'a distractor on the table' if distractor else 'no distractor'}.\n"
        "[scene]\n"
        'backgrounds = "."\n'
        f"distractor = {'true' if distractor else 'false'}\n"
    )


def write(
    output: Path, count: int, seed: int, size: tuple[int, int], distractor: bool, done: Callable[[], object] = lambda: None
) -> Path:
    """The pictures as output/CAMERA/bg_NNNN.jpg and output/randomization.toml; the file's path.
    The pictures of an earlier run there are replaced; a folder holding other pictures is refused
    (ValueError) before anything is written. `done` is called after each picture."""
    from PIL import Image

    folders = [output / name for name in fixed_cameras()]
    for folder in folders:
        others = [path.name for path in not_ours(folder)]
        if others:
            raise ValueError(
                f"{folder} holds pictures this command did not draw ({', '.join(sorted(others)[:3])}, ...): choose another --output"
            )
    for folder in folders:
        folder.mkdir(parents=True, exist_ok=True)
        for earlier in folder.glob(f"{PREFIX}*.jpg"):
            earlier.unlink()
        for number in range(count):
            picture = draw_background(seed, folder.name, number, size)
            Image.fromarray(picture).save(folder / f"{PREFIX}{number:04d}.jpg", quality=90)
            done()
    ranges = output / RANDOMIZATION_FILE
    ranges.write_text(randomization_text(count, seed, size, distractor))
    return ranges


def not_ours(folder: Path) -> list[Path]:
    """The pictures in `folder` the simulation would show that this command did not write."""
    if not folder.is_dir():
        return []
    return [path for path in folder.iterdir() if path.suffix.lower() in (".jpg", ".jpeg") and not path.name.startswith(PREFIX)]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--output", type=Path, required=True, help="folder for CAMERA/*.jpg and randomization.toml")
    p.add_argument("--count", type=at_least(1), default=200, help="pictures per fixed camera (default 200)")
    p.add_argument("--seed", type=at_least(0), default=0, help="which pictures: the same seed draws the same ones")
    p.add_argument(
        "--size",
        type=picture_size(MIN_SIDE),
        default=DEFAULT_SIZE,
        help="WIDTHxHEIGHT of each picture (default 192x144; each simulation keeps them all decoded: "
        "200 per camera take 33 MB at this size, 370 MB at 640x480)",
    )
    p.add_argument("--no-distractor", dest="distractor", action="store_false", help="leave the distractor out")


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    cameras = fixed_cameras()
    with tqdm(total=args.count * len(cameras), desc="backgrounds", unit="picture") as bar:
        try:
            ranges = write(args.output, args.count, args.seed, args.size, args.distractor, done=bar.update)
        except ValueError as refused:
            print(f"so101-learn backgrounds: {refused}", file=sys.stderr)
            return 2
    print(f"{args.count} pictures for each of {', '.join(cameras)} in {args.output}")
    print(f"Train and evaluate with them: --randomize {ranges}")
    return 0
