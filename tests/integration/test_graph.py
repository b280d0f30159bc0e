"""The node as rclpy sees it: name, topics with types, services, namespace."""

from __future__ import annotations

import time

import pytest
from harness import NODE_NAME, PUBLISHED_TOPICS, SERVICES, SUBSCRIBED_TOPICS, start_and_wait

DISCOVERY_TIMEOUT = 20.0


def wait_for_graph(ros, sim, expected_topics: dict[str, str], expected_services: dict[str, str]):
    """Wait until every expected name shows up in rclpy's graph with its type; fail listing what is
    missing or mistyped."""
    deadline = time.monotonic() + DISCOVERY_TIMEOUT
    while True:
        topics, services = ros.topics(), ros.services()
        wrong = {n: topics.get(n) for n, t in expected_topics.items() if t not in topics.get(n, [])}
        wrong.update({n: services.get(n) for n, t in expected_services.items() if t not in services.get(n, [])})
        if not wrong:
            return topics, services
        sim.assert_alive()
        if time.monotonic() > deadline:
            pytest.fail(
                f"after {DISCOVERY_TIMEOUT} s these names are missing or have other types (seen: {wrong});\n"
                f"expected topics {expected_topics},\nexpected services {expected_services};\n"
                f"the graph has topics {topics}\nand services {services}",
                pytrace=False,
            )
        time.sleep(0.1)


def test_node_and_topics_are_discovered(sim_factory, ros):
    sim = sim_factory()
    deadline = time.monotonic() + DISCOVERY_TIMEOUT
    while (NODE_NAME, "/") not in ros.node.get_node_names_and_namespaces():
        sim.assert_alive()
        if time.monotonic() > deadline:
            pytest.fail(
                f"node {NODE_NAME} not seen in namespace / within {DISCOVERY_TIMEOUT} s; "
                f"nodes seen: {ros.node.get_node_names_and_namespaces()}",
                pytrace=False,
            )
        time.sleep(0.1)

    expected = {f"/{k}": v for k, v in {**PUBLISHED_TOPICS, **SUBSCRIBED_TOPICS}.items()}
    wait_for_graph(ros, sim, expected, {f"/{k}": v for k, v in SERVICES.items()})

    # Directions: the node publishes the first group and subscribes the second.
    for topic in PUBLISHED_TOPICS:
        assert ros.node.count_publishers(f"/{topic}") >= 1, f"/{topic} has no publisher"
    for topic in SUBSCRIBED_TOPICS:
        assert ros.node.count_subscribers(f"/{topic}") >= 1, f"/{topic} has no subscriber"


def test_node_info_lists_its_endpoints(sim_factory, ros):
    """What `ros2 node info /so101_sim_node` shows: endpoints attributed to the node by name."""
    sim = sim_factory()
    wait_for_graph(ros, sim, {f"/{k}": v for k, v in PUBLISHED_TOPICS.items()}, {})

    def by_node():
        pubs = dict(ros.node.get_publisher_names_and_types_by_node(NODE_NAME, "/"))
        subs = dict(ros.node.get_subscriber_names_and_types_by_node(NODE_NAME, "/"))
        srvs = dict(ros.node.get_service_names_and_types_by_node(NODE_NAME, "/"))
        return pubs, subs, srvs

    deadline = time.monotonic() + DISCOVERY_TIMEOUT
    while True:
        try:
            pubs, subs, srvs = by_node()
        except Exception:  # noqa: BLE001 - node not known yet (rclpy raises NodeNameNonExistentError)
            pubs, subs, srvs = {}, {}, {}
        missing = [f"pub /{t}" for t, ty in PUBLISHED_TOPICS.items() if ty not in pubs.get(f"/{t}", [])]
        missing += [f"sub /{t}" for t, ty in SUBSCRIBED_TOPICS.items() if ty not in subs.get(f"/{t}", [])]
        missing += [f"srv /{s}" for s, ty in SERVICES.items() if ty not in srvs.get(f"/{s}", [])]
        if not missing:
            return
        sim.assert_alive()
        if time.monotonic() > deadline:
            pytest.fail(
                f"endpoints not attributed to node /{NODE_NAME}: {missing}\n"
                f"publishers {pubs}\nsubscribers {subs}\nservices {srvs}",
                pytrace=False,
            )
        time.sleep(0.1)


def test_namespace_prefixes_every_name(sim_factory, ros):
    from std_srvs.srv import Trigger

    running = start_and_wait(sim_factory, ros, "--namespace", "arm1")
    sim = running.sim
    assert sim.name("joint_states") == "/arm1/joint_states"
    expected = {f"/arm1/{k}": v for k, v in {**PUBLISHED_TOPICS, **SUBSCRIBED_TOPICS}.items()}
    wait_for_graph(ros, sim, expected, {f"/arm1/{k}": v for k, v in SERVICES.items()})

    # Nothing of it is left at the root.
    for relative in [*PUBLISHED_TOPICS, *SUBSCRIBED_TOPICS]:
        assert ros.node.count_publishers(f"/{relative}") == 0, f"/{relative} published without the namespace"
        assert ros.node.count_subscribers(f"/{relative}") == 0, f"/{relative} subscribed without the namespace"
    services = ros.services()
    assert not any(f"/{name}" in services for name in SERVICES), f"services at the root: {services}"

    # And it works there.
    running.joint_states.wait_count(10, 5.0, sim)
    response = ros.call(Trigger, "/arm1/sim/reset", sim=sim)
    assert response.success, response.message
