"""The one convention of the tools that take a subcommand (so101-learn, so101-sysid, so101-bench):
a table of name -> Subcommand. `TOOL --help` lists the subcommands, one line each; `TOOL NAME
--help` gives that one's description and options; an unknown name is refused with the list of
names (exit status 2); `TOOL NAME ARGS...` runs `run(args)` and exits with what it returns."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Mapping
from dataclasses import dataclass


@dataclass(frozen=True)
class Subcommand:
    summary: str  # its line in the tool's --help
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]
    description: str | None = None  # its own --help text, laid out as written (default: the summary)


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Descriptions laid out as written; each subcommand's summary on its name's line (argparse
    measures the names without the indent it prints them with, so a long one got a line alone)."""

    def add_argument(self, action: argparse.Action) -> None:
        super().add_argument(action)
        if action.help is not argparse.SUPPRESS and isinstance(action, argparse._SubParsersAction):
            names = [len(self._format_action_invocation(sub)) for sub in action._get_subactions()]
            indent = self._current_indent + self._indent_increment
            self._action_max_length = max(self._action_max_length, max(names, default=0) + indent)


def parser(
    prog: str, description: str | None, subcommands: Mapping[str, Subcommand], metavar: str = "COMMAND", title: str = "commands"
) -> argparse.ArgumentParser:
    """The tool's parser: one subparser per entry of `subcommands`, in table order, listed under
    `title` in its --help."""
    tool = argparse.ArgumentParser(prog=prog, description=description, formatter_class=HelpFormatter)
    chosen = tool.add_subparsers(dest="subcommand", required=True, metavar=metavar, title=title)
    for name, subcommand in subcommands.items():
        sub = chosen.add_parser(
            name,
            help=subcommand.summary,
            description=subcommand.description or subcommand.summary,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        subcommand.add_arguments(sub)
        sub.set_defaults(run=subcommand.run)
    return tool


def main(
    prog: str,
    description: str | None,
    subcommands: Mapping[str, Subcommand],
    argv: list[str] | None = None,
    metavar: str = "COMMAND",
    title: str = "commands",
) -> int:
    """Parses `argv` (default: the command line) and runs the subcommand it names."""
    args = parser(prog, description, subcommands, metavar, title).parse_args(argv)
    return args.run(args)


def run_alone(prog: str, subcommand: Subcommand, argv: list[str] | None = None) -> int:
    """One subcommand as a program of its own (`python -m so101.bench.sim ...`): the same options."""
    alone = argparse.ArgumentParser(
        prog=prog,
        description=subcommand.description or subcommand.summary,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    subcommand.add_arguments(alone)
    return subcommand.run(alone.parse_args(argv))
