"""so101-run-policy's live periods: late ones lose time instead of bursting, and the accounting
adds up whatever the machine's load (the integration test checks the same on the real runner)."""

from __future__ import annotations

import pytest

from so101.evaluate.run_policy import PeriodClock

PERIOD = 1 / 30


def run(work: list[float], duration: float) -> tuple[PeriodClock, list[float]]:
    """Runs the live loop's timing on a simulated clock: period k's work takes work[k % len] s,
    then the loop waits for the period's end as run_live does."""
    now = 100.0
    clock = PeriodClock(PERIOD, now)
    starts = []
    k = 0
    while clock.elapsed() < duration:
        starts.append(now)
        now += work[k % len(work)]
        tick = clock.next_period(now)
        now = max(now, tick)
        k += 1
    return clock, starts


def test_a_quiet_machine_sends_one_command_a_period_and_loses_nothing():
    clock, starts = run([0.005], 5.0)
    assert clock.periods in (150, 151) and clock.late == 0 and clock.lost == 0.0  # 151: 150 x (1/30) rounds below 5
    assert all(b - a == pytest.approx(PERIOD) for a, b in zip(starts, starts[1:]))


def test_late_periods_lose_time_instead_of_bursting():
    # Every third period's inference takes 80 ms, over two periods: it is late, the next starts at once.
    clock, starts = run([0.005, 0.005, 0.080], 5.0)
    assert clock.late > 0 and clock.lost > 0
    # Never two periods closer than one period, or than the work that ran in between.
    assert all(b - a >= PERIOD - 1e-9 for a, b in zip(starts, starts[1:]))
    assert clock.periods < 150
    # The accounting adds up: periods x period + lost covers the run, within one period.
    assert 5.0 <= clock.periods * PERIOD + clock.lost < 5.0 + PERIOD + 0.080


def test_a_stall_is_one_late_period_not_a_burst():
    clock, starts = run([0.005] * 10 + [1.0] + [0.005] * 200, 3.0)
    assert clock.late == 1 and clock.lost == pytest.approx(1.0 - PERIOD, abs=1e-9)
    gaps = [b - a for a, b in zip(starts, starts[1:])]
    assert max(gaps) == pytest.approx(1.0) and min(gaps) == pytest.approx(PERIOD)
    assert clock.periods * PERIOD + clock.lost >= 3.0
