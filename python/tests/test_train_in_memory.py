"""so101.learn.train_in_memory: a dataset without cameras is read once per item, then served from
memory, and is otherwise the dataset it wraps (lerobot-train reads its meta, episodes, ...)."""

from __future__ import annotations

import json
import pickle
from types import SimpleNamespace

import torch

from so101.learn.checkpoints import ITEMS_IN_MEMORY
from so101.learn.train_in_memory import ItemsInMemory, KeptItems, keeps_items, recording_kept_items, with_items_in_memory


class CountingDataset(torch.utils.data.Dataset):
    """Items made of tensors, each read counted; cameras as LeRobotDataset's meta lists them."""

    def __init__(self, size: int, camera_keys: list[str]) -> None:
        self.reads = [0] * size
        self.meta = SimpleNamespace(camera_keys=camera_keys)
        self.num_frames = size

    def __len__(self) -> int:
        return len(self.reads)

    def __getitem__(self, index: int) -> dict:
        self.reads[index] += 1
        return {"action": torch.full((16, 6), float(index)), "task": "put the cube in the bin"}


def test_each_item_is_read_once_then_served_from_memory():
    dataset = CountingDataset(5, [])
    kept = ItemsInMemory(dataset)
    loader = torch.utils.data.DataLoader(kept, batch_size=2, shuffle=True)
    epochs = [torch.cat([batch["action"][:, 0, 0] for batch in loader]) for _ in range(3)]
    assert dataset.reads == [1] * 5
    for values in epochs:
        assert sorted(values.tolist()) == [0.0, 1.0, 2.0, 3.0, 4.0]
    # A consumer that replaces a key changes its own copy, not the kept item.
    kept[3]["action"] = None
    assert kept[3]["action"][0, 0] == 3.0 and dataset.reads[3] == 1


def test_the_wrapper_is_the_dataset_it_wraps_but_for_its_items():
    dataset = CountingDataset(4, [])
    kept = ItemsInMemory(dataset)
    assert len(kept) == 4 and kept.num_frames == 4 and kept.meta is dataset.meta
    # A spawned loader process gets a copy by pickling.
    copy = pickle.loads(pickle.dumps(kept))
    assert copy.num_frames == 4 and float(copy[2]["action"][0, 0]) == 2.0
    # Protocols are the wrapper's own: a batched read of the wrapped dataset would bypass the kept items.
    dataset.__getitems__ = lambda indices: [dataset[i] for i in indices]
    assert not hasattr(kept, "__getitems__")


def test_only_a_dataset_without_cameras_is_kept_and_its_checkpoints_say_so(tmp_path):
    state, cameras = CountingDataset(3, []), CountingDataset(3, ["observation.images.top"])
    assert keeps_items(state) and not keeps_items(cameras)
    saved = []

    def save_checkpoint(checkpoint_dir, step, **rest):  # lerobot-train's, as it calls it: by keyword
        checkpoint_dir.mkdir(parents=True)
        saved.append(step)

    for kind, dataset in (("state", state), ("cameras", cameras)):
        kept = KeptItems()
        made = with_items_in_memory(lambda cfg: ({"state": state, "cameras": cameras}[cfg], None), kept)(kind)[0]
        assert isinstance(made, ItemsInMemory) if kind == "state" else made is dataset
        checkpoint = tmp_path / kind / "checkpoints" / "000002"
        recording_kept_items(save_checkpoint, kept)(checkpoint_dir=checkpoint, step=2, cfg=None)
        # What --resume reads to go on the same way.
        record = checkpoint / ITEMS_IN_MEMORY
        assert record.is_file() == (kind == "state")
    assert saved == [2, 2]
    assert json.loads((tmp_path / "state" / "checkpoints" / "000002" / ITEMS_IN_MEMORY).read_text())["items"] == 3
