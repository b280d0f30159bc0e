"""Evaluation episodes split over worker processes (so101-run-policy --eval N --workers K, on the
in-process backend): each worker loads the policy and runs a contiguous share of the seeds on a
simulation of its own, and the results come back in episode order, so the merged eval_info.json
holds the same numbers as one process running the same seeds (bit for bit at the same number of
torch threads: with another, matrix products sum in another order, and rewards differ in their
last digits). The split is pure; the pool is
Python's (spawned processes: no state of the parent's torch or simulation is shared)."""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor


def split(seeds: Sequence[int], first_index: int, workers: int) -> list[tuple[int, list[int]]]:
    """`seeds` in at most `workers` contiguous shares of nearly equal size, each with the episode
    index of its first seed."""
    workers = max(1, min(workers, len(seeds)))
    size, extra = divmod(len(seeds), workers)
    shares, start = [], 0
    for worker in range(workers):
        end = start + size + (1 if worker < extra else 0)
        if end > start:
            shares.append((first_index + start, list(seeds[start:end])))
        start = end
    return shares


def threads_per_worker(workers: int) -> int:
    """torch threads for each of `workers` processes: OMP_NUM_THREADS where the user set it (torch
    follows it), else the machine's cores shared out."""
    if os.environ.get("OMP_NUM_THREADS", "").isdigit():
        return max(1, int(os.environ["OMP_NUM_THREADS"]))
    return max(1, (os.cpu_count() or 1) // workers)


def run_shares(job: Callable, jobs: list[tuple], workers: int) -> list:
    """`job(*arguments)` for each of `jobs` on `workers` processes (a picklable top-level
    function); every job's results, in the jobs' order."""
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        futures = [pool.submit(job, *arguments) for arguments in jobs]
        return [result for future in futures for result in future.result()]
