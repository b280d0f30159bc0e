"""A LeRobot policy (a local checkpoint or a Hub id) behind the stack's units: joint positions in
radians and RGB frames in, joint targets in radians out. The policy's own pre- and post-processors
(normalization, device) run as lerobot-train saved them; this module only maps the stack's values
onto the policy's features and back. A policy that acts in end-effector space (so101.ee; trained on
a dataset converted with --action-space ee, which gives it observation.ee_state) gets its targets
turned into joint targets by the core's IK here, so every caller drives joints the same way;
which actions a policy gives is read from its training dataset's action names where that dataset
is on this machine (detected_action_space)."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..ee import EeCommander, checked_action_space, ee_from_lerobot_ee, ee_poses, lerobot_ee_from_ee
from ..units import lerobot_from_radians, radians_from_lerobot

STATE = "observation.state"
ENVIRONMENT_STATE = "observation.environment_state"  # the cube's pose (so101.dataset.convert)
ENVIRONMENT_STATE_SIZE = 7
EE_STATE = "observation.ee_state"  # the end-effector state (so101.ee; the converter's --action-space ee)
IMAGE_PREFIX = "observation.images."
log = logging.getLogger(__name__)


class PolicyError(Exception):
    """A policy this stack cannot drive the arm with, and why."""


@dataclass(frozen=True)
class CameraInput:
    """One camera the policy looks at: its name (observation.images.<name>) and frame size."""

    name: str
    height: int
    width: int


def pick_device(requested: str | None) -> str:
    """The torch device: the requested one, else CUDA when there is one, else the CPU."""
    import torch

    if requested:
        return requested
    return "cuda" if torch.cuda.is_available() else "cpu"


class StackPolicy:
    """Loads the policy and runs one inference per control period (select_action: chunking
    policies such as ACT answer from their action queue in between)."""

    def __init__(
        self, source: str, units: str = "lerobot", device: str | None = None, task: str = "", action_space: str = "auto"
    ):
        from lerobot.configs import FeatureType, PreTrainedConfig
        from lerobot.policies.factory import get_policy_class, make_pre_post_processors

        if units not in ("lerobot", "radians"):
            raise PolicyError(f"units {units!r}: lerobot or radians")
        self.units, self.task, self.device = units, task, pick_device(device)
        try:
            config = PreTrainedConfig.from_pretrained(source)
        except Exception as error:  # noqa: BLE001 - a missing file and a bad Hub id read the same to a user
            raise PolicyError(f"cannot load a LeRobot policy config from {source!r} ({type(error).__name__}: {error})") from error
        config.pretrained_path = Path(source) if Path(source).exists() else source
        config.device = self.device
        try:
            self.policy = get_policy_class(config.type).from_pretrained(source, config=config)
            overrides = {"device_processor": {"device": self.device}}
            self.preprocessor, self.postprocessor = make_pre_post_processors(
                config, pretrained_path=source, preprocessor_overrides=overrides
            )
        except Exception as error:  # noqa: BLE001 - missing weights or processors, a bad file
            raise PolicyError(f"cannot load the {config.type} policy of {source!r} ({type(error).__name__}: {error})") from error
        self.policy.eval()
        self.config = config

        inputs = config.input_features
        if STATE not in inputs or tuple(inputs[STATE].shape) != (6,):
            raise PolicyError(f"the policy's {STATE} is {inputs.get(STATE)}, not the six joint positions")
        action = config.output_features.get("action")
        if action is None or tuple(action.shape) != (6,):
            raise PolicyError(f"the policy's action is {action}, not six joint targets")
        visual = [key for key, feature in inputs.items() if feature.type is FeatureType.VISUAL]
        if unnamed := [key for key in visual if not key.startswith(IMAGE_PREFIX)]:
            raise PolicyError(f"the policy's images {unnamed} are not observation.images.<camera>")
        self.cameras = [
            CameraInput(key.removeprefix(IMAGE_PREFIX), int(inputs[key].shape[1]), int(inputs[key].shape[2])) for key in visual
        ]
        self.needs_environment_state = ENVIRONMENT_STATE in inputs
        if self.needs_environment_state and tuple(inputs[ENVIRONMENT_STATE].shape) != (ENVIRONMENT_STATE_SIZE,):
            raise PolicyError(f"the policy's {ENVIRONMENT_STATE} is {inputs[ENVIRONMENT_STATE]}, not the cube's pose (7 values)")
        self.needs_ee_state = EE_STATE in inputs
        if self.needs_ee_state and tuple(inputs[EE_STATE].shape) != (6,):
            raise PolicyError(f"the policy's {EE_STATE} is {inputs[EE_STATE]}, not the end-effector state (6 values)")
        if action_space == "auto":
            action_space = detected_action_space(source, self.needs_ee_state)
        try:
            self.action_space = checked_action_space(action_space)
        except ValueError as error:
            raise PolicyError(str(error)) from None
        self._commander: EeCommander | None = None  # started from the first observation of an episode
        self._positions: np.ndarray | None = None
        self.ee_steps = self.ee_clamped = 0  # end-effector targets turned into joints, and how many out of reach
        known = (STATE, ENVIRONMENT_STATE, EE_STATE)
        others = [key for key, feature in inputs.items() if key not in known and feature.type is not FeatureType.VISUAL]
        if others:
            raise PolicyError(f"the policy needs inputs the stack does not provide: {others}")
        log.info(
            "policy %s (%s, %s actions) on %s, cameras %s",
            source,
            config.type,
            self.action_space,
            self.device,
            ", ".join(f"{c.name} {c.width}x{c.height}" for c in self.cameras) or "none",
        )

    def reset(self) -> None:
        """Before each episode: clears the policy's action queue and observation history."""
        self.policy.reset()
        self.preprocessor.reset()
        self.postprocessor.reset()
        self._commander = None

    def observation(
        self, positions: np.ndarray, images: dict[str, np.ndarray], cube_pose: np.ndarray | None = None
    ) -> dict[str, np.ndarray]:
        """The policy's observation from joint positions (rad, contract order), HxWx3 uint8 frames
        by camera name (frames of another size are resized to the policy's) and, for a policy
        that takes the environment state, the cube's pose [x y z qw qx qy qz] (m, world frame)."""
        self._positions = np.asarray(positions, dtype=np.float64)
        state = lerobot_from_radians(positions) if self.units == "lerobot" else self._positions
        observation = {STATE: state.astype(np.float32)}
        if self.needs_ee_state:
            ee_state = ee_poses(self._positions)
            observation[EE_STATE] = (lerobot_ee_from_ee(ee_state) if self.units == "lerobot" else ee_state).astype(np.float32)
        if self.needs_environment_state:
            if cube_pose is None:
                raise PolicyError(f"the policy takes {ENVIRONMENT_STATE} (the cube's pose) and none was given")
            observation[ENVIRONMENT_STATE] = np.asarray(cube_pose, dtype=np.float32)
        for camera in self.cameras:
            frame = images[camera.name]
            if frame.shape[:2] != (camera.height, camera.width):
                frame = resize(frame, camera.height, camera.width)
            observation[IMAGE_PREFIX + camera.name] = frame
        return observation

    def act(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        """Joint targets (rad, contract order) for the observation."""
        import torch
        from lerobot.common.control_utils import predict_action

        action = predict_action(
            observation,
            self.policy,
            torch.device(self.device),
            self.preprocessor,
            self.postprocessor,
            use_amp=False,
            task=self.task,
            robot_type="so_follower",
        )
        values = action.squeeze(0).to("cpu").numpy().astype(np.float64)
        if values.shape != (6,) or not np.all(np.isfinite(values)):
            raise PolicyError(f"the policy answered {values}, not six finite {self.action_space} targets")
        if self.action_space == "joint":
            return radians_from_lerobot(values) if self.units == "lerobot" else values
        return self._joint_targets(ee_from_lerobot_ee(values) if self.units == "lerobot" else values)

    def _joint_targets(self, ee_target: np.ndarray) -> np.ndarray:
        """An end-effector target -> joint targets by the IK, from the episode's first joints on."""
        if self._commander is None:
            self._commander = EeCommander()
            self._commander.reset(self._positions)
        steps = self._commander.step(ee_target)
        self.ee_steps += 1
        self.ee_clamped += int(steps.clamped[0])
        if steps.clamped[0]:
            log.debug(
                "end-effector target %s out of reach by %.3f m: the nearest pose commanded", ee_target, steps.position_error[0]
            )
        return steps.targets[0]


def detected_action_space(source: str, reads_ee_state: bool) -> str:
    """What the policy's actions are: the names of its training dataset's actions where the
    checkpoint's train_config.json leads to the dataset on this machine (`ee.*`: end-effector
    targets), else end-effector when it reads observation.ee_state (the converter's --action-space
    ee writes both), else joint targets."""
    import json

    try:
        dataset = json.loads((Path(source) / "train_config.json").read_text())["dataset"]
        info = json.loads((Path(dataset["root"]) / "meta" / "info.json").read_text())
        names = info["features"]["action"]["names"]
    except (OSError, KeyError, TypeError, ValueError):
        return "ee" if reads_ee_state else "joint"
    if all(str(name).startswith("ee.") for name in names):
        return "ee"
    if all(str(name).endswith(".pos") for name in names):
        return "joint"
    raise PolicyError(f"the policy's training actions {names} are neither joint nor end-effector targets")


def resize(frame: np.ndarray, height: int, width: int) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.fromarray(frame).resize((width, height), Image.BILINEAR))
