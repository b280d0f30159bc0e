"""A node stopped and resumed (Ctrl+Z then `fg`): the stop interrupts RustDDS's waits and RustDDS
0.15.1 ends its event loop and discovery threads on that error, so the resumed node would run on
deaf and mute. It says why and stops cleanly instead (so101_core::ros::shutdown)."""

from __future__ import annotations

import signal
import time

from harness import start_and_wait, wait_until


def test_a_node_resumed_after_a_stop_says_its_dds_is_gone_and_exits_cleanly(sim_factory, ros):
    running = start_and_wait(sim_factory, ros)
    sim = running.sim
    sim.proc.send_signal(signal.SIGSTOP)
    time.sleep(0.3)
    sim.proc.send_signal(signal.SIGCONT)
    wait_until(lambda: not sim.alive(), 10.0, "the resumed node's exit", sim)
    assert sim.proc.returncode == 0, sim.log_tail()
    assert "resumed after a stop" in sim.log(), sim.log_tail()
