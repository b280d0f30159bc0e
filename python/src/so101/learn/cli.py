"""so101-learn: the learning recipes, one command each, with progress and a summary at the end.

  demos      record N expert demonstrations through the stack (sim, scripted expert, recorder)
             and convert the bags into a LeRobot dataset
  act        train LeRobot's ACT with lerobot-train, CPU-sized, on the state (joints + cube pose)
             or on joints + cameras (a dataset of demos --cameras ... --no-environment-state),
             then evaluate it through so101-run-policy in lockstep
  diffusion  the same with LeRobot's Diffusion Policy
  bc         behaviour cloning with `imitation` on in-process expert rollouts;
             --continue-with-sac STEPS: then SAC on cube_to_bin continuing from the clone
  sac        SAC (Stable-Baselines3) on the dense reward, success rate over training
  eval       evaluate any of them over M seeded episodes (95 % interval, rewards, MP4s)

`so101-learn RECIPE --help` tells each one's options; docs/learning.md the settings and timings.
"""

from __future__ import annotations

import argparse
import sys

from . import demos, eval_recipe, lerobot_train, sb3_bc, sb3_sac

RECIPES = {
    "demos": demos,
    "act": lerobot_train,
    "diffusion": lerobot_train,
    "bc": sb3_bc,
    "sac": sb3_sac,
    "eval": eval_recipe,
}


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="so101-learn", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    recipes = p.add_subparsers(dest="recipe", required=True, metavar="RECIPE")
    for name, module in RECIPES.items():
        module.add_parser(recipes, name)
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    return args.run(args)


if __name__ == "__main__":
    sys.exit(main())
