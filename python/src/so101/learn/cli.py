"""so101-learn: the learning recipes, one command each, with progress and a summary at the end.

  demos      record N expert demonstrations through the stack (sim, scripted expert, recorder)
             and convert the bags into a LeRobot dataset
  backgrounds  draw pictures to show behind the simulated scene in training, and the
             randomization file that shows them (demos --randomize DIR/randomization.toml)
  act        train LeRobot's ACT with lerobot-train, CPU-sized, on the state (joints + cube pose)
             or on joints + cameras (a dataset of demos --cameras ... --no-environment-state),
             then evaluate it through so101-run-policy in lockstep
  pose_act   ACT on the joints and the cube's pose, the pose estimated from the cameras by a CNN
             trained beside it (a dataset of demos --cameras ..., with the pose as its target)
  diffusion  the same with LeRobot's Diffusion Policy
  smolvla    fine-tune SmolVLA (lerobot/smolvla_base or local weights) on a camera dataset's tasks,
             language-conditioned on each episode's task text, then evaluate it on each task
  pi0        the same with pi0 (lerobot/pi0_base)
  bc         behaviour cloning with `imitation` on in-process expert rollouts;
             --continue-with-sac STEPS: then SAC on cube_to_bin continuing from the clone
  sac        SAC (Stable-Baselines3) on the dense reward, success rate over training
  eval       evaluate any of them over M seeded episodes (95 % interval, rewards, MP4s)

`so101-learn RECIPE --help` tells each one's options; docs/learning.md the settings and timings.
"""

from __future__ import annotations

import functools
import sys

from .. import subcommands
from ..subcommands import Subcommand
from . import demos, eval_recipe, lerobot_train, procedural_backgrounds, sb3_bc, sb3_sac, vla

RECIPES = {
    "demos": Subcommand(
        "record N expert demonstrations through the stack and convert them into a LeRobot dataset",
        demos.add_arguments,
        demos.run,
        demos.__doc__,
    ),
    "backgrounds": Subcommand(
        "draw pictures to show behind the simulated scene in training, and a randomization file showing them",
        procedural_backgrounds.add_arguments,
        procedural_backgrounds.run,
        procedural_backgrounds.__doc__,
    ),
    **{
        name: Subcommand(
            lerobot_train.summary(name),
            functools.partial(lerobot_train.add_arguments, name=name),
            lerobot_train.run,
            lerobot_train.__doc__,
        )
        for name in ("act", "pose_act", "diffusion")
    },
    **{
        name: Subcommand(vla.summary(name), functools.partial(vla.add_arguments, name=name), vla.run, vla.__doc__)
        for name in vla.VLAS
    },
    "bc": Subcommand(
        "behaviour cloning (imitation) on in-process expert demonstrations", sb3_bc.add_arguments, sb3_bc.run, sb3_bc.__doc__
    ),
    "sac": Subcommand(
        "SAC (Stable-Baselines3) on the dense reward, success rate over training",
        sb3_sac.add_arguments,
        sb3_sac.run,
        sb3_sac.__doc__,
    ),
    "eval": Subcommand(
        "evaluate a policy (bc, sac or LeRobot) over M seeded episodes",
        eval_recipe.add_arguments,
        eval_recipe.run,
        eval_recipe.__doc__,
    ),
}


def parser():
    return subcommands.parser("so101-learn", __doc__, RECIPES, metavar="RECIPE", title="recipes")


def main(argv: list[str] | None = None) -> int:
    return subcommands.main("so101-learn", __doc__, RECIPES, argv, metavar="RECIPE", title="recipes")


if __name__ == "__main__":
    sys.exit(main())
