#!/usr/bin/env python3
"""Recording size and image fidelity, and conversion at scale (docs/benchmarks.md, "Data at scale").

1. Recording: for each JPEG quality, so101_sim_node (meshes unless --lite; top, front, wrist at
   --size and 30 Hz; --speed 4 as so101-launch runs the expert; --jpeg --jpeg-quality Q) with the
   scripted expert, and two recorder_nodes on the same episodes: recorder_node's default set (raw
   sensor_msgs/Image) and so101-launch's default (so101.stack.launch_plan.COMPRESSED_RECORDING: the cameras'
   image_raw/compressed). Per layout, MB of bag per second of robot time (bag bytes over the sim-time
   span of /joint_states); per quality, the PSNR of every JPEG frame against the raw frame of the same
   camera and stamp (the raw render): over all frames (from the mean squared error) and the worst frame.
2. Conversion: so101-bag-to-lerobot (this checkout's, default options: AV1 videos) on the raw bags
   and on the compressed bags of --quality, each in a child process: frames/s and their ratio, peak RSS.
3. A long episode: one compressed episode of --quality repeated to --long-minutes (stamps and
   receive times shifted; the sim's own JPEG frames), converted: peak RSS. With --converter-src, that
   converter (e.g. the previous one, `git archive` of an older commit) and this one also convert the
   raw episode repeated to --old-seconds lengths, for the peak RSS of a converter that loads a whole
   episode.

Peak memory (psutil, sampled every 0.1 s or so): the converter process's RSS, and over its process
tree (LeRobot encodes each camera's video in a forked child) the sum of RSS, which counts pages the
children share with the converter again, and of PSS, which counts them once. Opens DDS participants: run inside a private network
namespace (scripts/bench.sh storage does). Prints a Markdown report; --json keeps the numbers.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from so101 import contract
from so101.bench import common as bench_common
from so101.messages import stamp_seconds
from so101.stack.launch_plan import COMPRESSED_RECORDING, DEFAULT_JPEG_QUALITY
from so101.subcommands import Subcommand, run_alone

CAMERAS = contract.CAMERA_NAMES
FIRST_EPISODE = f"{contract.EPISODE_DEFAULT_PREFIX}_{0:06d}"  # the recorder's first bag directory


def record(bin_dir: Path, work: Path, quality: int, episodes: int, size: str, lite: bool) -> float:
    """Records `episodes` expert episodes into work/raw and work/compressed; returns the wall seconds."""
    env = bench_common.node_env("warn", keep_callers_level=True)
    sim_args = [
        "--speed",
        "4",
        "--seed",
        "1",
        "--cameras",
        ",".join(CAMERAS),
        "--camera-size",
        size,
        "--camera-rate",
        f"{contract.CONTROL_RATE:g}",
    ]
    sim_args += ["--jpeg", "--jpeg-quality", str(quality)] + (["--lite"] if lite else [])
    compressed = [arg for pattern in COMPRESSED_RECORDING for arg in ("--regex", pattern)]
    started = time.monotonic()
    nodes = [subprocess.Popen([str(bin_dir / "so101_sim_node"), *sim_args], env=env, stderr=subprocess.DEVNULL)]
    for name, extra in (("raw", []), ("compressed", compressed)):
        command = [str(bin_dir / "recorder_node"), "--output", str(work / name), *extra]
        nodes.append(subprocess.Popen(command, env=env, stderr=subprocess.DEVNULL))
    try:
        time.sleep(2.0)  # both recorders subscribed to /episode/events
        subprocess.run(
            [str(bin_dir / "teleop_node"), "--source", "expert", "--sim-time", "--episodes", str(episodes), "--seed", "1"],
            env=env,
            check=True,
            stderr=subprocess.DEVNULL,
            timeout=120 * episodes + 120,
        )
        time.sleep(1.0)
    finally:
        for node in reversed(nodes):
            node.send_signal(2)
            node.wait(timeout=60)
    return time.monotonic() - started


def messages(episode: Path, topics: set[str] | None = None):
    """(topic, decoded ROS message) of an episode bag, in log-time order."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    for file in sorted(episode.glob("*.mcap")):
        with open(file, "rb") as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            for _schema, channel, _message, ros in reader.iter_decoded_messages(topics=topics):
                yield channel.topic, ros


def robot_seconds(episode: Path) -> float:
    """The sim-time span of the episode's /joint_states plus one period."""
    stamps = [stamp_seconds(ros) for _, ros in messages(episode, {"/" + contract.JOINT_STATES})]
    return max(stamps) - min(stamps) + float(np.median(np.diff(stamps)))


def bag_bytes(episode: Path) -> int:
    return sum(f.stat().st_size for f in episode.iterdir() if f.is_file())


def episodes_in(bags: Path) -> list[Path]:
    return sorted(d for d in bags.glob(f"{contract.EPISODE_DEFAULT_PREFIX}_*") if (d / contract.EPISODE_METADATA_FILE).is_file())


def psnr(raw_episode: Path, compressed_episode: Path) -> dict:
    """Squared errors of every compressed frame against the raw frame of the same camera and stamp."""
    from so101.messages import rgb_image

    raw_topics = {"/" + contract.camera_topic(c) for c in CAMERAS}
    raw = {(topic.split("/")[2], round(stamp_seconds(ros), 6)): ros for topic, ros in messages(raw_episode, raw_topics)}
    errors: list[float] = []
    jpeg_bytes: list[int] = []
    for topic, ros in messages(compressed_episode, {"/" + contract.camera_topic(c, contract.IMAGE_COMPRESSED) for c in CAMERAS}):
        reference = raw.pop((topic.split("/")[2], round(stamp_seconds(ros), 6)), None)
        if reference is None:
            continue  # a frame one recorder missed
        difference = rgb_image(ros).astype(np.float64) - rgb_image(reference)
        errors.append(float(np.mean(difference**2)))
        jpeg_bytes.append(len(ros.data))
    return {"mse": errors, "jpeg_bytes": jpeg_bytes}


def decibels(mse: float) -> float:
    return float("inf") if mse == 0 else 10 * np.log10(255.0**2 / mse)


def convert(bags: Path, output: Path, pythonpath: str | None = None) -> dict:
    """so101-bag-to-lerobot (default options, its dataset check included) in a child process:
    conversion seconds, wall seconds, frames, peak RSS."""
    import psutil

    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    command = [sys.executable, "-m", "so101.dataset.convert", str(bags), "--output", str(output), "--quiet"]
    started = time.monotonic()
    child = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    process = psutil.Process(child.pid)
    peak = {"own": 0, "tree": 0, "tree_pss": 0}
    while child.poll() is None:
        time.sleep(0.1)
        try:
            tree = [process, *process.children(recursive=True)]
            rss = [p.memory_info().rss for p in tree]
            # PSS: shared pages (the encoder processes are forks of the converter) counted once.
            pss = sum(p.memory_full_info().pss for p in tree)
        except psutil.Error:
            continue
        peak = {"own": max(peak["own"], rss[0]), "tree": max(peak["tree"], sum(rss)), "tree_pss": max(peak["tree_pss"], pss)}
    wall = time.monotonic() - started
    summary = child.stdout.read()
    if child.returncode != 0 or "; 0 skipped" not in summary:
        raise RuntimeError(f"the conversion of {bags} failed: {summary}")
    # "N episode(s) (...), F frames at 30 fps -> DIR (S s, R frames/s); 0 skipped": the conversion's
    # own time (reading, writing, encoding; not the interpreter's start nor the dataset check after).
    frames = int(summary.split(" frames at ")[0].rsplit(" ", 1)[1])
    seconds = float(summary.split(" frames/s)")[0].rsplit("(", 1)[1].split(" s, ")[0])
    return {
        "seconds": seconds,
        "wall_s": wall,
        "frames": frames,
        "peak_rss_mb": peak["own"] / 1e6,
        "peak_tree_rss_mb": peak["tree"] / 1e6,
        "peak_tree_pss_mb": peak["tree_pss"] / 1e6,
    }


def starts_with_header(schema: bytes) -> bool:
    """A ros2msg schema whose first field is the std_msgs/Header (comments and blank lines aside)."""
    fields = [line.strip() for line in schema.decode().splitlines() if line.strip() and not line.strip().startswith("#")]
    return bool(fields) and fields[0].split() == ["std_msgs/Header", "header"]


def repeat_episode(source: Path, target: Path, seconds: float) -> float:
    """Writes target/ as `source` repeated until it spans `seconds` of sim time: every message again
    and again with its receive time and header stamp shifted by the source's span (the
    CDR header's stamp is patched in place: the sim's own payloads, JPEG frames included). Returns
    the robot seconds written."""
    from mcap.reader import make_reader
    from mcap.well_known import MessageEncoding, SchemaEncoding
    from mcap.writer import CompressionType, Writer

    span = robot_seconds(source)
    (file,) = sorted(source.glob("*.mcap"))
    with open(file, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        log_times = [m.log_time for _, _, m in reader.iter_messages()]
    wall_span = max(log_times) - min(log_times) + int(0.01e9)
    repeats = int(np.ceil(seconds / span))
    target.mkdir(parents=True)
    name = f"{target.name}_0.mcap"
    count = 0
    with open(target / name, "wb") as out, open(file, "rb") as stream:
        writer = Writer(out, compression=CompressionType.NONE)
        writer.start(profile="ros2", library="so101.bench.storage")
        schemas = {sid: writer.register_schema(x.name, SchemaEncoding.ROS2, x.data) for sid, x in summary.schemas.items()}
        channels = {
            cid: writer.register_channel(c.topic, MessageEncoding.CDR, schemas.get(c.schema_id, 0), c.metadata)
            for cid, c in summary.channels.items()
        }
        stamped = {
            cid for cid, c in summary.channels.items() if c.schema_id and starts_with_header(summary.schemas[c.schema_id].data)
        }
        reader = make_reader(stream)
        for k in range(repeats):
            shift = int(round(k * span * 1e9))
            for _schema, channel, message in reader.iter_messages():
                data = message.data
                if channel.id in stamped and k:
                    data = bytearray(data)
                    order = "little" if data[1] == 1 else "big"
                    total = int.from_bytes(data[4:8], order, signed=True) * 10**9 + int.from_bytes(data[8:12], order) + shift
                    data[4:8] = (total // 10**9).to_bytes(4, order, signed=True)
                    data[8:12] = (total % 10**9).to_bytes(4, order)
                    data = bytes(data)
                time_ = message.log_time + k * wall_span
                writer.add_message(channels[channel.id], time_, data, time_, message.sequence)
                count += 1
        writer.finish()
    info = yaml.safe_load((source / contract.EPISODE_METADATA_FILE).read_text())
    bag = info["rosbag2_bagfile_information"]
    bag["relative_file_paths"] = [name]
    bag["message_count"] = count
    bag["duration"] = {"nanoseconds": repeats * wall_span}
    bag["files"] = [{"path": name, "starting_time": bag["starting_time"], "duration": bag["duration"], "message_count": count}]
    (target / contract.EPISODE_METADATA_FILE).write_text(yaml.safe_dump(info, sort_keys=False))
    return repeats * span


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--bin-dir", type=Path, required=True)
    parser.add_argument("--qualities", default="90,95,98,100", help="JPEG qualities to record, comma-separated")
    parser.add_argument("--quality", type=int, default=DEFAULT_JPEG_QUALITY, help="the one converted (so101-launch's default)")
    parser.add_argument("--episodes", type=int, default=2, help="expert episodes per quality")
    parser.add_argument("--size", default="640x480", help="camera size (the default cameras')")
    parser.add_argument("--lite", action="store_true", help="render without meshes (the main job renders them)")
    parser.add_argument("--long-minutes", type=float, default=10.0, help="length of the long episode (0: none)")
    parser.add_argument("--converter-src", default=None, help="another converter's python/src, e.g. the previous one's")
    parser.add_argument("--old-seconds", default="30,60", help="with --converter-src: raw episode lengths it converts")
    parser.add_argument("--workdir", type=Path, default=None, help="where the bags go (default: a temporary directory)")
    parser.add_argument("--json", type=Path, default=None)


def run(args: argparse.Namespace) -> int:
    qualities = [int(q) for q in args.qualities.split(",")]
    if args.quality not in qualities:
        qualities.append(args.quality)
    work = Path(tempfile.mkdtemp(prefix="so101_storage_", dir=args.workdir))
    results: dict = {"qualities": {}, "conversion": {}, "long": {}, "whole_episode": {}}
    try:
        for quality in qualities:
            run = work / f"q{quality}"
            wall = record(args.bin_dir, run, quality, args.episodes, args.size, args.lite)
            raw, compressed = episodes_in(run / "raw"), episodes_in(run / "compressed")
            if len(raw) != args.episodes or len(compressed) != args.episodes:
                raise RuntimeError(f"quality {quality}: {len(raw)} raw and {len(compressed)} compressed episodes recorded")
            seconds = [robot_seconds(e) for e in raw]
            errors = [psnr(r, c) for r, c in zip(raw, compressed)]
            mse = [m for e in errors for m in e["mse"]]
            results["qualities"][quality] = {
                "record_wall_s": wall,
                "robot_s": sum(seconds),
                "raw_mb": sum(bag_bytes(e) for e in raw) / 1e6,
                "compressed_mb": sum(bag_bytes(e) for e in compressed) / 1e6,
                "compressed_mb_per_s_each": [bag_bytes(e) / 1e6 / s for e, s in zip(compressed, seconds)],
                "frames_compared": len(mse),
                "psnr_db": decibels(float(np.mean(mse))),
                "worst_frame_psnr_db": decibels(max(mse)),
                "mean_jpeg_kb": float(np.mean([b for e in errors for b in e["jpeg_bytes"]])) / 1e3,
            }
            print(f"quality {quality}: {results['qualities'][quality]}", file=sys.stderr)
            if quality != args.quality:
                shutil.rmtree(run)
        run = work / f"q{args.quality}"
        for layout in ("raw", "compressed"):
            results["conversion"][layout] = convert(run / layout, work / f"dataset_{layout}")
            shutil.rmtree(work / f"dataset_{layout}")
            print(f"conversion of the {layout} bags: {results['conversion'][layout]}", file=sys.stderr)
        if args.long_minutes > 0:
            long_bags = work / "long"
            robot_s = repeat_episode(episodes_in(run / "compressed")[0], long_bags / FIRST_EPISODE, args.long_minutes * 60)
            result = convert(long_bags, work / "dataset_long")
            result.update(robot_s=robot_s, bag_mb=bag_bytes(long_bags / FIRST_EPISODE) / 1e6)
            results["long"] = result
            print(f"long episode: {result}", file=sys.stderr)
            shutil.rmtree(long_bags)
            shutil.rmtree(work / "dataset_long")
        if args.converter_src:
            for seconds in (float(s) for s in args.old_seconds.split(",")):
                bags = work / f"raw_{seconds:.0f}s"
                robot_s = repeat_episode(episodes_in(run / "raw")[0], bags / FIRST_EPISODE, seconds)
                entry = {"robot_s": robot_s}
                for label, source in (("other", args.converter_src), ("this", None)):
                    entry[label] = convert(bags, work / "dataset_whole", pythonpath=source)
                    shutil.rmtree(work / "dataset_whole")
                results["whole_episode"][f"{seconds:.0f}"] = entry
                print(f"raw episode of {robot_s:.0f} s: {entry}", file=sys.stderr)
                shutil.rmtree(bags)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return bench_common.report(report_lines(results, args), results, args.json)


def report_lines(results: dict, args) -> list[str]:
    lines = [
        f"Recording ({args.episodes} expert episodes per quality, three {args.size} cameras at 30 Hz, "
        f"{'lite' if args.lite else 'meshes'}, --speed 4):",
        "",
        "| JPEG quality | robot s | raw MB/s | compressed MB/s (each episode) | ratio raw/compressed | PSNR dB (worst frame) | mean JPEG kB | record wall s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for quality, r in results["qualities"].items():
        each = ", ".join(f"{x:.2f}" for x in r["compressed_mb_per_s_each"])
        lines.append(
            f"| {quality} | {r['robot_s']:.1f} | {r['raw_mb'] / r['robot_s']:.1f} | **{r['compressed_mb'] / r['robot_s']:.2f}** ({each}) | "
            f"{r['raw_mb'] / r['compressed_mb']:.1f} | **{r['psnr_db']:.1f}** ({r['worst_frame_psnr_db']:.1f}) | "
            f"{r['mean_jpeg_kb']:.1f} | {r['record_wall_s']:.0f} |"
        )
    raw, compressed = results["conversion"]["raw"], results["conversion"]["compressed"]
    lines += [
        "",
        f"Conversion of the quality-{args.quality} run's bags (the same episodes), so101-bag-to-lerobot with its defaults:",
        "",
        "| bags | frames | s | frames/s | peak RSS MB: converter (process tree RSS, PSS) |",
        "|---|---|---|---|---|",
    ]
    for label, r in (("raw", raw), ("compressed", compressed)):
        lines.append(
            f"| {label} | {r['frames']} | {r['seconds']:.1f} | **{r['frames'] / r['seconds']:.1f}** | "
            f"{r['peak_rss_mb']:.0f} ({r['peak_tree_rss_mb']:.0f}, {r['peak_tree_pss_mb']:.0f}) |"
        )
    ratio = (compressed["frames"] / compressed["seconds"]) / (raw["frames"] / raw["seconds"])
    lines.append(f"\nframes/s compressed / raw: **{ratio:.2f}**")
    if results["long"]:
        r = results["long"]
        lines += [
            "",
            f"Long episode: {r['robot_s'] / 60:.1f} min of robot time ({r['bag_mb']:.0f} MB of compressed bag), {r['frames']} frames "
            f"in {r['seconds']:.0f} s ({r['frames'] / r['seconds']:.1f} frames/s): peak RSS **{r['peak_rss_mb']:.0f} MB** "
            f"(process tree: RSS {r['peak_tree_rss_mb']:.0f} MB, PSS {r['peak_tree_pss_mb']:.0f} MB)",
        ]
    if results["whole_episode"]:
        lines += [
            "",
            "| raw episode | converter | frames | peak RSS MB: converter (process tree RSS, PSS) |",
            "|---|---|---|---|",
        ]
        for entry in results["whole_episode"].values():
            for label in ("other", "this"):
                r = entry[label]
                name = args.converter_src if label == "other" else "this checkout"
                lines.append(
                    f"| {entry['robot_s']:.1f} s | {name} | {r['frames']} | "
                    f"{r['peak_rss_mb']:.0f} ({r['peak_tree_rss_mb']:.0f}, {r['peak_tree_pss_mb']:.0f}) |"
                )
    return lines


SUBCOMMAND = Subcommand("recording size, image fidelity and conversion at scale", add_arguments, run, __doc__)


def main(argv: list[str] | None = None) -> int:
    return run_alone("so101-bench storage", SUBCOMMAND, argv)


if __name__ == "__main__":
    sys.exit(main())
