"""so101-bench: runs one benchmark of so101.bench (docs/benchmarks.md); `so101-bench NAME --help`
for its arguments. DDS peers: run it inside scripts/isolated, as scripts/bench.sh does."""

from __future__ import annotations

import sys

from .. import subcommands
from . import (
    backgrounds,
    camera_align,
    camera_node,
    cameras,
    convert,
    driver,
    ee,
    expert,
    grasps,
    latency,
    model_step,
    pose_estimate,
    recorder,
    servo_model,
    sim,
    sim_core,
    storage,
    sysid,
    train_step,
)

BENCHMARKS = {
    module.__name__.rpartition(".")[2]: module.SUBCOMMAND
    for module in (
        sim,
        sim_core,
        driver,
        recorder,
        cameras,
        camera_node,
        camera_align,
        backgrounds,
        expert,
        ee,
        convert,
        storage,
        latency,
        servo_model,
        sysid,
        train_step,
        model_step,
        pose_estimate,
        grasps,
    )
}


def main(argv: list[str] | None = None) -> int:
    return subcommands.main("so101-bench", __doc__, BENCHMARKS, argv, metavar="NAME", title="benchmarks")


if __name__ == "__main__":
    sys.exit(main())
