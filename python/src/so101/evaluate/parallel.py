"""Evaluation episodes split over worker processes (so101-run-policy --eval N --workers K, on the
in-process backend): each worker loads the policy and runs a contiguous share of the seeds on a
simulation of its own, and the results come back in episode order, so the merged eval_info.json
holds the same numbers as one process running the same seeds (bit for bit at the same number of
torch threads: with another, matrix products sum in another order, and rewards differ in their
last digits). The split is pure; the pool is
Python's, its processes forked from a fork server that has imported the heavy modules once (LeRobot
and torch take about 10 s of CPU to import, which each spawned worker paid again) and holds no
state of the parent's torch or simulation: nothing has run there but imports."""

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


def start_fork_server(job: Callable, preload: Sequence[str] = ()) -> None:
    """Starts the workers' fork server if it is not running, importing `job`'s module and
    `preload` there; called early, those imports run beside this process's own."""
    from multiprocessing import forkserver

    # Takes effect where the server is not running yet (a running one keeps its imports).
    multiprocessing.get_context("forkserver").set_forkserver_preload([job.__module__, *preload])
    forkserver.ensure_running()


def run_shares(job: Callable, jobs: list[tuple], workers: int, preload: Sequence[str] = ()) -> list:
    """`job(*arguments)` for each of `jobs` on `workers` processes (a picklable top-level
    function); every job's results, in the jobs' order. The workers fork from the server
    start_fork_server started (here, with `preload`, unless it came first)."""
    start_fork_server(job, preload)
    context = multiprocessing.get_context("forkserver")
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        futures = [pool.submit(job, *arguments) for arguments in jobs]
        return [result for future in futures for result in future.result()]
