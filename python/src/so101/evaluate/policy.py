"""A LeRobot policy (a local checkpoint or a Hub id) behind the stack's units: joint positions in
radians and RGB frames in, joint targets in radians out. The policy's own pre- and post-processors
(normalization, device) run as lerobot-train saved them; this module only maps the stack's values
onto the policy's features and back. A policy that acts in end-effector space (so101.ee; trained on
a dataset converted with --action-space ee, which gives it observation.ee_state) gets its targets
turned into joint targets by the core's IK here, so every caller drives joints the same way;
which actions a policy gives is read from its training dataset's action names where that dataset
is on this machine (detected_action_space)."""

from __future__ import annotations

import importlib.util
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import contract
from ..ee import EeCommander, checked_action_space, ee_from_lerobot_ee, ee_poses, lerobot_ee_from_ee
from ..units import lerobot_from_radians, radians_from_lerobot

STATE = "observation.state"
ENVIRONMENT_STATE = "observation.environment_state"  # the cube's pose (so101.dataset.convert)
ENVIRONMENT_STATE_SIZE = 7
EE_STATE = "observation.ee_state"  # the end-effector state (so101.ee; the converter's --action-space ee)
IMAGE_PREFIX = "observation.images."
# Policies that take any subset of their image inputs (SmolVLA leaves one no camera feeds out, pi0
# pads it), at any size (they resize and pad each frame): the VLAs, pretrained on other cameras.
VLA_TYPES = ("smolvla", "pi0", "pi05")
log = logging.getLogger(__name__)


def vla_packages_missing(policy_type: str, command: str) -> str | None:
    """Why this environment cannot run a `policy_type` policy, or None: the VLAs need LeRobot's
    smolvla/pi extras (transformers), which the stack keeps in an environment of their own
    (.venv-vla) because LeRobot imports transformers at every start wherever it is installed."""
    if policy_type not in VLA_TYPES or importlib.util.find_spec("transformers") is not None:
        return None
    return (
        f"a {policy_type} policy needs transformers (LeRobot's smolvla/pi extras), which this environment "
        f"lacks: run it in the VLAs' environment (.venv-vla/bin/{command}; scripts/setup_python.sh makes it), "
        "or add them here (pip install -r python/requirements-vla.txt)"
    )


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

        from ..policies import pose_act  # noqa: F401 - registers the policy type pose_act with LeRobot

        if units not in ("lerobot", "radians"):
            raise PolicyError(f"units {units!r}: lerobot or radians")
        self.units, self.task, self.device = units, task, pick_device(device)
        try:
            config = PreTrainedConfig.from_pretrained(source)
        except Exception as error:  # noqa: BLE001 - a missing file and a bad Hub id read the same to a user
            raise PolicyError(f"cannot load a LeRobot policy config from {source!r} ({type(error).__name__}: {error})") from error
        if missing := vla_packages_missing(config.type, "so101-run-policy"):
            raise PolicyError(missing)
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
        self.cameras = camera_inputs(
            {key: tuple(inputs[key].shape) for key in visual},
            renamed_inputs(self.preprocessor),
            training_features(source),
            optional_images=config.type in VLA_TYPES,
        )
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

    def act_on_env(self, observation: dict) -> np.ndarray:
        """Joint targets for an observation of the Gymnasium envs (so101.envs: agent_pos,
        pixels by camera, environment_state)."""
        return self.act(
            self.observation(observation["agent_pos"], observation.get("pixels", {}), observation["environment_state"])
        )

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


# Written beside a VLA fine-tune's weights by so101-learn smolvla|pi0: its dataset's features, so
# the checkpoint knows its frame sizes wherever it goes (its train_config.json names a dataset
# that may not be on the machine that runs it).
DATASET_FEATURES_FILE = "dataset_features.json"


def training_features(source: str) -> dict | None:
    """The features of the dataset the policy was trained on: the checkpoint's own copy
    (DATASET_FEATURES_FILE), else the dataset its train_config.json leads to on this machine; None
    otherwise (a Hub id, a moved dataset)."""
    import json

    try:
        features = json.loads((Path(source) / DATASET_FEATURES_FILE).read_text())
    except (OSError, ValueError):
        try:
            dataset = json.loads((Path(source) / "train_config.json").read_text())["dataset"]
            features = json.loads((Path(dataset["root"]) / "meta" / "info.json").read_text())["features"]
        except (OSError, KeyError, TypeError, ValueError):
            return None
    return features if isinstance(features, dict) else None


def renamed_inputs(preprocessor) -> dict[str, str]:
    """Policy input -> the observation key it is fed from: the inverse of the rename map the
    policy was fine-tuned with (lerobot-train --rename_map, kept in its preprocessor), e.g.
    observation.images.camera1 <- observation.images.top for a VLA pretrained on other cameras."""
    from lerobot.processor.rename_processor import RenameObservationsProcessorStep

    renamed = {}
    for step in getattr(preprocessor, "steps", []):
        if isinstance(step, RenameObservationsProcessorStep):
            renamed.update({policy_key: given for given, policy_key in step.rename_map.items()})
    return renamed


def camera_inputs(
    visual: dict[str, tuple[int, ...]], renamed: dict[str, str], trained_on: dict | None, optional_images: bool
) -> list[CameraInput]:
    """The stack's cameras that feed the policy's images (`visual`: policy key -> (C, H, W)).

    A policy that needs every image (ACT, Diffusion: optional_images False) gets each camera under
    its input's name at its input's size, as its config says (lerobot-train filled both from the
    dataset). A VLA (optional_images) keeps its pretrained inputs (smolvla_base: camera1..3 at
    256x256) and resizes and pads whatever it gets: each input is fed by the camera the fine-tune
    renamed onto it, at the size of the fine-tuning dataset's frames where known (else the
    input's), and an input no camera feeds is left to the model (SmolVLA leaves it out, pi0 pads it)."""
    if not optional_images:
        if unnamed := [key for key in visual if not key.startswith(IMAGE_PREFIX)]:
            raise PolicyError(f"the policy's images {unnamed} are not observation.images.<camera>")
        return [CameraInput(key.removeprefix(IMAGE_PREFIX), int(shape[1]), int(shape[2])) for key, shape in visual.items()]
    cameras, unfed = [], []
    for key, shape in visual.items():
        given = renamed.get(key, key)
        name = given.removeprefix(IMAGE_PREFIX)
        if trained_on is not None:
            fed = given in trained_on
        else:  # fed where renamed or named as one of the stack's cameras
            fed = key in renamed or name in contract.CAMERA_NAMES
        if not fed or not given.startswith(IMAGE_PREFIX):
            unfed.append(key)
            continue
        if trained_on is not None:
            height, width = (int(v) for v in trained_on[given]["shape"][:2])  # LeRobot datasets: (H, W, C)
        else:
            height, width = int(shape[1]), int(shape[2])
            log.warning("%s: no record of the fine-tuning frames' size, frames go in at the input's %dx%d", key, width, height)
        cameras.append(CameraInput(name, height, width))
    if not cameras and visual:
        raise PolicyError(f"no camera of the stack feeds any of the policy's images {list(visual)}")
    if unfed:
        log.info("no camera feeds the policy's %s: left to the model", ", ".join(unfed))
    return cameras


def detected_action_space(source: str, reads_ee_state: bool) -> str:
    """What the policy's actions are: the names of its training dataset's actions where the
    checkpoint's train_config.json leads to the dataset on this machine (`ee.*`: end-effector
    targets), else end-effector when it reads observation.ee_state (the converter's --action-space
    ee writes both), else joint targets."""
    features = training_features(source)
    try:
        names = features["action"]["names"]
    except (KeyError, TypeError):
        return "ee" if reads_ee_state else "joint"
    if all(str(name).startswith("ee.") for name in names):
        return "ee"
    if all(str(name).endswith(".pos") for name in names):
        return "joint"
    raise PolicyError(f"the policy's training actions {names} are neither joint nor end-effector targets")


def resize(frame: np.ndarray, height: int, width: int) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.fromarray(frame).resize((width, height), Image.BILINEAR))
