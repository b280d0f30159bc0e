"""so101-sysid: identify your arm's servos (record, fit) and measure how far the simulation is from
it (compare). See so101.sysid and docs/sim_to_real.md."""

from __future__ import annotations

import sys

from .. import subcommands
from ..subcommands import Subcommand
from . import compare, fit, record

COMMANDS = {
    "record": Subcommand(
        "drive the arm one joint at a time through steps and a chirp, one bag per joint",
        record.add_arguments,
        record.run,
        record.__doc__,
    ),
    "fit": Subcommand(
        "fit the servo model per joint to the recording; write a parameter file", fit.add_arguments, fit.run, fit.__doc__
    ),
    "compare": Subcommand(
        "replay recorded episodes in the sim; the tracking gap per joint and at the gripper",
        compare.add_arguments,
        compare.run,
        compare.__doc__,
    ),
}


def main(argv: list[str] | None = None) -> int:
    return subcommands.main("so101-sysid", __doc__, COMMANDS, argv)


if __name__ == "__main__":
    sys.exit(main())
