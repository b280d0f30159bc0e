#!/usr/bin/env python3
"""Benchmark of so101_feetech_driver against the servo-bus emulator with realistic wire timing.

Reports (docs/benchmarks.md):
  * full control cycles per second at --rate max (one SYNC_READ of 6 positions + one SYNC_WRITE of
    6 goals each), as a ratio to the wire limit computed from the bytes at the baud rate, with the
    telemetry reads the driver makes between cycles taken out of the wire budget;
  * cycle start jitter (lateness against the schedule) at the default 200 Hz: p50, p99, max;
  * CPU use of the driver process in both modes.

The driver opens a DDS participant, so run this inside a private network namespace
(scripts/bench.sh does): scripts/isolated .venv/bin/python -m so101.bench.driver --bin-dir DIR
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from so101.contract import JOINT_NAMES
from so101.subcommands import Subcommand, run_alone

BITS_PER_BYTE = 10
SYNC_READ_REQUEST = 8 + 6  # FF FF FE LEN 82 ADDR SIZE CHK + 6 ids
STATUS_OVERHEAD = 6  # FF FF ID LEN ERR ... CHK
POSITION_BYTES = 2
TELEMETRY_BYTES = 13
SYNC_WRITE_BYTES = 8 + 6 * (1 + POSITION_BYTES)

CALIBRATION = {
    name: {"id": i + 1, "drive_mode": 0, "homing_offset": 0, "range_min": 1000, "range_max": 3000}
    for i, name in enumerate(JOINT_NAMES)
}


def cycle_bytes() -> int:
    return SYNC_READ_REQUEST + 6 * (STATUS_OVERHEAD + POSITION_BYTES) + SYNC_WRITE_BYTES


def telemetry_bytes() -> int:
    return SYNC_READ_REQUEST + 6 * (STATUS_OVERHEAD + TELEMETRY_BYTES)


def wire_limit(baud: int, telemetry_rate: float) -> float:
    """Cycles/s the wire allows when `telemetry_rate` telemetry reads per second share it."""
    byte_time = BITS_PER_BYTE / baud
    free = 1.0 - telemetry_rate * telemetry_bytes() * byte_time
    return free / (cycle_bytes() * byte_time)


def run_once(bin_dir: Path, workdir: Path, baud: int, rate: str, telemetry_rate: float, seconds: float, timing: str) -> dict:
    link = workdir / "bus"
    calibration = workdir / "calibration.json"
    calibration.write_text(json.dumps(CALIBRATION))
    stats = workdir / "stats.json"
    stats.unlink(missing_ok=True)
    emulator = subprocess.Popen(
        # The emulated servos hold the calibration the driver is given (the driver refuses others).
        [
            str(bin_dir / "so101_servo_emulator"),
            "--link",
            str(link),
            "--timing",
            timing,
            "--baud",
            str(baud),
            "--calibration",
            str(calibration),
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        if not emulator.stdout.readline().startswith("PTY "):
            raise RuntimeError("the emulator did not start")
        env = {k: v for k, v in os.environ.items() if k not in ("LD_LIBRARY_PATH", "_ROS_WHEELS_BOOTSTRAP_COMPLETE")}
        env["RUST_LOG"] = "warn"
        driver = subprocess.run(
            [
                str(bin_dir / "so101_feetech_driver"),
                "--port",
                str(link),
                "--baud",
                str(baud),
                "--calibration",
                str(calibration),
                "--rate",
                rate,
                "--telemetry-rate",
                str(telemetry_rate),
                "--duration",
                str(seconds),
                "--stats-json",
                str(stats),
            ],
            env=env,
            capture_output=True,
            text=True,
            timeout=seconds + 60,
        )
        if driver.returncode != 0:
            raise RuntimeError(f"driver failed ({driver.returncode}):\n{driver.stderr[-3000:]}")
        return json.loads(stats.read_text())
    finally:
        emulator.stdin.close()
        emulator.send_signal(signal.SIGTERM)
        emulator.wait(timeout=10)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--bin-dir", type=Path, required=True, help="directory of the release binaries")
    parser.add_argument("--seconds", type=float, default=10.0, help="length of each run")
    parser.add_argument("--repeats", type=int, default=3, help="runs per configuration (medians are reported)")
    parser.add_argument("--baud", type=int, default=1_000_000)
    parser.add_argument("--json", type=Path, help="write the raw results here")


def run(args: argparse.Namespace) -> int:
    # The last one has no wire time at all: what a cycle costs in the pty and the driver alone.
    configurations = [
        ("max rate, telemetry 10 Hz (default)", "max", 10.0, "realistic"),
        ("max rate, telemetry 1 Hz", "max", 1.0, "realistic"),
        ("200 Hz (default), telemetry 10 Hz", "200", 10.0, "realistic"),
        ("max rate, telemetry 1 Hz, instant emulator (no wire time)", "max", 1.0, "instant"),
    ]
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, rate, telemetry, timing in configurations:
            runs = []
            for repeat in range(args.repeats):
                print(f"[{label}] run {repeat + 1}/{args.repeats} ({args.seconds:.0f} s)...", file=sys.stderr, flush=True)
                runs.append(run_once(args.bin_dir, Path(tmp), args.baud, rate, telemetry, args.seconds, timing))
            limit = wire_limit(args.baud, telemetry) if timing == "realistic" else None
            rates = [run["cycles"]["cycles_per_second"] for run in runs]
            results.append(
                {
                    "label": label,
                    "rate": rate,
                    "telemetry_rate": telemetry,
                    "timing": timing,
                    "wire_limit_cycles_per_second": limit,
                    "cycles_per_second": statistics.median(rates),
                    "ratio_to_wire_limit": statistics.median(rates) / limit if limit else None,
                    "lateness_p50_us": statistics.median(r["cycles"]["lateness_p50_us"] for r in runs),
                    "lateness_p99_us": statistics.median(r["cycles"]["lateness_p99_us"] for r in runs),
                    "lateness_max_us": max(r["cycles"]["lateness_max_us"] for r in runs),
                    "period_p50_us": statistics.median(r["cycles"]["period_p50_us"] for r in runs),
                    "period_p99_us": statistics.median(r["cycles"]["period_p99_us"] for r in runs),
                    "cpu_percent": statistics.median(r["cpu_percent"] for r in runs),
                    "timeouts": sum(r["bus"]["timeouts"] for r in runs),
                    "failed_cycles": sum(r["failed_cycles"] for r in runs),
                    "runs": runs,
                }
            )

    print(f"\nWire: {cycle_bytes()} bytes per cycle, {telemetry_bytes()} per telemetry read, {args.baud} baud, 10 bits per byte")
    print("| configuration | cycles/s | wire limit | ratio | lateness p50 / p99 / max (us) | period p50 / p99 (us) | CPU % |")
    print("|---|---|---|---|---|---|---|")
    for r in results:
        limit, ratio = r["wire_limit_cycles_per_second"], r["ratio_to_wire_limit"]
        print(
            f"| {r['label']} | {r['cycles_per_second']:.1f} | {f'{limit:.1f}' if limit else '-'} | "
            f"{f'**{ratio:.3f}**' if ratio else '-'} | {r['lateness_p50_us']:.0f} / {r['lateness_p99_us']:.0f} / {r['lateness_max_us']:.0f} | "
            f"{r['period_p50_us']:.0f} / {r['period_p99_us']:.0f} | {r['cpu_percent']:.1f} |"
        )
    failures = sum(r["timeouts"] + r["failed_cycles"] for r in results)
    print(f"bus timeouts + failed cycles over all runs: {failures}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))
    return 0


SUBCOMMAND = Subcommand(
    "so101_feetech_driver's cycle rate and lateness against the emulator's wire limit", add_arguments, run, __doc__
)


def main(argv: list[str] | None = None) -> int:
    return run_alone("so101-bench driver", SUBCOMMAND, argv)


if __name__ == "__main__":
    sys.exit(main())
