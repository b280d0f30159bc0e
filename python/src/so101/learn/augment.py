"""Image augmentation for the camera recipes (`so101-learn act|diffusion --augment SETS`): named
sets of transforms, given to lerobot-train as LeRobot's image transforms (each a class of
torchvision.transforms.v2 or one of LeRobot's own). LeRobot draws up to `max_num_transforms` (3)
of the enabled transforms for each frame of each camera, so every camera of a sample gets its own.

- colour (the recipe's default): LeRobot's default colour transforms (brightness, contrast,
  saturation, hue, sharpness). Its default set also holds a random affine shift of up to 5 %,
  which moves the cube by centimetres on the table as the top camera sees it: a policy that must
  grasp within millimetres cannot tell that from the cube really lying elsewhere, so it is left out.
- shift: the picture moved by up to 2 % of its size (2 pixels of 96), no rotation: of the order of
  what the default randomization's camera jitter (1.5 cm, 3 degrees of field of view) moves the
  scene by at 96x72, far less than LeRobot's 5 %.
- blur: a Gaussian blur of 3 by 3 pixels, sigma 0.1-1 (a real camera's focus and motion).
- noise: Gaussian noise, its standard deviation drawn up to 5 levels of 255 for each frame (a real
  sensor's grain; LeRobot's GaussianNoise).
- none: no augmentation.
"""

from __future__ import annotations

import json

SETS = ("colour", "shift", "blur", "noise")
DEFAULT = "colour"
# LeRobot's default set, less its geometric transform (see above).
LEFT_OUT_OF_LEROBOTS_DEFAULT = ("affine",)
ADDED = {
    "shift": {"type": "RandomAffine", "kwargs": {"degrees": 0.0, "translate": [0.02, 0.02]}},
    "blur": {"type": "GaussianBlur", "kwargs": {"kernel_size": 3, "sigma": [0.1, 1.0]}},
    # LeRobot's own GaussianNoise (its std in levels of 255, drawn per frame), not torchvision's.
    "noise": {"type": "GaussianNoise", "kwargs": {"std": [0.0, 5.0]}},
}


def parse_sets(text: str) -> tuple[str, ...]:
    """`--augment`'s value (a comma list of SETS, or none) as the sets it names; ValueError names
    an unknown one."""
    names = tuple(name.strip() for name in text.split(",") if name.strip())
    if names == ("none",):
        return ()
    unknown = [name for name in names if name not in SETS]
    if unknown or not names:
        raise ValueError(f"unknown augmentation {', '.join(unknown) or repr(text)}: a comma list of {', '.join(SETS)}, or none")
    return tuple(dict.fromkeys(names))


def colour_transforms() -> dict[str, dict]:
    """LeRobot's default image transforms without the geometric ones."""
    from dataclasses import asdict

    from lerobot.transforms.transforms import ImageTransformsConfig

    return {
        name: asdict(config) for name, config in ImageTransformsConfig().tfs.items() if name not in LEFT_OUT_OF_LEROBOTS_DEFAULT
    }


def transforms(sets: tuple[str, ...]) -> dict[str, dict]:
    """The transforms of `sets`, keyed by name, as LeRobot's ImageTransformConfig fields."""
    chosen = {}
    for name in sets:
        if name == "colour":
            chosen |= colour_transforms()
        else:
            chosen[name] = {"weight": 1.0, **ADDED[name]}
    return chosen


def training_settings(sets: tuple[str, ...]) -> dict[str, str]:
    """lerobot-train's settings for the augmentation of `sets` (none: augmentation off)."""
    if not sets:
        return {"dataset.image_transforms.enable": "false"}
    return {"dataset.image_transforms.enable": "true", "dataset.image_transforms.tfs": json.dumps(transforms(sets))}
