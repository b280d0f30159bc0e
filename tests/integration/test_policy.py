"""The loop back from LeRobot: a tiny ACT policy, built from its config and trained for a few steps
on the CPU by lerobot-train on a dataset converted from expert bags, runs through
so101-run-policy: an evaluation episode on its own sim in lockstep (eval_info.json, an MP4 that
PyAV decodes frame for frame), live against a running sim (commands at the policy's fps, inside
the joint limits) and on the driver with so101_camera_node's JPEG frames (the real arm, emulated);
a bad policy and a missing camera are reported, not fatal to the arm."""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
from harness import TINY_ACT, SimNode, best_effort_qos, blind_domain, node_binary, reliable_qos, wait_until

JOINTS = ["shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper"]
LIMITS = [(-1.9199, 1.9199), (-1.7453, 1.7453), (-1.69, 1.69), (-1.6581, 1.6581), (-2.7438, 2.8412), (-0.1745, 1.7453)]
VENV_BIN = Path(sys.executable).parent
CAMERAS = "top:64x48,wrist:64x48"


def run(argv: list[str], timeout: float, env_extra: dict | None = None, **kwargs) -> subprocess.CompletedProcess:
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "WANDB_MODE": "disabled", **(env_extra or {})}
    return subprocess.run([str(a) for a in argv], capture_output=True, text=True, timeout=timeout, env=env, **kwargs)


def train_tiny_act(dataset: Path, output: Path) -> Path:
    """lerobot-train, as a user runs it: ACT shrunk to a few thousand transformer weights, no
    pretrained backbone (nothing downloaded), 3 steps on the CPU."""
    done = run(
        [
            VENV_BIN / "lerobot-train",
            "--dataset.repo_id=local/so101_policy_test",
            f"--dataset.root={dataset}",
            *TINY_ACT,
            "--policy.n_vae_encoder_layers=1",
            "--policy.chunk_size=10",
            "--policy.n_action_steps=10",
            "--steps=3",
            "--batch_size=4",
            "--num_workers=0",
            "--save_freq=3",
            "--log_freq=1",
            "--wandb.enable=false",
            f"--output_dir={output}",
        ],
        timeout=300,
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    checkpoint = output / "checkpoints" / "last" / "pretrained_model"
    assert (checkpoint / "model.safetensors").is_file() and (checkpoint / "policy_preprocessor.json").is_file()
    return checkpoint


def test_a_tiny_act_trained_on_a_converted_dataset_runs_through_the_runner(
    sim_factory, recorder_factory, teleop_factory, arm_factory, ros, tmp_path
):
    # Demonstrations: one expert episode, recorded and converted.
    sim = sim_factory("--speed", "2", "--seed", "5", "--cameras", CAMERAS)
    recorder = recorder_factory()
    ros.wait_for_graph(lambda: ros.node.count_subscribers("/episode/events") >= 1, 20.0, "the recorder", sim)
    teleop = teleop_factory("--source", "expert", "--sim-time", "--episodes", "1", "--seed", "5")
    wait_until(lambda: not teleop.alive(), 90.0, "the expert's episode", sim)
    # Where the expert left the cube, for the stand-in cube tracker the arm needs below.
    from geometry_msgs.msg import PoseStamped

    cube = ros.one_message("/cube/pose", PoseStamped, 20.0, sim)
    wait_until(lambda: (recorder.output / "episode_000000" / "metadata.yaml").is_file(), 20.0, "the closed episode", sim)
    dataset = tmp_path / "dataset"
    done = run(
        [
            VENV_BIN / "so101-bag-to-lerobot",
            recorder.output,
            "--output",
            dataset,
            "--repo-id",
            "local/so101_policy_test",
            "--quiet",
        ],
        timeout=300,
    )
    # The expert's verdict through the stack is timing's to decide (99 % or so); the policy's few
    # training steps need the episode, not its success.
    assert done.returncode == 0 and "1 episode(s) (" in done.stdout, done.stdout + done.stderr

    checkpoint = train_tiny_act(dataset, tmp_path / "train")

    # Evaluation: one seeded episode of 2 s on the runner's own sim in lockstep, on the held-out
    # shift set (wider ranges, pictures behind the scene, a distractor).
    evaluation = tmp_path / "eval"
    done = run(
        [
            VENV_BIN / "so101-run-policy",
            checkpoint,
            "--eval",
            "1",
            "--seed",
            "7",
            "--episode-time",
            "2",
            "--lite",
            "--randomize",
            "heldout",
            "--output",
            evaluation,
            "--quiet",
        ],
        timeout=300,
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    info = json.loads((evaluation / "eval_info.json").read_text())
    assert info["aggregated"]["episodes"] == 1 and info["aggregated"]["pc_success"] in (0.0, 100.0)
    assert info["aggregated"]["randomize"] == "heldout" and info["aggregated"]["servo_params"] == "sts3215"
    # The episode ran on a randomized world: the runner reports the draw the sim published.
    draw = info["per_episode"][0]["settings"]["draw"]
    assert draw["seed"] > 0 and draw["background"] is not None and len(draw["distractor"]["position"]) == 2, draw
    episode = info["per_episode"][0]
    assert episode["seed"] == 7 and episode["steps"] == 60, episode  # 2 s at 30 fps, unless it succeeded: it cannot
    assert math.isfinite(episode["sum_reward"]) and episode["max_reward"] >= 0.0
    assert "1 episode(s): success" in done.stdout, done.stdout

    # The same episodes in-process, in one process and split over two: the same numbers, bit for
    # bit at one torch thread each (with another count, rewards differ in their 8th digit).
    reports = {}
    for workers in (1, 2):
        output = tmp_path / f"eval_inprocess_{workers}"
        done = run(
            [VENV_BIN / "so101-run-policy", checkpoint, "--eval", "3", "--seed", "11", "--episode-time", "1", "--lite",
             "--backend", "inprocess", "--workers", str(workers), "--videos", "1", "--output", output, "--quiet"],
            timeout=300,
            env_extra={"OMP_NUM_THREADS": "1"},
        )  # fmt: skip
        assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
        reports[workers] = json.loads((output / "eval_info.json").read_text())
    sequential, split = reports[1]["per_episode"], reports[2]["per_episode"]
    assert [e["seed"] for e in split] == [11, 12, 13]
    for alone, shared in zip(sequential, split):
        assert {k: alone[k] for k in ("seed", "success", "steps", "sum_reward", "max_reward")} == {
            k: shared[k] for k in ("seed", "success", "steps", "sum_reward", "max_reward")
        }
    assert reports[1]["aggregated"] == reports[2]["aggregated"]
    assert split[0]["video"] and not split[1]["video"]

    import av

    with av.open(episode["video"]) as container:
        frames = [frame.to_ndarray(format="rgb24") for frame in container.decode(video=0)]
    assert len(frames) == 60, f"{len(frames)} video frames for 60 steps"
    # The policy's two 64x48 cameras side by side, each pixel repeated 8 times: a watchable 384 rows.
    assert frames[0].shape == (384, 1024, 3), "the video is not the policy's two cameras side by side, enlarged"
    assert frames[0].std() > 5, "a blank video"

    # Live: against a sim running in real time, under a namespace of its own.
    from sensor_msgs.msg import JointState

    live = sim_factory("--cameras", CAMERAS, "--namespace", "live")
    commands = ros.subscribe("/live/joint_commands", JointState, reliable_qos(1000))
    done = run([VENV_BIN / "so101-run-policy", checkpoint, "--namespace", "live", "--duration", "5", "--reset"], timeout=120)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    live.assert_alive()
    # The runner's own accounting adds up, however busy the machine: every period of the 5 s either
    # sent a command or held the arm, and late periods lose wall time instead of bursting to catch up
    # (5 s = periods / 30 Hz + the time lost, within a period), so it never sends more than 151.
    summary = re.search(r"(\d+) commands at 30 Hz, .* (\d+) late periods \(([\d.]+) s lost\), (\d+) held", done.stdout)
    assert summary, done.stdout
    sent, late, lost, held = int(summary[1]), int(summary[2]), float(summary[3]), int(summary[4])
    assert 1 <= sent and sent + held <= 151 and late <= sent + held, done.stdout
    assert (sent + held) / 30 + lost >= 5.0 - 0.01, f"the runner stopped early: {done.stdout}"
    assert lost == 0.0 or late > 0, done.stdout
    # This probe, matched with the runner some time after it started (discovery takes longer on a
    # loaded machine), gets the later ones, each well-formed and inside the limits.
    received = commands.messages()
    assert 1 <= len(received) <= sent, f"{len(received)} of {sent} commands received"
    for msg in received:
        assert list(msg.name) == JOINTS and len(msg.position) == 6
        assert all(np.isfinite(msg.position)), msg.position
    positions = np.array([msg.position for msg in received])
    low, high = np.array(LIMITS).T
    assert np.all(positions >= low - 1e-9) and np.all(positions <= high + 1e-9), "a command outside the joint limits"

    # Unchanged against the physical arm's driver (on the servo-bus emulator) and its cameras
    # (so101_camera_node serving two fake cameras, their JPEG frames): the arm follows the policy.
    # The sim goes first, so the driver alone answers on /joint_states and /joint_commands; the
    # cube's pose the policy takes comes from a stand-in for a cube tracker, where the expert left it.
    assert sim.stop() == 0, sim.log_tail()
    tracker = ros.publisher("/cube/pose", PoseStamped, reliable_qos(10), wait_for_subscriber=None)
    tracking = threading.Event()

    def track() -> None:
        while not tracking.wait(1 / 30):
            cube.header.stamp = ros.node.get_clock().now().to_msg()
            tracker.publish(cube)

    threading.Thread(target=track, daemon=True).start()
    arm, _emulator = arm_factory()
    cameras = SimNode(
        node_binary("so101_camera_node"),
        ["--camera", "top=fake:64x48@30", "--camera", "wrist=fake:yuyv,64x48@30"],
        tmp_path / "camera_node.log",
    )
    states = ros.subscribe("/joint_states", JointState, best_effort_qos())
    first = states.next_message(20.0, arm)
    before = np.array([dict(zip(first.name, first.position))[j] for j in JOINTS])
    done = run(
        [
            VENV_BIN / "so101-run-policy",
            checkpoint,
            "--duration",
            "3",
            "--compressed",
        ],
        timeout=120,
    )
    tracking.set()
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    arm.assert_alive()
    cameras.assert_alive()
    assert cameras.stop() == 0, cameras.log_tail()
    after = np.array([dict(zip(states.latest().name, states.latest().position))[j] for j in JOINTS])
    assert np.abs(after - before).max() > 0.05, f"the driven arm did not move: {before} -> {after}"

    # A missing camera: the runner says which and exits; the sim is unharmed.
    partial = sim_factory("--cameras", "top:64x48", "--namespace", "partial")
    done = run(
        [VENV_BIN / "so101-run-policy", checkpoint, "--namespace", "partial", "--duration", "1", "--startup-timeout", "3"],
        # As the run above: the runner's start (torch, LeRobot, the policy) took 19 s of a bad path
        # alone beside two busy loops, and more beside another test's training.
        timeout=120,
    )
    assert done.returncode != 0 and "camera wrist" in done.stderr, done.stdout + done.stderr
    partial.assert_alive()


def test_the_runner_reports_a_policy_it_cannot_load(tmp_path):
    done = run([VENV_BIN / "so101-run-policy", tmp_path / "no_such_policy", "--duration", "1"], timeout=120)
    assert done.returncode != 0
    assert "cannot load a LeRobot policy" in done.stderr and "Traceback" not in done.stderr, done.stderr[-2000:]


def test_the_runner_replaces_a_participant_blind_to_the_arm_s_node(sim_factory, monkeypatch, caplog):
    """Fast DDS can miss a starting node's publications for good (so101.stack.discovery): the live
    runner's node then starts over on a fresh participant. The blindness is made here: its first
    participant opens in another ROS domain than the sim's."""
    from so101.evaluate.run_policy import LiveNode

    sim = sim_factory("--cameras", "top:64x48", "--namespace", "blind")
    node_domain = os.environ.get("ROS_DOMAIN_ID", "0")
    monkeypatch.setenv("ROS_DOMAIN_ID", blind_domain())
    live = LiveNode("/blind", {"top": "/blind/camera/top/image_raw"}, cube_pose=True)
    monkeypatch.setenv("ROS_DOMAIN_ID", node_domain)
    try:
        assert live.wait_for_inputs(["top"], max_age=1.0, timeout=20.0), live.inputs.stale(["top"], 1.0)
        assert "no publisher of /blind/joint_states" in caplog.text and "starting a fresh DDS participant" in caplog.text
        sim.assert_alive()
    finally:
        live.close()
