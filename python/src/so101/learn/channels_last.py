"""The camera policy's convolutions in channels_last memory format under mixed precision, inside
lerobot-train (which has no option for it): installed by so101.learn.train_in_memory.

Why: on a CPU with AMX, oneDNN's bfloat16 convolutions want channels_last. The camera ACT's model
step under bf16 autocast took 0.637 s with contiguous weights and 0.561 s with channels_last (0.88x);
in float32 the layout changed nothing (0.885 against 0.880 s; docs/benchmarks.md, "bf16 on a CPU
that has it"). So the layout follows the run's mixed precision (the policy config's `use_amp`, which
`so101-learn --bf16` sets and --resume keeps) and its cameras: a float32 run keeps lerobot-train's
weights to the bit.

The weights are saved contiguous all the same (safetensors' save_model makes them so); the
optimizer's moments, which AdamW creates in the parameters' layout, are made contiguous before
lerobot-train writes them, as safetensors requires.
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


def contiguous(value):
    """`value` (an optimizer's state dict, or any part of it) with every tensor contiguous."""
    if isinstance(value, torch.Tensor):
        return value.contiguous()
    if isinstance(value, dict):
        return {key: contiguous(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(contiguous(item) for item in value)
    return value


def saving_contiguous_state(save_optimizer_state: Callable) -> Callable:
    """lerobot's save_optimizer_state, given the optimizer's state with contiguous tensors (a dict
    of optimizers, which lerobot saves one by one, each so)."""

    def save(optimizer, save_dir, optim_state_dict=None):
        if isinstance(optimizer, dict):
            for name, one in optimizer.items():
                (save_dir / name).mkdir(exist_ok=True, parents=True)
                save(one, save_dir / name)
            return None
        state = optimizer.state_dict() if optim_state_dict is None else optim_state_dict
        return save_optimizer_state(optimizer, save_dir, optim_state_dict=contiguous(state))

    return save
