"""Identification against ground truth: the servo-bus emulator stands in for the arm with known,
non-default servo parameters (TRUTH below); `so101-sysid record` drives every joint through the
driver and records, `fit` identifies the parameters, `compare` replays the held-out motions in the
simulation before (the default servo model) and after the fit. Prints each parameter's relative error
and the headline `identification error: N %` (the largest over the fitted parameters).

    so101-bench sysid [--output DIR] [--joints a,b]   (inside scripts/isolated, or it isolates itself)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from .. import contract
from ..subcommands import Subcommand, run_alone

# What the fit starts from and is compared with: the default servo model.
PRESET = contract.DEFAULT_SERVO_MODEL
# The emulated arm's truth, relative to the preset: every fitted parameter moved.
TRUTH = {"gain_per_p": 0.5, "damping": 1.6, "friction": 2.0, "armature": 1.4}
TRUTH_LATENCY = 0.020  # s
TRUTH_DEAD_ZONE = 2.0  # ticks, CW and CCW
FITTED = ("gain_per_p", "damping", "friction", "armature", "latency", "dead_zone")


def truth_params() -> dict:
    """The parameter file of the emulated arm."""
    import so101_native

    params = json.loads(so101_native.servo_params_json(PRESET))
    for joint in params["joints"].values():
        for name, factor in TRUTH.items():
            joint["mechanics"][name] *= factor
        joint["mechanics"]["latency"] = TRUTH_LATENCY
        joint["registers"]["cw_dead_zone"] = joint["registers"]["ccw_dead_zone"] = TRUTH_DEAD_ZONE
    return params


def values(joint: dict) -> dict[str, float]:
    mechanics = {name: joint["mechanics"][name] for name in FITTED if name in joint["mechanics"]}
    return {**mechanics, "dead_zone": 0.5 * (joint["registers"]["cw_dead_zone"] + joint["registers"]["ccw_dead_zone"])}


def relative_errors(fitted: dict, truth: dict) -> dict[str, dict[str, float]]:
    """joint -> parameter -> |fitted - truth| / truth."""
    errors = {}
    for name, joint in fitted["joints"].items():
        if name not in truth["joints"]:
            continue
        found, expected = values(joint), values(truth["joints"][name])
        errors[name] = {key: abs(found[key] - expected[key]) / expected[key] for key in FITTED}
    return errors


def sysid(*argv) -> str:
    done = subprocess.run([sys.executable, "-m", "so101.sysid.cli", *map(str, argv)], capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"so101-sysid {argv[0]} failed:\n{done.stdout[-3000:]}{done.stderr[-3000:]}")
    return done.stdout


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--bin-dir", type=Path, default=None, help="the built binaries (scripts/bench.sh passes it)")
    p.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    p.add_argument("--output", default=None, help="keep the bags and files here (default: a temporary directory)")
    p.add_argument("--joints", default=None, help="joints to identify (default: all six)")


def run(args: argparse.Namespace) -> int:
    if args.bin_dir:
        os.environ["SO101_BIN_DIR"] = str(args.bin_dir)
    output = Path(args.output or tempfile.mkdtemp(prefix="so101_sysid_bench_"))
    output.mkdir(parents=True, exist_ok=True)
    truth = truth_params()
    (output / "truth.json").write_text(json.dumps(truth, indent=1))
    joints = ["--joints", args.joints] if args.joints else []
    sysid(
        "record", "--emulate", "--emulator-servo-params", output / "truth.json", "--held-out", "--bags", output / "bags", *joints
    )
    print(sysid("fit", output / "bags", "--output", output / "fit.json"))
    fitted = json.loads((output / "fit.json").read_text())
    errors = relative_errors(fitted, truth)
    print("| joint | " + " | ".join(FITTED) + " |")
    print("|---|" + "---|" * len(FITTED))
    for name, row in errors.items():
        print(f"| {name} | " + " | ".join(f"{100 * row[key]:.0f} %" for key in FITTED) + " |")
    worst = {key: max(row[key] for row in errors.values()) for key in FITTED}
    print("largest error per parameter: " + ", ".join(f"{key} {100 * value:.0f} %" for key, value in worst.items()))
    sysid(
        "compare",
        output / "bags",
        "--tasks",
        "so101-sysid",
        "--servo-params",
        PRESET,
        "--servo-params",
        output / "fit.json",
        "--json",
        output / "compare.json",
    )
    gaps = json.loads((output / "compare.json").read_text())
    print("| held-out motion | joint RMS before / after (mrad) | gripper RMS before / after (mm) |")
    print("|---|---|---|")
    for result in gaps.values():
        task = result["task"]
        if not task.endswith("held-out"):
            continue
        joint = task.split()[1]
        index = contract.JOINT_NAMES.index(joint)
        before, after = result[PRESET], result[str(output / "fit.json")]
        print(
            f"| {joint} | {1000 * before['rms_rad'][index]:.2f} / {1000 * after['rms_rad'][index]:.2f} | "
            f"{before['gripper_rms_mm']:.2f} / {after['gripper_rms_mm']:.2f} |"
        )
    print(f"identification error: {100 * max(worst.values()):.0f} %")
    if args.json:
        args.json.write_text(json.dumps({"relative_errors": errors, "largest": worst, "gaps": gaps}, indent=2))
    print(f"(files in {output})")
    return 0


SUBCOMMAND = Subcommand(
    "so101-sysid against the emulator's known servo parameters: the identification error", add_arguments, run, __doc__
)


def main(argv: list[str] | None = None) -> int:
    return run_alone("so101-bench sysid", SUBCOMMAND, argv)


if __name__ == "__main__":
    raise SystemExit(main())
