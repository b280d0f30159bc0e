"""The command that runs a training module on several processes through accelerate (LeRobot's
multi-GPU training: one process per GPU, or processes sharing the CPU's cores over gloo)."""

from __future__ import annotations

import os
import socket
import sys
from pathlib import Path


def free_port() -> int:
    """A TCP port no one listens on now (the system picks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def accelerate_command(num_processes: int, module: str) -> list[str]:
    """accelerate launch with `num_processes` processes running lerobot-train's `module` (its
    arguments follow): LeRobot's multi-GPU training, or processes on the CPU (gloo) where the
    policy's device is the CPU."""
    accelerate = str(Path(sys.executable).with_name("accelerate"))
    return [
        accelerate,
        "launch",
        f"--num_processes={num_processes}",
        # torch.distributed's launcher for either: lerobot-train's Accelerator takes the CPU (gloo)
        # itself when the policy's device is the CPU.
        "--multi_gpu",
        # accelerate gives each process one thread unless told: on the CPU they share the cores.
        f"--num_cpu_threads_per_process={max(1, (os.cpu_count() or 1) // num_processes)}",
        "--num_machines=1",
        # A port of its own for the processes' rendezvous: at accelerate's fixed default, a second
        # training on the machine would join the first one's group and both would wait forever.
        f"--main_process_port={free_port()}",
        "--mixed_precision=no",
        "--dynamo_backend=no",
        "-m",
        module,
    ]
