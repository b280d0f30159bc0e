"""What every so101-learn recipe shares: its subcommand, with the module's docstring as help text."""

from __future__ import annotations

import argparse


def recipe_parser(recipes, name: str, summary: str, doc: str | None) -> argparse.ArgumentParser:
    """The subcommand `name` of so101-learn: `summary` in the recipe list, `doc` (the module's
    docstring) in its --help, laid out as written."""
    return recipes.add_parser(name, help=summary, description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
