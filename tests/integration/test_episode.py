"""Episodes and stepping: /sim/reset with seeded cube placement, --lockstep with /sim/step, the task
topics, /diagnostics and --duration."""

from __future__ import annotations

import math
import subprocess
import time

import pytest
from harness import (
    DIAGNOSTICS_STATUS_NAME,
    best_effort_qos,
    latest_diagnostics_values,
    stamp_nanoseconds,
    start_and_wait,
    wait_until,
)

SETTLE = 0.5  # s of wall time for the cube to come to rest after a reset


def cube_xyz(pose_stamped) -> tuple[float, float, float]:
    p = pose_stamped.pose.position
    return (p.x, p.y, p.z)


def cube_after(running, inbox, t_from: float) -> tuple[float, float, float]:
    """Cube position from the newest /cube/pose received at least SETTLE s after `t_from`."""
    wait_until(lambda: inbox.count() > 0 and inbox.items()[-1][0] >= t_from + SETTLE, 5.0, "a settled /cube/pose", running.sim)
    msg = inbox.latest()
    assert msg.header.frame_id == "world", f"/cube/pose frame_id {msg.header.frame_id!r}"
    xyz = cube_xyz(msg)
    assert all(math.isfinite(v) for v in xyz), f"cube pose {xyz}"
    return xyz


def reset(ros, running):
    from std_srvs.srv import Trigger

    response = ros.call(Trigger, running.sim.name("sim/reset"), sim=running.sim)
    assert response.success, f"/sim/reset failed: {response.message!r}"
    assert response.message, "/sim/reset answered without a message (it should say the cube position)"
    return response


def cube_sequence(sim_factory, ros, seed: int, resets: int = 3) -> list[tuple[float, float, float]]:
    """Start a node with --seed, return the cube position of its first episode and after each reset,
    then stop it (it must exit cleanly)."""
    from geometry_msgs.msg import PoseStamped

    running = start_and_wait(sim_factory, ros, "--seed", str(seed))
    inbox = ros.subscribe(running.sim.name("cube/pose"), PoseStamped, best_effort_qos())
    positions = [cube_after(running, inbox, time.monotonic())]
    for _ in range(resets):
        reset(ros, running)
        positions.append(cube_after(running, inbox, time.monotonic()))
    code = running.sim.stop()
    assert code == 0, f"node with --seed {seed} exited with {code} after SIGINT:\n{running.sim.log_tail()}"
    return positions


def test_reset_places_the_cube_somewhere_new_on_the_table(sim_factory, ros):
    from geometry_msgs.msg import PoseStamped

    running = start_and_wait(sim_factory, ros, "--seed", "3")
    inbox = ros.subscribe(running.sim.name("cube/pose"), PoseStamped, best_effort_qos())
    positions = [cube_after(running, inbox, time.monotonic())]
    for _ in range(3):
        reset(ros, running)
        positions.append(cube_after(running, inbox, time.monotonic()))

    table_z = positions[0][2]
    for before, after in zip(positions, positions[1:]):
        moved = math.dist(before[:2], after[:2])
        assert moved > 0.005, f"cube stayed at {before[:2]} -> {after[:2]} after /sim/reset"
        # Resting on the table again: same height as in the first episode.
        assert after[2] == pytest.approx(table_z, abs=0.01), (
            f"cube at z={after[2]:.4f} after reset, first episode z={table_z:.4f}"
        )
    # The joint_states keep coming across resets.
    running.joint_states.next_message(5.0, running.sim)


def test_same_seed_same_episodes_other_seed_others(sim_factory, ros):
    first = cube_sequence(sim_factory, ros, seed=7)
    again = cube_sequence(sim_factory, ros, seed=7)
    other = cube_sequence(sim_factory, ros, seed=8)
    for a, b in zip(first, again):
        assert math.dist(a[:2], b[:2]) < 0.001, f"--seed 7 twice gave different cube positions:\n{first}\n{again}"
    assert max(math.dist(a[:2], c[:2]) for a, c in zip(first, other)) > 0.01, (
        f"--seed 7 and --seed 8 gave the same cube positions:\n{first}\n{other}"
    )


@pytest.mark.parametrize("rate", [100, 50])
def test_lockstep_advances_exactly_one_period_per_step(sim_factory, ros, rate):
    from rosgraph_msgs.msg import Clock
    from std_srvs.srv import Trigger

    period_ns = round(1e9 / rate)
    tolerance_ns = 1000  # 1 us: "exactly", up to float rounding of the sim time
    sim = sim_factory("--lockstep", "--rate", str(rate))
    clock = ros.subscribe(sim.name("clock"), Clock, best_effort_qos())

    def step():
        response = ros.call(Trigger, sim.name("sim/step"), sim=sim)
        assert response.success, f"/sim/step failed in lockstep: {response.message!r}"

    def clock_values() -> list[int]:
        return [stamp_nanoseconds(m.clock) for m in clock.messages()]

    # Without steps, sim time stands still (the node may publish its initial time, never a new one).
    ros.wait_for_publisher(sim.name("clock"), 20.0, "the /clock publisher", sim)
    time.sleep(1.5)
    idle = set(clock_values())
    assert len(idle) <= 1, f"/clock advanced without /sim/step: {sorted(idle)[:10]}"

    # A first step gives the reference time.
    step()
    clock.wait_for(lambda msgs: msgs and stamp_nanoseconds(msgs[-1].clock) not in idle, 5.0, "a /clock after /sim/step", sim)
    base = clock_values()[-1]
    if idle:
        assert abs(base - (next(iter(idle)) + period_ns)) <= tolerance_ns, f"first step went {sorted(idle)} -> {base} ns"

    for k in range(1, 6):
        step()
        expected = base + k * period_ns
        clock.wait_for(
            lambda msgs: any(abs(stamp_nanoseconds(m.clock) - expected) <= tolerance_ns for m in msgs),
            5.0,
            f"/clock = {expected} ns after step {k}",
            sim,
        )
        time.sleep(0.05)
        beyond = [v for v in clock_values() if v > expected + tolerance_ns]
        assert not beyond, f"after step {k} /clock went past {expected} ns: {beyond}"

    # And stands still again.
    last = clock_values()[-1]
    time.sleep(1.0)
    assert max(clock_values()) <= last + tolerance_ns, "/clock advanced after the last /sim/step"


def test_step_is_refused_without_lockstep(sim_factory, ros):
    from std_srvs.srv import Trigger

    running = start_and_wait(sim_factory, ros)
    response = ros.call(Trigger, running.sim.name("sim/step"), sim=running.sim)
    assert not response.success, "/sim/step succeeded on a free-running node"
    running.joint_states.next_message(5.0, running.sim)


@pytest.mark.parametrize(
    "task_args",
    [
        ["--task", "cube_to_bin"],
        ["--task", "cube_to_bin", "--dense-reward"],
        ["--task", "touch_cube"],
        ["--task", "touch_cube_sparse"],
    ],
    ids=["cube_to_bin", "cube_to_bin_dense", "touch_cube", "touch_cube_sparse"],
)
def test_task_reward_and_success_are_published(sim_factory, ros, task_args):
    from std_msgs.msg import Bool, Float64

    rate = 100
    running = start_and_wait(sim_factory, ros, "--rate", str(rate), *task_args)
    reward = ros.subscribe(running.sim.name("task/reward"), Float64, best_effort_qos())
    success = ros.subscribe(running.sim.name("task/success"), Bool, best_effort_qos())
    reward.wait_count(1, 10.0, running.sim)
    success.wait_count(1, 10.0, running.sim)
    reward.clear()
    success.clear()
    running.joint_states.clear()
    time.sleep(1.0)

    rewards = [m.data for m in reward.messages()]
    successes = [m.data for m in success.messages()]
    periods = running.joint_states.count()
    # Once per control period, as /joint_states (allowing for best-effort delivery and the window's
    # edges); counted against the node's own periods, not wall time, which a busy machine stretches.
    assert periods >= 10, f"only {periods} /joint_states in 1 s at rate {rate}"
    assert len(rewards) >= 0.8 * periods, f"{len(rewards)} /task/reward for {periods} control periods"
    assert len(successes) >= 0.8 * periods, f"{len(successes)} /task/success for {periods} control periods"
    assert all(math.isfinite(r) for r in rewards), f"non-finite rewards: {rewards[:10]}"
    assert all(isinstance(s, bool) for s in successes)
    if "touch_cube_sparse" in task_args:
        assert set(rewards) <= {0.0, 1.0}, f"sparse reward takes values {sorted(set(rewards))[:10]}"
    if task_args == ["--task", "cube_to_bin"]:
        assert not any(successes), "cube_to_bin reports success at the start of an episode"


def test_diagnostics_report_command_counters(sim_factory, ros):
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState

    running = start_and_wait(sim_factory, ros)
    diagnostics = ros.subscribe(running.sim.name("diagnostics"), DiagnosticArray, best_effort_qos())
    pub = ros.publisher(running.sim.name("joint_commands"), JointState, sim=running.sim)
    current = running.current_positions()
    pub.publish(JointState(name=["gripper"], position=[current["gripper"]]))

    msgs = diagnostics.wait_for(
        lambda msgs: (
            (c := latest_diagnostics_values(msgs)) is not None
            and c.get("accepted_commands", "0").isdigit()
            and int(c["accepted_commands"]) >= 1
        ),
        5.0,
        f"a status {DIAGNOSTICS_STATUS_NAME!r} with accepted_commands >= 1",
        running.sim,
    )
    values = latest_diagnostics_values(msgs)
    for key in ("accepted_commands", "rejected_commands"):
        assert key in values, f"{key} missing from {values}"
        assert values[key].isdigit(), f"{key}={values[key]!r} is not a decimal integer"
    assert int(values["rejected_commands"]) == 0, f"a valid command was rejected: {values}"


def test_duration_exits_cleanly(sim_factory, ros):
    running = start_and_wait(sim_factory, ros, "--duration", "3")
    try:
        code = running.sim.proc.wait(timeout=3.0 + 10.0)
    except subprocess.TimeoutExpired:
        pytest.fail(f"--duration 3 still running after 13 s:\n{running.sim.log_tail()}", pytrace=False)
    assert code == 0, f"--duration 3 exited with {code}:\n{running.sim.log_tail()}"
