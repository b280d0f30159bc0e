"""What an rclpy program does when DDS discovery misses a node's publishers.

Fast DDS 2.14 (the Jazzy rclpy wheels' middleware) sometimes acknowledges every publication a
starting RustDDS node announces and registers none of them: the program's graph shows no
publisher of the node's topics, its subscriptions never match, and Fast DDS asks for nothing
again, so the participant stays blind to them for good (docs/real_arm.md, "Troubleshooting",
has the packet-level trace). A participant created afterwards discovers the same node at once.
Programs that wait for a node's first messages therefore replace their participant when a topic
they need still has no publisher after `REDISCOVER_AFTER_S`.
"""

from __future__ import annotations

import time

# Discovery on one machine completes within about a second even on a loaded 2-core host; three
# seconds without a single publisher means the node is absent or was missed.
REDISCOVER_AFTER_S = 3.0


def without_publishers(node, topics: list[str]) -> list[str]:
    """The topics (absolute names) for which `node`'s participant has discovered no publisher."""
    return [topic for topic in topics if node.count_publishers(topic) == 0]


def blind_to(node, topics: list[str], looking_since: float) -> list[str]:
    """The topics without a discovered publisher once REDISCOVER_AFTER_S have passed since
    `looking_since` (time.monotonic: the participant opened, or the node started); none before."""
    if time.monotonic() - looking_since < REDISCOVER_AFTER_S:
        return []
    return without_publishers(node, topics)


def publishers_seen(node, topics: list[str]) -> str:
    """What discovery found for each topic: no publisher at all points at the node or the domain,
    a publisher that sends nothing here at QoS or at the DDS link between the two."""
    seen = []
    for topic in topics:
        nodes = sorted(
            {f"{info.node_namespace.rstrip('/')}/{info.node_name}" for info in node.get_publishers_info_by_topic(topic)}
        )
        seen.append(f"{topic}: {len(nodes)} publisher(s) discovered{' (' + ', '.join(nodes) + ')' if nodes else ''}")
    return "; ".join(seen)
