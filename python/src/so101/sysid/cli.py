"""so101-sysid: identify your arm's servos (record, fit) and measure how far the simulation is from
it (compare). See so101.sysid and docs/sim_to_real.md."""

from __future__ import annotations

import argparse
import sys

from . import compare, fit, record


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="so101-sysid", description=__doc__)
    commands = p.add_subparsers(dest="command", required=True)
    for name, module, text in (
        ("record", record, "drive the arm one joint at a time through steps and a chirp, one bag per joint"),
        ("fit", fit, "fit the servo model per joint to the recording; write a parameter file"),
        ("compare", compare, "replay recorded episodes in the sim; the tracking gap per joint and at the gripper"),
    ):
        sub = commands.add_parser(name, help=text, description=(module.__doc__ or text))
        module.add_arguments(sub)
        sub.set_defaults(run=module.run)
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    return args.run(args)


if __name__ == "__main__":
    sys.exit(main())
