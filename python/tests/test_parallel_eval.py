"""so101.evaluate.parallel's split of evaluation seeds over worker processes: contiguous, nearly
equal shares that keep every episode's index, whatever the number of workers."""

from __future__ import annotations

import pytest

from so101.evaluate.parallel import split, threads_per_worker


@pytest.mark.parametrize("count, workers", [(10, 1), (10, 3), (7, 2), (3, 8), (1, 4), (100, 16)])
def test_shares_cover_every_seed_once_in_order(count, workers):
    seeds = list(range(500, 500 + count))
    shares = split(seeds, first_index=4, workers=workers)
    assert len(shares) == min(count, workers)
    assert [seed for _, share in shares for seed in share] == seeds
    sizes = [len(share) for _, share in shares]
    assert max(sizes) - min(sizes) <= 1
    # Each share's first index is the episode index of its first seed.
    for first_index, share in shares:
        assert first_index == 4 + seeds.index(share[0])


def test_no_seeds_no_shares():
    assert split([], 0, 4) == []


def test_each_worker_gets_at_least_one_thread_or_what_the_user_set(monkeypatch):
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    assert threads_per_worker(1) >= 1 and threads_per_worker(10_000) == 1
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    assert threads_per_worker(2) == 3
