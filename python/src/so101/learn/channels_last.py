"""The camera policy's convolutions in channels_last memory format under mixed precision, inside
lerobot-train (which has no option for it): installed by so101.learn.train_in_memory.

Why: on a CPU with AMX, oneDNN's bfloat16 convolutions want channels_last. The camera ACT's model
step under bf16 autocast took 0.637 s with contiguous weights and 0.561 s with channels_last (0.88x);
in float32 the layout changed nothing (0.885 against 0.880 s; docs/benchmarks.md, "bf16 on a CPU
that has it"). So the layout follows the run's mixed precision (the policy config's `use_amp`, which
`so101-learn --bf16` sets and --resume keeps) and its cameras: a float32 run keeps lerobot-train's
weights to the bit.

The weights are saved contiguous all the same (safetensors' save_model makes them so); the
optimizer's moments, which AdamW creates in the parameters' layout, are made contiguous where
LeRobot's optimizer saver hands them to safetensors, which requires it.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import torch


def wants_channels_last(policy_config) -> bool:
    """Whether a policy of this config trains in channels_last: under mixed precision, with images."""
    return bool(getattr(policy_config, "use_amp", False)) and bool(getattr(policy_config, "image_features", None))


def in_channels_last(policy: torch.nn.Module) -> torch.nn.Module:
    """`policy` with its 4-D weights (the convolutions') in channels_last, in place."""
    return policy.to(memory_format=torch.channels_last)


def making_channels_last(make_policy: Callable) -> Callable:
    """lerobot-train's make_policy, its policy turned channels_last when its config wants it."""

    def make(*args, **kwargs):
        policy = make_policy(*args, **kwargs)
        config = kwargs.get("cfg", args[0] if args else None)
        if wants_channels_last(config):
            logging.info("so101: the policy's convolutions train in channels_last (mixed precision with cameras)")
            return in_channels_last(policy)
        return policy

    return make


def contiguous_tensors(tensors: dict) -> dict:
    """`tensors` (safetensors' name -> tensor) with every tensor contiguous."""
    return {name: tensor.contiguous() for name, tensor in tensors.items()}


def saving_contiguous(save_file: Callable) -> Callable:
    """safetensors' save_file, as LeRobot's optimizer saver calls it, each tensor made contiguous
    first (every optimizer of a run, however LeRobot groups them, goes through it)."""

    def save(tensors, filename, metadata=None):
        return save_file(contiguous_tensors(tensors), filename, metadata=metadata)

    return save
