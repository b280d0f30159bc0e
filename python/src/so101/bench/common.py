"""What the benchmark scripts share: the environment of the Rust nodes they start, an rclpy
subscriber process that counts the messages of one topic, and how a report is put out."""

from __future__ import annotations

import json

from so101.paths import node_environment


def node_env(rust_log: str, keep_callers_level: bool = False) -> dict:
    """The environment for a Rust node (so101.paths.node_environment) with RUST_LOG as given, or as
    the caller set it when `keep_callers_level`."""
    env = node_environment()
    if keep_callers_level:
        env.setdefault("RUST_LOG", rust_log)
    else:
        env["RUST_LOG"] = rust_log
    return env


def counting_subscriber(package: str, message: str, topic: str, depth: int) -> str:
    """Python source of a process that counts `topic` messages until SIGINT, then prints the count
    (run as `python -c SOURCE`)."""
    return f"""
import rclpy
from rclpy.node import Node
from {package}.msg import {message}
rclpy.init()
node = Node('bench_subscriber')
count = [0]
node.create_subscription({message}, '{topic}', lambda m: count.__setitem__(0, count[0] + 1), {depth})
try:
    rclpy.spin(node)
except KeyboardInterrupt:
    pass
print(count[0])
"""


def report(lines: list[str], results, json_path) -> int:
    """Prints a benchmark's Markdown lines and writes its raw numbers to `json_path` (if given);
    the exit status."""
    print("\n".join(lines))
    if json_path:
        json_path.write_text(json.dumps(results, indent=2))
    return 0
