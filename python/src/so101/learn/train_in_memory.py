"""lerobot-train itself, with one change: a dataset without cameras keeps each item in memory after
its first read (`python -m so101.learn.train_in_memory` takes lerobot-train's arguments).

Why: LeRobotDataset builds an item from Arrow rows each time it is asked, about 6 ms per item on
this 2-core CPU for the state recipes' windows (2 observation steps, 16 actions), so 372 ms a batch
of 64, against 153 ms for a whole Diffusion step (forward, backward, AdamW) of the state recipe.
A state item is the same every epoch (image transforms and video decoding are the only random or
costly parts, and such a dataset has no cameras), so after the first pass the loader returns the
kept item. A dataset with cameras goes through untouched: its augmentation differs each epoch.
Each checkpoint of a run that keeps its items says so (so101.learn.checkpoints), for --resume.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from torch.utils.data import Dataset, IterableDataset

from .checkpoints import record_items_in_memory


class ItemsInMemory(Dataset):
    """A map-style dataset's items, each read once from `dataset` and then kept; every attribute
    but the items (meta, episodes, num_frames, ...) is the wrapped dataset's."""

    def __init__(self, dataset) -> None:
        self.dataset = dataset
        self.items: list[dict | None] = [None] * len(dataset)

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, index: int) -> dict:
        item = self.items[index]
        if item is None:
            item = self.items[index] = self.dataset[index]
        # A new dict each time: a consumer that adds or replaces keys leaves the kept item intact.
        return dict(item)

    def __getattr__(self, name: str):
        # Only for attributes this wrapper lacks. Not `dataset` itself (an unpickled copy has none
        # yet: it raises instead of recursing), nor Python's and torch's protocols: a batched
        # __getitems__ of the wrapped dataset would bypass the kept items.
        if name == "dataset" or name.startswith("__"):
            raise AttributeError(name)
        return getattr(self.dataset, name)


def keeps_items(dataset) -> bool:
    """Whether `dataset`'s items are the same at every read: a map-style dataset without cameras."""
    return not isinstance(dataset, IterableDataset) and not dataset.meta.camera_keys


@dataclass
class KeptItems:
    """What this process's training dataset keeps in memory: its number of items, or None."""

    count: int | None = None


def with_items_in_memory(make_datasets, kept: KeptItems):
    """lerobot-train's dataset factory, its training dataset wrapped in ItemsInMemory when its
    items are the same at every read (noted in `kept`)."""

    def make(cfg):
        dataset, eval_dataset = make_datasets(cfg)
        if keeps_items(dataset):
            logging.info(
                "so101: the dataset has no cameras: each of its %d items is kept in memory after its first read", len(dataset)
            )
            kept.count = len(dataset)
            dataset = ItemsInMemory(dataset)
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
    from lerobot.scripts import lerobot_train

    factory = getattr(lerobot_train, "make_train_eval_datasets", None)
    save_checkpoint = getattr(lerobot_train, "save_checkpoint", None)
    if factory is None or save_checkpoint is None:
        raise SystemExit(
            "so101.learn.train_in_memory: this LeRobot's lerobot-train makes its datasets or checkpoints another way; "
            "train with so101-learn --reread-items (lerobot-train itself)"
        )
    kept = KeptItems()
    lerobot_train.make_train_eval_datasets = with_items_in_memory(factory, kept)
    lerobot_train.save_checkpoint = recording_kept_items(save_checkpoint, kept)
    lerobot_train.main()


if __name__ == "__main__":
    main()
