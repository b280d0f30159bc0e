#!/usr/bin/env python3
"""Benchmark of recorder_node (docs/benchmarks.md), all in one run on one disk.

1. The reference load (so101_load_publisher's defaults): two 640x480 rgb8 cameras at 30 Hz + joint states at 500 Hz
   (so101_load_publisher) recorded by recorder_node: every message kept? recorder CPU.
2. Sustained: the two cameras at rising rates (joint states at 500 Hz): the highest rate the
   recorder keeps every message of, end to end (DDS receive + MCAP), in MB/s and messages/s.
3. The writing side alone on the bag of (1): the recorder's BagWriter against a raw sequential
   write of the same message bytes (both by bag_write_bench, same process conditions) and against
   the Python mcap writer, each with fsync, as ratios.

Opens DDS participants: run inside a private network namespace (scripts/bench.sh recorder does).
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from so101 import contract
from so101.paths import node_environment
from so101.stack import process
from so101.subcommands import Subcommand, run_alone

CLOCK_TICKS = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS


def record(bin_dir: Path, out: Path, publisher_args: list[str]) -> dict:
    """Runs the recorder (--start) while the load publisher publishes; returns counts and times."""
    env = node_environment(rust_log="warn")
    recorder = subprocess.Popen(
        [str(bin_dir / "recorder_node"), "--output", str(out), "--start"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    time.sleep(0.5)
    cpu_before = cpu_seconds(recorder.pid)
    publisher = subprocess.run(
        [str(bin_dir / "so101_load_publisher"), *publisher_args],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    if publisher.returncode != 0:
        recorder.kill()
        raise RuntimeError(f"load publisher failed: {publisher.stderr[-2000:]}")
    published = json.loads(publisher.stdout.strip().splitlines()[-1])
    time.sleep(1.0)
    cpu = cpu_seconds(recorder.pid) - cpu_before
    _, stderr = process.interrupt_and_collect(recorder, timeout=60)
    if recorder.returncode != 0:
        raise RuntimeError(f"recorder failed: {stderr[-2000:]}")
    import yaml

    episode = sorted(glob.glob(str(out / f"{contract.EPISODE_DEFAULT_PREFIX}_*")))[-1]
    meta = yaml.safe_load(Path(episode, contract.EPISODE_METADATA_FILE).read_text())["rosbag2_bagfile_information"]
    counts = {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]}
    files = [Path(episode, f["path"]) for f in meta["files"]]
    return {
        "published": published["published"],
        "publish_seconds": published["seconds"],
        "recorded": counts,
        "dropped": int(meta["custom_data"]["dropped_messages"]),
        "recorder_cpu_seconds": cpu,
        "files": [str(f) for f in files],
        "file_bytes": sum(f.stat().st_size for f in files),
    }


def clean_page_cache() -> None:
    """Writes out and, where allowed (root), drops the page cache: on this kind of VM a page cache
    full of earlier runs' files makes writes several times slower, whoever writes."""
    os.sync()
    try:
        Path("/proc/sys/vm/drop_caches").write_text("3\n")
    except OSError:
        pass


def load_messages(path: str):
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        reader = make_reader(f)
        return [(schema, channel, message) for schema, channel, message in reader.iter_messages(log_time_order=False)]


def python_mcap_write(messages, path: Path, fsync: bool) -> float:
    from mcap.writer import CompressionType, Writer

    started = time.perf_counter()
    with open(path, "wb") as f:
        writer = Writer(f, chunk_size=1 << 20, compression=CompressionType.NONE)
        writer.start(profile="ros2", library="python mcap")
        schemas, channels = {}, {}
        for schema, channel, message in messages:
            if channel.id not in channels:
                if schema.id not in schemas:
                    schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
                channels[channel.id] = writer.register_channel(channel.topic, "cdr", schemas[schema.id], channel.metadata)
            writer.add_message(channels[channel.id], message.log_time, message.data, message.publish_time, message.sequence)
        writer.finish()
        f.flush()
        if fsync:
            os.fsync(f.fileno())
    return time.perf_counter() - started


def rust_write(bin_dir: Path, bag: str, out: Path, mode: str, fsync: bool) -> float:
    """The recorder's BagWriter (mode bag) or a plain sequential write of the same bytes (raw),
    both from the same Rust program under the same conditions."""
    done = subprocess.run(
        [str(bin_dir / "bag_write_bench"), "--input", bag, "--output", str(out), "--mode", mode]
        + ([] if fsync else ["--no-fsync"]),
        capture_output=True,
        text=True,
        timeout=600,
    )
    if done.returncode != 0:
        raise RuntimeError(done.stderr)
    return json.loads(done.stdout)["seconds"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--bin-dir", type=Path, required=True)
    parser.add_argument("--seconds", type=float, default=10.0, help="publishing time of the reference-load recording")
    parser.add_argument("--sweep-seconds", type=float, default=4.0, help="publishing time of each sweep step")
    parser.add_argument("--rates", default="30,60,90,120,180,240", help="camera rates (Hz) of the sweep")
    parser.add_argument("--repeats", type=int, default=3, help="repeats of the writer comparison (medians)")
    parser.add_argument("--workdir", type=Path, default=None, help="where bags go (default: a temporary directory)")
    parser.add_argument("--json", type=Path)


def run(args: argparse.Namespace) -> int:
    work = Path(tempfile.mkdtemp(prefix="so101_bench_recorder_", dir=args.workdir))
    results: dict = {}
    try:
        print("[1/3] the reference load ...", file=sys.stderr, flush=True)
        load = record(args.bin_dir, work / "load", ["--duration", str(args.seconds)])
        results["stack_load"] = load

        sweep = []
        for rate in [float(r) for r in args.rates.split(",")]:
            print(f"[2/3] sustained: cameras at {rate:g} Hz ...", file=sys.stderr, flush=True)
            step = record(
                args.bin_dir, work / f"rate{rate:g}", ["--duration", str(args.sweep_seconds), "--camera-rate", str(rate)]
            )
            step["camera_rate"] = rate
            step["missing"] = sum(step["published"][t] - step["recorded"].get(t, 0) for t in step["published"])
            sweep.append(step)
            shutil.rmtree(work / f"rate{rate:g}")
            if step["missing"] > 0:
                break
        results["sweep"] = sweep

        print("[3/3] writers on the same messages ...", file=sys.stderr, flush=True)
        bag = load["files"][0]
        messages = load_messages(bag)
        total_bytes = sum(len(m.data) for _, _, m in messages)
        results["writers"] = {"messages": len(messages), "bytes": total_bytes}
        for durable in (False, True):
            times = {"raw": [], "recorder_bag_writer": [], "python_mcap": []}
            writers = {
                "raw": lambda r: rust_write(args.bin_dir, bag, work / f"raw{r}", "raw", durable),
                "recorder_bag_writer": lambda r: rust_write(args.bin_dir, bag, work / f"rust{r}", "bag", durable),
                "python_mcap": lambda r: python_mcap_write(messages, work / f"py{r}.mcap", durable),
            }
            order = list(writers)
            for repeat in range(args.repeats):
                # Each writer starts from a clean page cache (no one else's dirty pages in its
                # fsync), in a rotating order.
                for name in order[repeat % 3 :] + order[: repeat % 3]:
                    clean_page_cache()
                    time.sleep(0.5)
                    times[name].append(writers[name](repeat))
                    for leftover in (
                        list(work.glob(f"raw{repeat}")) + list(work.glob(f"rust{repeat}")) + list(work.glob(f"py{repeat}.mcap"))
                    ):
                        shutil.rmtree(leftover) if leftover.is_dir() else leftover.unlink()
            results["writers"]["fsync" if durable else "page_cache"] = {
                "seconds": {k: statistics.median(v) for k, v in times.items()},
                "runs": times,
            }
    finally:
        shutil.rmtree(work, ignore_errors=True)

    load, sweep, writers = results["stack_load"], results["sweep"], results["writers"]
    lost = {t: load["published"][t] - load["recorded"].get(t, 0) for t in load["published"]}
    print("\n## Stack load (2 x 640x480 rgb8 @ 30 Hz + JointState @ 500 Hz)")
    print(f"published {load['published']}, recorded {load['recorded']}, missing {lost}, dropped {load['dropped']}")
    mb = load["file_bytes"] / 1e6 / load["publish_seconds"]
    print(
        f"recorder CPU {100 * load['recorder_cpu_seconds'] / (load['publish_seconds'] + 1):.1f} % of a core, {mb:.1f} MB/s into the bag"
    )
    print("\n## Sustained: two 640x480 rgb8 cameras at rising rates + JointState @ 500 Hz")
    print("| camera rate (Hz) | published | recorded | missing | reported lost | MB/s into the bag | messages/s | recorder CPU |")
    print("|---|---|---|---|---|---|---|---|")
    for step in sweep:
        seconds = step["publish_seconds"]
        print(
            f"| {step['camera_rate']:g} | {sum(step['published'].values())} | {sum(step['recorded'].values())} | {step['missing']} | {step['dropped']} | "
            f"{step['file_bytes'] / 1e6 / seconds:.1f} | {sum(step['recorded'].values()) / seconds:.0f} | "
            f"{100 * step['recorder_cpu_seconds'] / (seconds + 1):.0f} % |"
        )
    for mode, title in (("page_cache", "page cache (no fsync): the writers' own cost"), ("fsync", "fsync included: this disk")):
        seconds = writers[mode]["seconds"]
        mbps = {k: writers["bytes"] / 1e6 / v for k, v in seconds.items()}
        print(
            f"\n## Writers on the same {writers['messages']} messages ({writers['bytes'] / 1e6:.0f} MB), {title}, medians of {args.repeats}"
        )
        print("| writer | MB/s | messages/s | ratio to raw write | ratio to Python mcap |")
        print("|---|---|---|---|---|")
        for key in ("raw", "recorder_bag_writer", "python_mcap"):
            print(
                f"| {key} | {mbps[key]:.0f} | {writers['messages'] / seconds[key]:.0f} | {mbps[key] / mbps['raw']:.2f} | {mbps[key] / mbps['python_mcap']:.2f} |"
            )
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))
    return 0


SUBCOMMAND = Subcommand(
    "recorder_node's sustained rates and its writer against Python's mcap writer", add_arguments, run, __doc__
)


def main(argv: list[str] | None = None) -> int:
    return run_alone("so101-bench recorder", SUBCOMMAND, argv)


if __name__ == "__main__":
    sys.exit(main())
