"""PoseACTConfig: ACT's configuration, plus the cube-pose estimator's.

Why a policy of its own: ACT trained end to end on joints + 96x72 cameras must learn where the
cube is from its action loss alone, a few hundred demonstrations' worth of it. On this project's
2-core CPU that takes 3.7 hours for 92 % nominal success, and under the default randomization
(colours, lights, camera poses, servos) the policy fell to 52 % (docs/benchmarks.md). The cube's
pose is a small, well-defined quantity the simulation knows at every recorded frame: supervising
it directly, frame by frame, is the way vision-based sim-to-real systems train their state
estimators under domain randomization (OpenAI's in-hand manipulation work estimated the object's
pose from three cameras with a CNN, its policy acting on the estimate). Here the two train in one
lerobot-train run:
- the estimator, a 4-layer CNN per camera ending in spatial-softmax keypoints (LeRobot's own
  SpatialSoftmax, as Diffusion Policy uses it), regresses observation.environment_state (the
  cube's position and orientation, normalized by the dataset's mean and std) from the images;
- the state ACT (the `act` recipe's, cheap on a CPU) learns the actions from the joints and a pose:
  the recorded one with noise, or, for a share of each batch once the estimator has warmed up, the
  estimator's own (detached) estimate, so the actions learn to live with its errors.
observation.environment_state is a training target only: the policy's saved input features are the
joints and the cameras, and at inference the pose comes from the estimator alone, as on a real arm.
"""

from __future__ import annotations

from dataclasses import dataclass

from lerobot.configs import NormalizationMode, PreTrainedConfig
from lerobot.policies.act.configuration_act import ACTConfig
from lerobot.utils.constants import OBS_ENV_STATE


@PreTrainedConfig.register_subclass("pose_act")
@dataclass
class PoseACTConfig(ACTConfig):
    # The pose the estimator regresses (observation.environment_state: position and quaternion).
    pose_dim: int = 7
    # The estimator: channels of its convolutions and keypoints per camera.
    estimator_channels: int = 32
    estimator_keypoints: int = 32
    estimator_hidden: int = 256
    # Whether the estimator's head reads the joints (normalized) beside the cameras' keypoints.
    estimator_reads_joints: bool = True
    # The least standard deviation the pose is normalized by (m for the position, 1 for the
    # quaternion): a component that barely varies (the quaternion's tilt while the cube lies flat)
    # would otherwise turn its last tenth of a millimetre of jitter into the estimator's largest error.
    pose_std_floor: float = 0.02
    # The estimator learns the cube's position relative to the gripper (the cube's minus the forward
    # kinematics' of the joints): a fixed camera that stands a centimetre off or sees a few degrees
    # wider moves the gripper and the cube in its picture alike, so their offset survives what the
    # cameras' randomization changes, and it is read most precisely where precision counts, as the
    # gripper closes on the cube. Its unit is this many metres: at a centimetre the errors that
    # matter (millimetres to centimetres) lie in the Huber loss's linear part, whose gradient does
    # not fade as they shrink; at 0.1 m they sat in its quadratic part and the estimator stalled
    # (13.5 mm held-out error against 9.8 mm in the same 6 minutes, docs/benchmarks.md).
    relative_scale: float = 0.01
    # The estimator's learning rate (ACT's is optimizer_lr, or the recipe's): a CNN from scratch
    # learns faster than the transformer's 1e-4 allows in the recipe's steps.
    estimator_lr: float = 5e-4
    # Weight of the estimator's Huber loss (normalized units) beside ACT's L1 loss.
    pose_loss_weight: float = 1.0
    # Weight of the orientation's part of that loss against the position's: the grasp needs the
    # position to millimetres, the wrist's roll only to a few degrees.
    orientation_loss_weight: float = 0.4
    # Standard deviation of the noise on the recorded pose ACT learns from (normalized units).
    pose_input_noise: float = 0.05
    # Share of each batch whose ACT input is the estimator's own estimate, from warm-up on.
    estimated_pose_share: float = 0.5
    estimator_warmup_steps: int = 500

    def __post_init__(self):
        super().__post_init__()
        if not 0.0 <= self.estimated_pose_share <= 1.0:
            raise ValueError(f"estimated_pose_share {self.estimated_pose_share}: a share between 0 and 1")
        if NormalizationMode(self.normalization_mapping.get("STATE")) is not NormalizationMode.MEAN_STD:
            raise ValueError("pose_act finds the gripper from the joints normalized by mean and std (STATE: MEAN_STD)")
        if self.pose_dim < 3 or self.estimator_channels <= 0 or self.estimator_keypoints <= 0:
            raise ValueError("pose_dim (at least the position), estimator_channels and estimator_keypoints must be positive")

    def validate_features(self) -> None:
        """Cameras are the inputs; the dataset's environment state, if the features carry it, is
        taken out of them: it is what the estimator learns, not something a policy is given."""
        if not self.image_features:
            raise ValueError("pose_act reads the cube's pose from cameras: the dataset has none (record demos with --cameras)")
        pose = self.input_features.pop(OBS_ENV_STATE, None)
        if pose is not None and tuple(pose.shape) != (self.pose_dim,):
            raise ValueError(f"{OBS_ENV_STATE} has shape {pose.shape}, pose_dim is {self.pose_dim}")

    def act_config(self) -> ACTConfig:
        """The state ACT's configuration: this one's ACT settings, the joints and a pose as inputs."""
        from dataclasses import fields

        from lerobot.configs import FeatureType, PolicyFeature
        from lerobot.utils.constants import OBS_STATE

        settings = {f.name: getattr(self, f.name) for f in fields(ACTConfig) if f.init}
        settings["input_features"] = {
            OBS_STATE: self.input_features[OBS_STATE],
            OBS_ENV_STATE: PolicyFeature(type=FeatureType.ENV, shape=(self.pose_dim,)),
        }
        settings["output_features"] = dict(self.output_features)
        return ACTConfig(**settings)
