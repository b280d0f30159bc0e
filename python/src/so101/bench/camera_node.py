#!/usr/bin/env python3
"""Real-camera benchmark of so101_camera_node (issue 29), served by its fake camera at 640x480@30
MJPEG, textured so its JPEGs are as large as a webcam's (about 54 kB; the fake encodes each of its 32 pictures once, so serving a frame costs a copy and the
node's own work is what is measured; a V4L2 camera adds the kernel's USB and mmap work, which no
node can avoid):

1. CPU per camera in MJPEG passthrough (one Rust subscriber), as % of one core, from the node's
   /proc CPU time over the measured window;
2. the same with --raw (every frame decoded to rgb8 with zune-jpeg and published), against
   decoding the same JPEGs with OpenCV's cv2.imdecode in this process, in the same run: the node's
   added CPU per frame against OpenCV's time per frame, as a ratio (> 1: the node decodes and
   publishes faster than OpenCV alone decodes);
3. capture-to-subscriber latency p50/p99 for a Rust subscriber (camera_latency_probe) and an rclpy
   one (the instant a frame arrives minus its stamp, the capture instant);
4. three cameras at 640x480@30 + so101_feetech_driver at --rate max on the servo-bus emulator
   (realistic wire timing) + recorder_node recording the JPEG topics: frames lost by the stack
   (every camera's stamps in the bag one frame period apart, the recorder's dropped count), and
   each process's CPU.

Must run inside one private network namespace (scripts/bench.sh does that). Prints a Markdown
report on stdout and writes the raw numbers as JSON to --json.
"""

from __future__ import annotations

import argparse
import json
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from so101 import contract
from so101.bench import common as bench_common
from so101.bench.latency import percentile
from so101.bench.recorder import cpu_seconds
from so101.paths import asset
from so101.stack import process
from so101.subcommands import Subcommand, run_alone

CAMERA = "fake:640x480@30,textured"  # JPEGs of about 54 kB, as a webcam's
FPS = 30.0

# An rclpy subscriber of camera/top/image_raw/compressed: prints its latencies (ms) as JSON at
# SIGINT and keeps the first 32 JPEGs it got in the directory argv[1] (the anchor decodes them).
RCLPY_PROBE = """
import json, sys, time
from pathlib import Path
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from sensor_msgs.msg import CompressedImage
keep = Path(sys.argv[1])
rclpy.init()
node = Node('bench_rclpy_camera_probe')
latencies = []
def got(message):
    now = time.time()
    latencies.append((now - (message.header.stamp.sec + message.header.stamp.nanosec * 1e-9)) * 1e3)
    if len(latencies) <= 32:
        (keep / f'{len(latencies):02d}.jpg').write_bytes(bytes(message.data))
node.create_subscription(CompressedImage, '/camera/top/image_raw/compressed', got, 10)
try:
    rclpy.spin(node)
except (KeyboardInterrupt, ExternalShutdownException):
    pass
print(json.dumps(latencies))
"""


def start_node(bin_dir: Path, cameras: list[str], log: Path, extra: list[str] = ()) -> subprocess.Popen:
    """so101_camera_node, its output into `log`. Not a pipe: a pipe nobody reads fills, and a node
    blocked writing a log line stops publishing (the first version of this benchmark saw the
    recorder's frames stop after 6.6 s that way)."""
    argv = [str(bin_dir / "so101_camera_node")]
    for camera in cameras:
        argv += ["--camera", camera]
    with open(log, "w") as out:
        return subprocess.Popen(
            [*argv, *extra], env=bench_common.node_env("warn,rustdds=error"), stdout=out, stderr=subprocess.STDOUT
        )


def stop(proc: subprocess.Popen, what: str, log: Path | None = None) -> str:
    """SIGINT, then the process's output (from `log` where it went there)."""
    out, err = process.interrupt_and_collect(proc, timeout=30)
    text = log.read_text(errors="replace") if log is not None else (out or "") + (err or "")
    if proc.returncode != 0:
        raise RuntimeError(f"{what} exited with {proc.returncode}: {text[-2000:]}")
    return text


def node_cpu(bin_dir: Path, extra: list[str], seconds: float, warmup: float, work: Path) -> dict:
    """One camera, one Rust subscriber (latency too): the node's CPU over `seconds`."""
    log = work / "camera_node.log"
    node = start_node(bin_dir, [f"top={CAMERA}"], log, extra)
    probe = subprocess.Popen(
        [str(bin_dir / "camera_latency_probe"), "--seconds", str(seconds + warmup)],
        env=bench_common.node_env("warn,rustdds=error"),
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        time.sleep(warmup)
        before, begun = cpu_seconds(node.pid), time.monotonic()
        time.sleep(seconds)
        cpu, wall = cpu_seconds(node.pid) - before, time.monotonic() - begun
        out, _ = probe.communicate(timeout=90)
    finally:
        if probe.poll() is None:
            probe.kill()
        summary = summary_lines(stop(node, "so101_camera_node", log))
    return {"cpu_percent": 100 * cpu / wall, "rust_subscriber": json.loads(out.strip().splitlines()[-1]), "summary": summary}


def summary_lines(output: str) -> list[str]:
    """The node's closing line per camera."""
    return [line for line in output.splitlines() if " frames in " in line and "INFO" not in line]


def rclpy_latency(bin_dir: Path, seconds: float, warmup: float, keep: Path, work: Path) -> list[float]:
    log = work / "camera_node.log"
    node = start_node(bin_dir, [f"top={CAMERA}"], log)
    probe = subprocess.Popen([sys.executable, "-c", RCLPY_PROBE, str(keep)], stdout=subprocess.PIPE, text=True)
    try:
        time.sleep(seconds + warmup)
    finally:
        probe.send_signal(signal.SIGINT)
        out, _ = probe.communicate(timeout=30)
        stop(node, "so101_camera_node", log)
    latencies = json.loads(out.strip().splitlines()[-1])
    return latencies[int(warmup * FPS) :]


def opencv_ms_per_frame(jpegs: list[bytes], rounds: int) -> float:
    import cv2
    import numpy as np

    buffers = [np.frombuffer(jpeg, dtype=np.uint8) for jpeg in jpegs]
    for buffer in buffers:
        cv2.imdecode(buffer, cv2.IMREAD_COLOR)
    begun = time.process_time()
    for _ in range(rounds):
        for buffer in buffers:
            cv2.imdecode(buffer, cv2.IMREAD_COLOR)
    return (time.process_time() - begun) * 1e3 / (rounds * len(buffers))


def full_load(bin_dir: Path, seconds: float, work: Path) -> dict:
    """Three cameras + the driver at full rate + the recorder, `seconds` recorded."""
    import yaml

    env = bench_common.node_env("warn,rustdds=error")
    link = work / "bus"
    calibration = asset("emulated_arm/so101_calibration.json")
    emulator = subprocess.Popen(
        [
            str(bin_dir / "so101_servo_emulator"),
            *("--link", str(link), "--calibration", str(calibration)),
            *("--timing", "realistic", "--baud", "1000000"),
        ],
        env=env,
        stdin=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 20
    while not link.exists() and time.monotonic() < deadline:
        time.sleep(0.1)
    driver_log, recorder_log = work / "driver.log", work / "recorder.log"
    with open(driver_log, "w") as out:
        driver = subprocess.Popen(
            [str(bin_dir / "so101_feetech_driver"), "--port", str(link), "--calibration", str(calibration), "--rate", "max"],
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    camera_log = work / "camera_node.log"
    cameras = start_node(bin_dir, [f"{name}={CAMERA}" for name in ("top", "front", "wrist")], camera_log)
    bags = work / "bags"
    recorder_argv = [str(bin_dir / "recorder_node"), "--output", str(bags)]
    for pattern in ("joint_states", f"{contract.CAMERA_PREFIX}/[^/]+/{contract.IMAGE_COMPRESSED}"):
        recorder_argv += ["--regex", pattern]
    time.sleep(3.0)  # every peer discovered before the episode starts
    with open(recorder_log, "w") as out:
        recorder = subprocess.Popen([*recorder_argv, "--start"], env=env, stdout=out, stderr=subprocess.STDOUT)
    processes = {"so101_camera_node": cameras, "so101_feetech_driver": driver, "recorder_node": recorder}
    try:
        time.sleep(2.0)
        before = {name: cpu_seconds(p.pid) for name, p in processes.items()}
        begun = time.monotonic()
        time.sleep(seconds)
        wall = time.monotonic() - begun
        cpu = {name: 100 * (cpu_seconds(p.pid) - before[name]) / wall for name, p in processes.items()}
    finally:
        stop(recorder, "recorder_node", recorder_log)
        summary = summary_lines(stop(cameras, "so101_camera_node", camera_log))
        stop(driver, "so101_feetech_driver", driver_log)
        emulator.stdin.close()
        emulator.wait(timeout=30)
    episode = sorted(bags.glob(f"{contract.EPISODE_DEFAULT_PREFIX}_*"))[-1]
    meta = yaml.safe_load((episode / contract.EPISODE_METADATA_FILE).read_text())["rosbag2_bagfile_information"]
    counts = {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]}
    return {
        "cpu_percent": cpu,
        "recorded": counts,
        "recorder_dropped": int(meta["custom_data"]["dropped_messages"]),
        "gaps": stamp_gaps(episode),
        "camera_summary": summary,
        "episode_seconds": meta["duration"]["nanoseconds"] * 1e-9,
    }


def stamp_gaps(episode: Path) -> dict[str, int]:
    """Per camera topic: frames missing between the first and last frame in the bag (a stamp step
    longer than 1.5 frame periods counts the frames it skips)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    stamps: dict[str, list[float]] = {}
    for path in sorted(episode.glob("*.mcap")):
        with open(path, "rb") as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            for _, channel, _, message in reader.iter_decoded_messages(topics=None):
                if channel.topic.endswith(contract.IMAGE_COMPRESSED):
                    stamp = message.header.stamp
                    stamps.setdefault(channel.topic, []).append(stamp.sec + stamp.nanosec * 1e-9)
    gaps = {}
    for topic, values in stamps.items():
        values.sort()
        steps = [b - a for a, b in zip(values, values[1:])]
        gaps[topic] = sum(max(0, round(step * FPS) - 1) for step in steps if step > 1.5 / FPS)
    return gaps


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--bin-dir", type=Path, required=True)
    parser.add_argument("--seconds", type=float, default=20.0, help="measured seconds of each run")
    parser.add_argument("--warmup", type=float, default=3.0, help="seconds before each measurement")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each CPU measurement (medians)")
    parser.add_argument("--json", type=Path)


def run(args: argparse.Namespace) -> int:
    results: dict = {}
    work = Path(tempfile.mkdtemp(prefix="so101_bench_camera_node_"))
    try:
        runs: dict[str, list[dict]] = {"passthrough": [], "raw": []}
        for repeat in range(args.repeats):
            for mode, extra in (("passthrough", []), ("raw", ["--raw"])):
                print(f"[1/3] {mode}, run {repeat + 1} of {args.repeats} ...", file=sys.stderr, flush=True)
                runs[mode].append(node_cpu(args.bin_dir, extra, args.seconds, args.warmup, work))
        results["runs"] = runs
        keep = work / "jpegs"
        keep.mkdir()
        print("[2/3] rclpy latency, OpenCV anchor ...", file=sys.stderr, flush=True)
        rclpy = rclpy_latency(args.bin_dir, args.seconds, args.warmup, keep, work)
        jpegs = [path.read_bytes() for path in sorted(keep.glob("*.jpg"))]
        results["opencv_ms_per_frame"] = opencv_ms_per_frame(jpegs, rounds=10)
        results["jpeg_bytes"] = statistics.mean(len(jpeg) for jpeg in jpegs)
        ordered = sorted(rclpy)
        results["rclpy_latency_ms"] = {"frames": len(rclpy), "p50": percentile(ordered, 50), "p99": percentile(ordered, 99)}
        print("[3/3] three cameras + driver + recorder ...", file=sys.stderr, flush=True)
        results["full_load"] = full_load(args.bin_dir, args.seconds, work)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return bench_common.report(markdown(results, args), results, args.json)


def markdown(results: dict, args) -> list[str]:
    runs = results["runs"]
    passthrough = statistics.median(run["cpu_percent"] for run in runs["passthrough"])
    raw = statistics.median(run["cpu_percent"] for run in runs["raw"])
    node_decode_ms = (raw - passthrough) / 100 * 1e3 / FPS
    opencv_ms = results["opencv_ms_per_frame"]
    rust = [run["rust_subscriber"] for run in runs["passthrough"]]
    rclpy = results["rclpy_latency_ms"]
    load = results["full_load"]
    lines = [
        f"camera CPU per 640x480@30 MJPEG camera: {passthrough:.1f} % of a core",
        "",
        f"Medians of {args.repeats} runs of {args.seconds:g} s, one camera ({CAMERA}: JPEGs of "
        f"{results['jpeg_bytes'] / 1000:.0f} kB), one Rust subscriber.",
        "",
        "| measure | value | anchor | ratio |",
        "|---|---|---|---|",
        f"| CPU, MJPEG passthrough | {passthrough:.2f} % of a core | target < 3 % | - |",
        f"| CPU, with --raw (zune-jpeg to rgb8, published) | {raw:.2f} % of a core "
        f"({node_decode_ms:.2f} ms per frame over passthrough) | cv2.imdecode of the same JPEGs: {opencv_ms:.2f} ms per frame | "
        f"**{opencv_ms / node_decode_ms:.2f}x** (target >= 1.0) |",
        f"| latency capture -> Rust subscriber, p50 / p99 | {statistics.median(r['p50_ms'] for r in rust):.2f} / "
        f"{statistics.median(r['p99_ms'] for r in rust):.2f} ms | - | - |",
        f"| latency capture -> rclpy subscriber, p50 / p99 | {rclpy['p50']:.2f} / {rclpy['p99']:.2f} ms "
        f"({rclpy['frames']} frames) | - | - |",
        "",
        f"Three cameras at 640x480@30 + so101_feetech_driver --rate max (emulator, realistic wire) + recorder_node "
        f"(JPEG topics and /joint_states), {load['episode_seconds']:.1f} s recorded:",
        "",
        "| camera topic | frames recorded | episode length x 30 fps | frames missing between stamps |",
        "|---|---|---|---|",
    ]
    for topic, missing in sorted(load["gaps"].items()):
        lines.append(f"| {topic} | {load['recorded'].get(topic, 0)} | {load['episode_seconds'] * FPS:.0f} | {missing} |")
    cpu = ", ".join(f"{name} {value:.1f} %" for name, value in load["cpu_percent"].items())
    lines += [
        "",
        f"Recorder dropped: {load['recorder_dropped']}; /joint_states recorded: {load['recorded'].get('/joint_states', 0)}. "
        f"CPU (of one core): {cpu}.",
    ]
    return lines


SUBCOMMAND = Subcommand("so101_camera_node's CPU, latency and full load on its fake 640x480 camera", add_arguments, run, __doc__)


def main(argv: list[str] | None = None) -> int:
    return run_alone("so101-bench camera_node", SUBCOMMAND, argv)


if __name__ == "__main__":
    sys.exit(main())
