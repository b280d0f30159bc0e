"""Waiting on the ROS graph from the rclpy tools (replay, policy runner)."""

from __future__ import annotations

import time
from collections.abc import Callable


def spin_until(node, predicate: Callable[[], bool], timeout: float) -> bool:
    """Spins `node` until `predicate()` holds; False when `timeout` seconds pass first."""
    import rclpy

    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return False
        rclpy.spin_once(node, timeout_sec=0.05)
    return True
