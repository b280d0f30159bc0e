"""A lerobot-train run directory as LeRobot leaves it, read for `so101-learn act|diffusion --resume`:
OUTPUT/checkpoints/<step>/ with pretrained_model/ (the weights and train_config.json) and
training_state/ (optimizer, scheduler, RNG, training_step.json), and checkpoints/last pointing at
the newest checkpoint once it is written whole (the names are LeRobot's, lerobot.utils.constants);
in each checkpoint, beside LeRobot's, ours: whether the run keeps its items in memory
(so101.learn.train_in_memory). Also the policy a new run starts from (--init): a checkpoint's
pretrained_model/."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

CHECKPOINTS = "checkpoints"
LAST = "last"
TRAIN_CONFIG = Path("pretrained_model") / "train_config.json"
TRAINING_STEP = Path("training_state") / "training_step.json"
# In a checkpoint: its run keeps its items in memory. --resume reads it to go on the same way: a
# run's loading decides its weights (lerobot-train's loader process alone changes them).
ITEMS_IN_MEMORY = "so101_items_in_memory.json"


class CheckpointError(Exception):
    """A run directory with no checkpoint to resume from; the message says what is missing."""


@dataclass(frozen=True)
class Checkpoint:
    """The last checkpoint of a run."""

    config_file: Path  # its train_config.json: what lerobot-train --config_path takes
    config: dict  # that file's settings (policy, dataset, steps, batch_size, ...)
    step: int  # the training step it was written at
    num_processes: int | None  # the processes that trained it (None: a LeRobot older than the record)
    # Its run kept its items in memory. False for lerobot-train's own loading, and for a run
    # started before the record existed (before 2026-11-29, 04:36 UTC).
    items_in_memory: bool


def last_checkpoint(output: Path) -> Checkpoint:
    """The run's last checkpoint. checkpoints/last may be a link (as LeRobot makes it) or a
    directory (a run copied without links). Raises CheckpointError when there is none, or when
    it lacks its settings or its step."""
    last = output / CHECKPOINTS / LAST
    if not last.is_dir():
        numbered = sorted(path.name for path in (output / CHECKPOINTS).glob("[0-9]*") if path.is_dir())
        if numbered:
            raise CheckpointError(
                f"{output}: {CHECKPOINTS}/{LAST} is missing or points nowhere, beside the checkpoints "
                f"{', '.join(numbered)}: point it at the newest whole one (ln -sfn {numbered[-1]} {last})"
            )
        raise CheckpointError(
            f"{output} has no checkpoint to resume from (no {CHECKPOINTS}/{LAST}): a run writes its first one "
            "after --save-every steps"
        )
    for required in (TRAIN_CONFIG, TRAINING_STEP):
        if not (last / required).is_file():
            raise CheckpointError(f"{output}: the last checkpoint lacks {required}")
    state = json.loads((last / TRAINING_STEP).read_text())
    return Checkpoint(
        config_file=last / TRAIN_CONFIG,
        config=json.loads((last / TRAIN_CONFIG).read_text()),
        step=int(state["step"]),
        num_processes=state.get("num_processes"),
        items_in_memory=(last / ITEMS_IN_MEMORY).is_file(),
    )


def record_items_in_memory(checkpoint_dir: Path, items: int) -> None:
    """Marks a checkpoint as one of a run keeping its items in memory (written beside its
    pretrained_model/ and training_state/, so it travels with the checkpoint)."""
    (checkpoint_dir / ITEMS_IN_MEMORY).write_text(json.dumps({"items_in_memory": True, "items": items}) + "\n")


def init_problem(policy_type: str, checkpoint: Path) -> str | None:
    """Why a run of `policy_type` cannot start from `checkpoint`'s weights (--init), or None."""
    config = checkpoint / "config.json"
    if not (config.is_file() and (checkpoint / "model.safetensors").is_file()):
        return f"--init {checkpoint} holds no policy (config.json and model.safetensors: a checkpoint's pretrained_model)"
    found = json.loads(config.read_text()).get("type")
    if found != policy_type:
        return f"--init {checkpoint} is a {found} policy, not {policy_type}"
    return None
