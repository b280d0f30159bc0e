"""lerobot-train itself, with one change: each item of the training dataset is kept in memory after
its first read (`python -m so101.learn.train_in_memory` takes lerobot-train's arguments). And one
layout: under mixed precision a camera policy's convolutions train in channels_last
(so101.learn.channels_last).

Why: LeRobotDataset builds an item each time it is asked, from Arrow rows (about 6 ms per item on
this 2-core CPU for the state recipes' windows of 2 observations and 16 actions: 372 ms a batch of
64, against 153 ms for a whole Diffusion step of the state recipe) and, with cameras, by decoding
each camera's video at the item's instant (about 10 ms per item for two 64x48 cameras). An item is
the same every epoch but for its image augmentation, so the kept item is the one LeRobotDataset
builds without its image transforms, and they are applied at each read exactly as LeRobotDataset
applies them (each camera but depth ones, in the meta's camera order): the augmentation draws the
same random numbers in the same order, so training gives the weights lerobot-train's own loading
gives from the same seed and loader processes. Frames are kept as the 8-bit values they were
decoded from: lerobot-train asks LeRobotDataset for them as uint8 (the augmentation works on those,
and the training loop turns the batch into floats); a dataset giving floats has its frames kept as
8-bit values too (a quarter of float32's memory) and given back as the very same floats.

With cameras the kept frames must fit: a dataset whose frames, once per loader process (each keeps
its own copies, across epochs as lerobot-train's loaders persist), would take more than half of the
memory available at the start goes through untouched, and says so.
Each checkpoint of a run that keeps its items says so (so101.learn.checkpoints), for --resume.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from dataclasses import dataclass
from math import prod
from pathlib import Path

import torch
from torch.utils.data import Dataset, IterableDataset

from . import channels_last
from .checkpoints import record_items_in_memory

# The share of the memory available at the start that kept frames may take.
MEMORY_SHARE = 0.5


@dataclass(frozen=True)
class CompactFrames:
    """Decoded float frames kept as their 8-bit values (`values`, uint8)."""

    values: torch.Tensor


def compact_frames(frames: torch.Tensor) -> torch.Tensor | CompactFrames:
    """Decoded frames as float32 in [0, 1] (8-bit values over 255) as CompactFrames, when
    expand_frames gives the very same floats back; anything else (frames LeRobot already gives as
    uint8, as lerobot-train asks it to; depth) as it is."""
    if frames.dtype != torch.float32:
        return frames
    values = (frames * 255).round_()
    if values.min() < 0 or values.max() > 255:
        return frames
    compact = CompactFrames(values.to(torch.uint8))
    return compact if expand_frames(compact).equal(frames) else frames


def expand_frames(frames: torch.Tensor | CompactFrames) -> torch.Tensor:
    """compact_frames' inverse: LeRobot's own conversion of decoded 8-bit frames to float32."""
    return frames.values.type(torch.float32) / 255 if isinstance(frames, CompactFrames) else frames


class ItemsInMemory(Dataset):
    """A map-style dataset's items, each read once from `dataset` (whose image transforms, if any,
    have been taken off and given here) and then kept; `transforms` applied at each read to
    `transformed` (camera keys, in order). Every attribute but the items (meta, episodes,
    num_frames, ...) is the wrapped dataset's."""

    def __init__(
        self, dataset, cameras: tuple[str, ...] = (), transformed: tuple[str, ...] = (), transforms: Callable | None = None
    ) -> None:
        self.dataset = dataset
        self.items: list[dict | None] = [None] * len(dataset)
        self.cameras = tuple(cameras)
        self.transformed = tuple(transformed) if transforms is not None else ()
        self.transforms = transforms

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, index: int) -> dict:
        item = self.items[index]
        if item is None:
            item = self.dataset[index]
            item = self.items[index] = {
                key: compact_frames(value) if key in self.cameras else value for key, value in item.items()
            }
        # A new dict each time: a consumer that adds or replaces keys leaves the kept item intact.
        item = {key: expand_frames(value) if key in self.cameras else value for key, value in item.items()}
        for camera in self.transformed:
            item[camera] = self.transforms(item[camera])
        return item

    def __getattr__(self, name: str):
        # Only for attributes this wrapper lacks. Not `dataset` itself (an unpickled copy has none
        # yet: it raises instead of recursing), nor Python's and torch's protocols: a batched
        # __getitems__ of the wrapped dataset would bypass the kept items.
        if name == "dataset" or name.startswith("__"):
            raise AttributeError(name)
        return getattr(self.dataset, name)


def keeps_items(dataset) -> bool:
    """Whether `dataset`'s items can be kept: a map-style dataset (a streaming one is read once)."""
    return not isinstance(dataset, IterableDataset)


def frame_bytes(dataset) -> int:
    """The bytes one item's camera frames take once kept (8 bits a value, each observation step
    of a camera the item holds)."""
    steps = getattr(dataset, "delta_timestamps", None) or {}
    return sum(prod(dataset.meta.features[camera]["shape"]) * len(steps.get(camera, [0])) for camera in dataset.meta.camera_keys)


def memory_available() -> int | None:
    """The memory the system has available now (Linux's MemAvailable), in bytes; None if unknown."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def size(count: int) -> str:
    """A number of bytes in GiB, or in MiB below one GiB."""
    return f"{count / 2**30:.1f} GiB" if count >= 2**30 else f"{count / 2**20:.1f} MiB"


def frames_fit(dataset, copies: int, available: int | None) -> tuple[bool, str]:
    """Whether the dataset's kept frames, `copies` times over, fit in MEMORY_SHARE of `available`;
    and the figures that say so."""
    needed = frame_bytes(dataset) * len(dataset) * copies
    if needed == 0:
        return True, "no frames"
    if available is None:
        return False, f"{size(needed)} of frames, and the memory available is unknown"
    figures = f"{size(needed)} of frames ({copies} cop{'y' if copies == 1 else 'ies'}) of {size(available)} available"
    return needed <= MEMORY_SHARE * available, figures


def loader_copies(cfg) -> int:
    """How many copies of the kept items a run holds: one per loader process (or the training
    process itself), in each training process accelerate launched."""
    return max(1, int(getattr(cfg, "num_workers", 0) or 0)) * max(1, int(os.environ.get("WORLD_SIZE", "1")))


@dataclass
class KeptItems:
    """What this process's training dataset keeps in memory: its number of items, or None."""

    count: int | None = None


def in_memory(dataset, copies: int, available: int | None) -> Dataset:
    """`dataset` wrapped in ItemsInMemory when it can be (its image transforms moved to the wrapper),
    or `dataset` itself when it cannot, logging which and why."""
    if not keeps_items(dataset):
        return dataset
    cameras = tuple(dataset.meta.camera_keys)
    if not cameras:
        logging.info(
            "so101: the dataset has no cameras: each of its %d items is kept in memory after its first read", len(dataset)
        )
        return ItemsInMemory(dataset)
    fits, figures = frames_fit(dataset, copies, available)
    if not fits:
        logging.warning(
            "so101: the dataset's items are read at every step, as lerobot-train does: keeping them would take %s", figures
        )
        return dataset
    transforms = dataset.image_transforms
    depth = set(getattr(dataset.meta, "depth_keys", ()) or ())
    dataset.clear_image_transforms()
    logging.info(
        "so101: each of the dataset's %d items is kept in memory after its first read (%s), its image augmentation "
        "applied at every read",
        len(dataset),
        figures,
    )
    return ItemsInMemory(dataset, cameras, tuple(camera for camera in cameras if camera not in depth), transforms)


def with_items_in_memory(make_datasets, kept: KeptItems, available: Callable[[], int | None] = memory_available):
    """lerobot-train's dataset factory, its training dataset kept in memory when it can be
    (noted in `kept`)."""

    def make(cfg):
        dataset, eval_dataset = make_datasets(cfg)
        dataset = in_memory(dataset, loader_copies(cfg), available())
        if isinstance(dataset, ItemsInMemory):
            kept.count = len(dataset)
        return dataset, eval_dataset

    return make


def recording_kept_items(save_checkpoint, kept: KeptItems):
    """lerobot-train's save_checkpoint (its main process's alone), each checkpoint then marked as
    one of a run that keeps its items in memory when it does."""

    def save(*args, **kwargs):
        save_checkpoint(*args, **kwargs)
        if kept.count is not None:
            record_items_in_memory(Path(kwargs["checkpoint_dir"] if "checkpoint_dir" in kwargs else args[0]), kept.count)

    return save


def main() -> None:
    from lerobot.optim import optimizers
    from lerobot.scripts import lerobot_train

    factory = getattr(lerobot_train, "make_train_eval_datasets", None)
    save_checkpoint = getattr(lerobot_train, "save_checkpoint", None)
    make_policy = getattr(lerobot_train, "make_policy", None)
    save_file = getattr(optimizers, "save_file", None)
    if None in (factory, save_checkpoint, make_policy, save_file):
        raise SystemExit(
            "so101.learn.train_in_memory: this LeRobot's lerobot-train makes its datasets, policy or checkpoints another "
            "way; train with so101-learn --reread-items (lerobot-train itself)"
        )
    kept = KeptItems()
    lerobot_train.make_train_eval_datasets = with_items_in_memory(factory, kept)
    lerobot_train.save_checkpoint = recording_kept_items(save_checkpoint, kept)
    # Under mixed precision with cameras, the layout oneDNN's bf16 convolutions want (so101.learn.channels_last).
    lerobot_train.make_policy = channels_last.making_channels_last(make_policy)
    optimizers.save_file = channels_last.saving_contiguous(save_file)
    lerobot_train.main()


if __name__ == "__main__":
    main()
