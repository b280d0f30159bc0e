"""PoseACTPolicy: the cube-pose estimator and the state ACT in one LeRobot policy
(configuration_pose_act says why). Training: ACT's L1 loss on the actions plus the estimator's
Huber error on the recorded pose. Inference: the estimator's pose, never a given one."""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F  # noqa: N812 - torch's own convention
from lerobot.policies.act.modeling_act import ACTPolicy
from lerobot.policies.pretrained import PreTrainedPolicy
from lerobot.utils.constants import ACTION, OBS_ENV_STATE, OBS_STATE
from torch import Tensor

from ...ee import ee_poses
from ...units import radians_from_lerobot
from .configuration_pose_act import PoseACTConfig
from .estimator import CubePoseEstimator


class PoseACTPolicy(PreTrainedPolicy):
    config_class = PoseACTConfig
    name = "pose_act"

    def __init__(self, config: PoseACTConfig, dataset_stats: dict | None = None, **kwargs):
        super().__init__(config)
        config.validate_features()
        self.config = config
        self.act = ACTPolicy(config.act_config())
        shapes = [tuple(config.input_features[key].shape) for key in config.image_features]
        self.estimator = CubePoseEstimator(
            shapes,
            config.pose_dim,
            config.estimator_channels,
            config.estimator_keypoints,
            config.estimator_hidden,
            joints=config.input_features[OBS_STATE].shape[0] if config.estimator_reads_joints else 0,
        )
        # The pose's normalization (the dataset's mean and std), saved with the weights.
        self.register_buffer("pose_mean", torch.zeros(config.pose_dim))
        self.register_buffer("pose_std", torch.ones(config.pose_dim))
        # The joints' normalization (the preprocessor's), to find the gripper by forward kinematics.
        self.register_buffer("state_mean", torch.zeros(6))
        self.register_buffer("state_std", torch.ones(6))
        self.register_buffer("trained_steps", torch.zeros((), dtype=torch.long))
        stats = dataset_stats or {}
        if OBS_ENV_STATE in stats:
            self.pose_mean.copy_(as_vector(stats[OBS_ENV_STATE]["mean"]))
            self.pose_std.copy_(as_vector(stats[OBS_ENV_STATE]["std"]).clamp_min(config.pose_std_floor))
        if OBS_STATE in stats:
            self.state_mean.copy_(as_vector(stats[OBS_STATE]["mean"]))
            self.state_std.copy_(as_vector(stats[OBS_STATE]["std"]))
        # About where the cube lies from the gripper (the mean pose's offset from the mean joints'
        # gripper; the base frame sits below the world's table), taken off the estimator's target so
        # that it learns the offset's changes, not a constant of several tenths of a metre.
        self.register_buffer("relative_mean", self.pose_mean[:3] - self.gripper_position(torch.zeros(1, 6))[0])
        self.reset()

    @classmethod
    def from_pretrained(cls, pretrained_name_or_path, *, dataset_stats: dict | None = None, **kwargs):
        """The saved policy. Given a dataset's statistics (lerobot-train --policy.pretrained_path:
        fine-tuning on another dataset), the joints' normalization follows them, as the
        preprocessor's does, so the forward kinematics reads the joints it is given; the pose's
        units stay the saved ones, the estimator's outputs are in them."""
        policy = super().from_pretrained(pretrained_name_or_path, dataset_stats=dataset_stats, **kwargs)
        if dataset_stats and OBS_STATE in dataset_stats:
            policy.state_mean.copy_(as_vector(dataset_stats[OBS_STATE]["mean"]))
            policy.state_std.copy_(as_vector(dataset_stats[OBS_STATE]["std"]))
        return policy

    def get_optim_params(self):
        estimator = [p for p in self.estimator.parameters() if p.requires_grad]
        chosen = {id(p) for p in estimator}
        rest = [p for p in self.parameters() if p.requires_grad and id(p) not in chosen]
        return [{"params": rest}, {"params": estimator, "lr": self.config.estimator_lr}]

    def reset(self):
        self.act.reset()

    def _images(self, batch: dict[str, Tensor]) -> list[Tensor]:
        return [batch[key] for key in self.config.image_features]

    def gripper_position(self, state: Tensor) -> Tensor:
        """The gripper's position (m, the arm's base frame) by the core's forward kinematics of the
        normalized joints (LeRobot's units)."""
        lerobot_units = (state * self.state_std + self.state_mean).detach().cpu().double().numpy()
        position = ee_poses(radians_from_lerobot(lerobot_units))[..., :3]
        return torch.as_tensor(np.ascontiguousarray(position), dtype=state.dtype, device=state.device)

    def estimator_target(self, pose: Tensor, gripper: Tensor) -> Tensor:
        """What the estimator regresses: the position relative to the gripper and the normalized
        orientation."""
        relative = (pose[:, :3] - gripper - self.relative_mean) / self.config.relative_scale
        return torch.cat([relative, (pose[:, 3:] - self.pose_mean[3:]) / self.pose_std[3:]], dim=1)

    def pose_from_estimate(self, estimate: Tensor, gripper: Tensor) -> Tensor:
        """The inverse of estimator_target: the pose (m, quaternion)."""
        position = gripper + self.relative_mean + estimate[:, :3] * self.config.relative_scale
        return torch.cat([position, estimate[:, 3:] * self.pose_std[3:] + self.pose_mean[3:]], dim=1)

    def normalized(self, pose: Tensor) -> Tensor:
        """The pose as the state ACT reads it (by the dataset's mean and std)."""
        return (pose - self.pose_mean) / self.pose_std

    def estimated_pose(self, batch: dict[str, Tensor]) -> Tensor:
        """The cube's pose the cameras show, in the recorded pose's units (m, quaternion)."""
        return self.pose_from_estimate(self._estimate(batch), self.gripper_position(batch[OBS_STATE]))

    def _estimate(self, batch: dict[str, Tensor]) -> Tensor:
        return self.estimator(self._images(batch), batch[OBS_STATE])

    def _act_batch(self, batch: dict[str, Tensor], pose: Tensor) -> dict[str, Tensor]:
        act_batch = {OBS_STATE: batch[OBS_STATE], OBS_ENV_STATE: pose}
        for key in (ACTION, "action_is_pad"):
            if key in batch:
                act_batch[key] = batch[key]
        return act_batch

    @torch.no_grad()
    def select_action(self, batch: dict[str, Tensor], **kwargs) -> Tensor:
        self.eval()
        return self.act.select_action(self._act_batch(batch, self.normalized(self.estimated_pose(batch))))

    @torch.no_grad()
    def predict_action_chunk(self, batch: dict[str, Tensor], **kwargs) -> Tensor:
        self.eval()
        return self.act.predict_action_chunk(self._act_batch(batch, self.normalized(self.estimated_pose(batch))))

    def forward(self, batch: dict[str, Tensor]) -> tuple[Tensor, dict]:
        if OBS_ENV_STATE not in batch:
            raise ValueError(
                f"pose_act trains on {OBS_ENV_STATE}, the recorded cube pose: the dataset has none "
                "(record its demos without --no-environment-state)"
            )
        recorded = batch[OBS_ENV_STATE]
        gripper = self.gripper_position(batch[OBS_STATE])
        target = self.estimator_target(recorded, gripper)
        estimate = self._estimate(batch)
        # Huber: squared within one unit (relative_scale of position, a standard deviation of
        # orientation), linear beyond, so the frames whose pose no picture can tell (a cube
        # tumbling in the bin, its quaternion's sign) do not swamp the rest.
        pose_loss = F.smooth_l1_loss(estimate[:, :3], target[:, :3])
        if target.shape[1] > 3:
            pose_loss = pose_loss + self.config.orientation_loss_weight * F.smooth_l1_loss(estimate[:, 3:], target[:, 3:])
        truth = self.normalized(recorded)
        pose = truth + self.config.pose_input_noise * torch.randn_like(truth)
        if self.training and int(self.trained_steps) >= self.config.estimator_warmup_steps:
            chosen = torch.rand(truth.shape[0], 1, device=truth.device) < self.config.estimated_pose_share
            pose = torch.where(chosen, self.normalized(self.pose_from_estimate(estimate.detach(), gripper)), pose)
        act_loss, losses = self.act.forward(self._act_batch(batch, pose))
        if self.training:
            self.trained_steps += 1
        losses = dict(losses or {})
        losses["pose_loss"] = pose_loss.item()
        with torch.no_grad():
            error = (estimate[:, :3] - target[:, :3]) * self.config.relative_scale
            losses["pose_error_mm"] = 1000 * error.norm(dim=1).mean().item()
        return act_loss + self.config.pose_loss_weight * pose_loss, losses


def as_vector(values) -> Tensor:
    return torch.as_tensor(values, dtype=torch.float32).reshape(-1)
