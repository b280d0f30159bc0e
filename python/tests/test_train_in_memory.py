"""so101.learn.train_in_memory: each item is read once, then served from memory (a camera
dataset's frames as their 8-bit values, its augmentation applied at every read with the random
draws LeRobotDataset itself makes), and the wrapper is otherwise the dataset it wraps (lerobot-train
reads its meta, episodes, ...); a camera dataset whose frames would not fit goes through untouched."""

from __future__ import annotations

import json
import pickle
from types import SimpleNamespace

import pytest
import torch

from so101.learn.checkpoints import ITEMS_IN_MEMORY
from so101.learn.train_in_memory import (
    ItemsInMemory,
    KeptItems,
    compact_frames,
    expand_frames,
    frame_bytes,
    frames_fit,
    recording_kept_items,
    with_items_in_memory,
)

TOP, WRIST = "observation.images.top", "observation.images.wrist"


class CountingDataset(torch.utils.data.Dataset):
    """Items made of tensors, each read counted. With cameras, LeRobotDataset's way: frames decoded
    as 8-bit values over 255 (float32), then its image transforms, if any, applied to each camera in
    the meta's order."""

    def __init__(self, size: int, camera_keys: list[str], image_transforms=None, uint8: bool = False) -> None:
        self.reads = [0] * size
        self.meta = SimpleNamespace(
            camera_keys=camera_keys, features={camera: {"dtype": "video", "shape": [6, 8, 3]} for camera in camera_keys}
        )
        self.num_frames = size
        self.image_transforms = image_transforms
        self.uint8 = uint8  # as lerobot-train asks LeRobotDataset for its frames (return_uint8)

    def clear_image_transforms(self) -> None:
        self.image_transforms = None

    def __len__(self) -> int:
        return len(self.reads)

    def __getitem__(self, index: int) -> dict:
        self.reads[index] += 1
        item = {"action": torch.full((16, 6), float(index)), "task": "put the cube in the bin"}
        for number, camera in enumerate(self.meta.camera_keys):
            values = torch.arange(3 * 6 * 8).reshape(3, 6, 8).add(40 * index + number) % 256
            item[camera] = values.to(torch.uint8) if self.uint8 else values.type(torch.float32) / 255
        for camera in self.meta.camera_keys:
            if self.image_transforms is not None:
                item[camera] = self.image_transforms(item[camera])
        return item


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


def made(dataset, available: int | None = 2**30, workers: int = 1):
    """lerobot-train's factory wrapped, on `dataset`, with `available` bytes of memory."""
    kept = KeptItems()
    cfg = SimpleNamespace(num_workers=workers)
    return with_items_in_memory(lambda _cfg: (dataset, None), kept, lambda: available)(cfg)[0], kept


def test_every_dataset_is_kept_and_its_checkpoints_say_so(tmp_path):
    state, cameras = CountingDataset(3, []), CountingDataset(3, [TOP])
    saved = []

    def save_checkpoint(checkpoint_dir, step, **rest):  # lerobot-train's, as it calls it: by keyword
        checkpoint_dir.mkdir(parents=True)
        saved.append(step)

    for kind, dataset in (("state", state), ("cameras", cameras)):
        wrapped, kept = made(dataset)
        assert isinstance(wrapped, ItemsInMemory) and kept.count == 3
        checkpoint = tmp_path / kind / "checkpoints" / "000002"
        recording_kept_items(save_checkpoint, kept)(checkpoint_dir=checkpoint, step=2, cfg=None)
        # What --resume reads to go on the same way.
        assert json.loads((checkpoint / ITEMS_IN_MEMORY).read_text())["items"] == 3
    assert saved == [2, 2]


def test_camera_frames_are_kept_as_their_8_bit_values_and_come_back_as_the_same_floats():
    decoded = torch.arange(256, dtype=torch.uint8).type(torch.float32) / 255  # LeRobot's decoders' conversion
    kept = compact_frames(decoded)
    assert kept.values.dtype == torch.uint8 and expand_frames(kept).equal(decoded)
    # Anything else stays as it is: depth in metres, values between two 8-bit steps, and frames
    # LeRobot gives as uint8 (lerobot-train asks it to: its augmentation works on those).
    as_uint8 = torch.arange(256, dtype=torch.uint8)
    for other in (torch.tensor([0.5, 1.7]), torch.tensor([0.5 / 255]), as_uint8):
        assert compact_frames(other) is other and expand_frames(other) is other


@pytest.mark.parametrize("uint8", [True, False], ids=["uint8 frames", "float frames"])
def test_camera_items_are_decoded_once_and_augmented_at_every_read_as_lerobot_does(uint8):
    """The wrapper takes the dataset's transforms off and applies them at each read: the same
    random draws in the same order, so the same augmented frames as LeRobotDataset reading every
    item itself from the same seed. LeRobot's own transforms (the camera recipe's colour set)."""
    from lerobot.transforms.transforms import ImageTransformConfig, ImageTransforms, ImageTransformsConfig

    from so101.learn.lerobot_train import vision_preset

    tfs = json.loads(vision_preset()[1]["dataset.image_transforms.tfs"])
    config = ImageTransformsConfig(enable=True, tfs={name: ImageTransformConfig(**tf) for name, tf in tfs.items()})
    order = [2, 0, 3, 2, 1, 0, 3, 1]
    torch.manual_seed(7)
    reread = CountingDataset(4, [TOP, WRIST], ImageTransforms(config), uint8)
    expected = [reread[index] for index in order]
    torch.manual_seed(7)
    dataset = CountingDataset(4, [TOP, WRIST], ImageTransforms(config), uint8)
    wrapped, _ = made(dataset)
    assert dataset.image_transforms is None and wrapped.transforms is not None
    got = [wrapped[index] for index in order]
    assert dataset.reads == [1, 1, 1, 1]
    for want, have in zip(expected, got, strict=True):
        assert want.keys() == have.keys()
        for camera in (TOP, WRIST):
            assert have[camera].dtype == want[camera].dtype and have[camera].equal(want[camera])
    # The augmentation differs between two reads of one item; what is kept is the decoded frames.
    assert not got[0][TOP].equal(got[3][TOP])
    kept = wrapped.items[2][TOP]
    assert kept.dtype == torch.uint8 if uint8 else kept.values.dtype == torch.uint8


def test_camera_frames_that_would_not_fit_are_read_at_every_step(caplog):
    dataset = CountingDataset(1000, [TOP, WRIST])  # 1000 items of 2 x 144 bytes: 288 kB a copy
    assert frames_fit(dataset, 1, 576_000)[0] and not frames_fit(dataset, 3, 576_000)[0]
    wrapped, kept = made(dataset, available=576_000, workers=3)
    assert wrapped is dataset and kept.count is None
    assert "read at every step" in caplog.text and "0.8 MiB of frames (3 copies) of 0.5 MiB available" in caplog.text
    # Diffusion's two observation steps of a camera: twice its frames.
    dataset.delta_timestamps = {TOP: [-1 / 30, 0.0], "action": [0.0] * 16}
    assert frame_bytes(dataset) == 2 * 144 + 144
    # Unknown memory: not kept. A dataset without cameras needs none for frames.
    assert made(CountingDataset(10, [TOP]), available=None)[0].__class__ is CountingDataset
    assert isinstance(made(CountingDataset(10, []), available=None)[0], ItemsInMemory)


@pytest.mark.parametrize("workers", [0, 2])
def test_each_loader_process_keeps_a_copy(workers, monkeypatch):
    from so101.learn.train_in_memory import loader_copies

    monkeypatch.setenv("WORLD_SIZE", "2")
    assert loader_copies(SimpleNamespace(num_workers=workers)) == max(1, workers) * 2
