"""What a LeRobot dataset on disk holds, read from its meta/ files: its cameras and the contract's
tasks its episodes carry. Shared by the recipes that train on it (lerobot_train, vla) and the
benchmarks that load it."""

from __future__ import annotations

import json
from pathlib import Path

from .. import contract
from ..dataset.parquet import read_parquet


def has_cameras(dataset: Path) -> bool:
    """Whether `dataset` is a LeRobot dataset with camera features (False when it is none yet)."""
    return (dataset / "meta" / "info.json").is_file() and bool(dataset_cameras(dataset))


def dataset_cameras(dataset: Path) -> list[str]:
    """The dataset's camera features (observation.images.<name>), from its meta/info.json."""
    features = json.loads((dataset / "meta" / "info.json").read_text())["features"]
    return [key for key, feature in features.items() if feature.get("dtype") in ("video", "image")]


def dataset_texts(dataset: Path) -> list[str]:
    """The task texts of the dataset's episodes (meta/tasks.parquet; none when unreadable)."""
    try:
        return list(read_parquet(Path(dataset) / "meta" / "tasks.parquet").index)
    except (OSError, ValueError):
        return []


def dataset_tasks(dataset: Path) -> list[str]:
    """The contract's tasks whose texts the dataset's episodes carry."""
    texts = dataset_texts(dataset)
    return [name for name, facts in contract.TASKS.items() if facts.description in texts]


def dataset_task(dataset: Path) -> str:
    """The contract's task whose text the dataset's episodes carry (the one the recipe evaluates
    on); cube_to_bin for a dataset of several tasks or of a text no task has."""
    texts = dataset_texts(dataset)
    tasks = [name for name, facts in contract.TASKS.items() if [facts.description] == texts]
    if not tasks:
        print(f"so101-learn: the dataset's tasks {texts} are no single task of the sim: evaluating on cube_to_bin")
    return tasks[0] if tasks else "cube_to_bin"
