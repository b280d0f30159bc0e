"""pose_act's pre- and post-processors: ACT's (LeRobot's defaults: each input and the action
normalized by its dataset statistics). The environment state is not among the policy's inputs, so
they leave it as recorded; the policy normalizes its target itself."""

from __future__ import annotations

from lerobot.policies.act.processor_act import make_act_pre_post_processors

from .configuration_pose_act import PoseACTConfig


def make_pose_act_pre_post_processors(config: PoseACTConfig, dataset_stats=None):
    return make_act_pre_post_processors(config, dataset_stats)
