"""so101.stack.process: children stopped the way the nodes expect (SIGINT first, SIGKILL only for one
that ignores it), with their output collected."""

from __future__ import annotations

import subprocess
import sys
import time

from so101.stack import process

# A child that reports SIGINT on stdout and exits 0, like the nodes' clean shutdown.
POLITE = """
import signal, sys, time
signal.signal(signal.SIGINT, lambda *_: (print("interrupted", flush=True), sys.exit(0)))
print("up", flush=True)
time.sleep(60)
"""
# A child that ignores SIGINT.
STUBBORN = """
import signal, time
signal.signal(signal.SIGINT, signal.SIG_IGN)
print("up", flush=True)
time.sleep(60)
"""


def started(source: str) -> subprocess.Popen:
    child = process.start([sys.executable, "-c", source], stdout=subprocess.PIPE, text=True)
    assert child.stdout.readline().strip() == "up"
    return child


def test_stop_interrupts_a_child_that_exits_on_sigint():
    child = started(POLITE)
    assert process.stop(child, timeout=10) == 0


def test_stop_kills_a_child_that_ignores_sigint_after_the_timeout():
    child = started(STUBBORN)
    begun = time.monotonic()
    assert process.stop(child, timeout=0.5) == -9
    assert time.monotonic() - begun < 5


def test_interrupt_and_collect_returns_what_the_child_wrote_after_the_signal():
    child = started(POLITE)
    out, _ = process.interrupt_and_collect(child, timeout=10)
    assert out.strip() == "interrupted" and child.returncode == 0


def test_stopping_a_child_that_already_exited_returns_its_status():
    child = process.start([sys.executable, "-c", "raise SystemExit(3)"])
    child.wait()
    assert process.stop(child) == 3
