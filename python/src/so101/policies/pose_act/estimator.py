"""The cube-pose estimator of pose_act: one small CNN per camera, each ending in spatial-softmax
keypoints, and an MLP from every camera's keypoints to the pose.

Why this shape: the cube is 3 cm wide, a few pixels in a 96x72 frame, and a grasp needs its place
to millimetres. ACT's ResNet-18 reduces such a frame to a 3x3 map (stride 32); these convolutions
stop at stride 4 (24x18), and the keypoints are expectations over that map, so their precision is
finer than a cell. Four layers of 32 channels cost about a tenth of ResNet-18's multiply-adds per
frame, which is what lets the robust recipe train within an hour on two CPU cores. GroupNorm, not
BatchNorm: the same statistics in training and at inference, one frame at a time."""

from __future__ import annotations

import torch
from lerobot.policies.diffusion.modeling_diffusion import SpatialSoftmax
from torch import Tensor, nn


def camera_trunk(channels: int) -> nn.Sequential:
    """3 x H x W -> channels x H/4 x W/4."""

    def block(inputs: int, outputs: int, kernel: int, stride: int) -> list[nn.Module]:
        return [
            nn.Conv2d(inputs, outputs, kernel, stride=stride, padding=kernel // 2),
            nn.GroupNorm(8 if outputs % 8 == 0 else 1, outputs),
            nn.ReLU(inplace=True),
        ]

    return nn.Sequential(
        *block(3, channels, 5, 2),
        *block(channels, channels, 3, 2),
        *block(channels, channels, 3, 1),
        *block(channels, channels, 3, 1),
    )


class CubePoseEstimator(nn.Module):
    """Frames (B x 3 x H x W each, in the cameras' order) and, when `joints` > 0, the normalized
    joints (B x joints) -> the pose (B x pose_dim, normalized).

    The joints tell the head where the wrist camera looks from: its keypoints place the cube in the
    gripper's frame, the target is in the base frame, and the rotation between the two is the arm's."""

    def __init__(
        self, image_shapes: list[tuple[int, int, int]], pose_dim: int, channels: int, keypoints: int, hidden: int, joints: int = 0
    ):
        super().__init__()
        self.joints = joints
        self.trunks = nn.ModuleList(camera_trunk(channels) for _ in image_shapes)
        self.keypoints = nn.ModuleList(
            SpatialSoftmax((channels, -(-h // 4), -(-w // 4)), num_kp=keypoints) for _, h, w in image_shapes
        )
        self.head = nn.Sequential(
            nn.Linear(2 * keypoints * len(image_shapes) + joints, hidden),
            nn.ReLU(inplace=True),
            nn.Linear(hidden, hidden),
            nn.ReLU(inplace=True),
            nn.Linear(hidden, pose_dim),
        )

    def forward(self, images: list[Tensor], joints: Tensor | None = None) -> Tensor:
        points = [kp(trunk(image)).flatten(1) for image, trunk, kp in zip(images, self.trunks, self.keypoints, strict=True)]
        if self.joints:
            if joints is None or joints.shape[-1] != self.joints:
                raise ValueError(f"the estimator reads {self.joints} joints beside the cameras")
            points.append(joints)
        return self.head(torch.cat(points, dim=1))
