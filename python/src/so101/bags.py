"""Reading recorder_node's episode bags: one directory per episode with metadata.yaml and its MCAP
file(s), read with the `mcap` and `mcap-ros2-support` packages. The layout's rules are
so101_core::episode_bag's (names and keys from so101.contract; both tested against
tests/fixtures/episode_bags.txt)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from . import contract
from .commands import CommandError, obeyed_targets, targets_from_array, targets_from_joint_state
from .messages import cube_pose_vector, joint_positions, rgb_image


class BagError(Exception):
    """An episode that cannot be converted, and why."""


@dataclass
class Stream:
    """Messages of one topic: sim times (s) and values, in time order."""

    times: list[float] = field(default_factory=list)
    values: list = field(default_factory=list)


@dataclass
class Episode:
    path: Path
    task: str
    success: bool | None
    seed: str
    joint_states: Stream
    joint_commands: Stream
    reward: Stream
    task_success: Stream
    # The cube's pose from /cube/pose, stamped: float64[7] position (m) and orientation (w x y z),
    # world frame (empty when the bag has no /cube/pose).
    cube_pose: Stream
    cameras: dict[str, Stream]
    # Command messages the nodes would have rejected (so101.commands), with the first reasons.
    rejected_commands: int = 0
    rejection_reasons: list[str] = field(default_factory=list)


def _split_number(path: Path) -> int | None:
    _, _, split = path.stem.rpartition("_")
    return int(split) if split.isdigit() else None


def mcap_files(directory: Path) -> list[Path]:
    """The MCAP files in `directory`, in split order (_0, _1, ..., _10; others after, by name)."""
    files = [p for p in directory.iterdir() if p.is_file() and p.suffix == ".mcap"]
    return sorted(files, key=lambda p: (_split_number(p) is None, _split_number(p) or 0, p.name))


def is_episode_dir(directory: Path) -> bool:
    """A metadata.yaml or an MCAP file in it (an episode cut short has no metadata.yaml yet)."""
    return (directory / contract.EPISODE_METADATA_FILE).is_file() or (directory.is_dir() and bool(mcap_files(directory)))


def _has_episode_name(directory: Path) -> bool:
    prefix, _, index = directory.name.rpartition("_")
    return bool(prefix) and len(index) >= 6 and index.isdigit()


def episode_dirs(paths: list[Path]) -> list[Path]:
    """The episodes meant by `paths`: each path that is an episode itself, and the episode
    directories named <prefix>_<index> inside each of the others, in name order; in the order the
    paths were given. A path that does not exist is a BagError."""
    found: list[Path] = []
    for path in paths:
        if is_episode_dir(path):
            found.append(path)
        elif path.is_dir():
            found.extend(sorted(p for p in path.iterdir() if p.is_dir() and _has_episode_name(p) and is_episode_dir(p)))
        else:
            raise BagError(f"{path}: neither an episode directory nor a directory of episodes")
    return found


def _stamp(header) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def read_episode(path: Path, cameras: list[str] | None) -> Episode:
    """Everything of one episode the converter uses, in sim time. Raises BagError for an episode
    that was not closed (no metadata.yaml: the recorder was killed), an unreadable file, or one
    that misses a stream."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    metadata_file = path / contract.EPISODE_METADATA_FILE
    if not metadata_file.is_file():
        raise BagError(f"{path.name}: no metadata.yaml (the recording was cut short); its bag may be truncated")
    try:
        info = yaml.safe_load(metadata_file.read_text())["rosbag2_bagfile_information"]
    except Exception as error:  # noqa: BLE001 - any malformed file is reported the same way
        raise BagError(
            f"{path.name}: unreadable metadata.yaml ({type(error).__name__}: {' '.join(str(error).split())})"
        ) from error
    if not isinstance(info, dict):
        raise BagError(f"{path.name}: malformed metadata.yaml (rosbag2_bagfile_information is not a mapping)")
    custom = info.get("custom_data") or {}
    if not isinstance(custom, dict):
        raise BagError(f"{path.name}: malformed metadata.yaml (custom_data is not a mapping)")
    relative = info.get("relative_file_paths")
    if not isinstance(relative, list) or not all(isinstance(entry, str) for entry in relative):
        raise BagError(f"{path.name}: malformed metadata.yaml (relative_file_paths is not a list of file names)")
    files = [path / entry for entry in relative]
    if not files or not all(f.is_file() for f in files):
        raise BagError(f"{path.name}: metadata.yaml lists files that are missing: {files}")

    raw_states: list[tuple[float, float, np.ndarray]] = []  # (receive time, stamp, positions)
    # (receive time, topic order, targets or the reason the nodes reject the message)
    raw_commands: list[tuple[float, int, object]] = []
    raw_reward: list[tuple[float, float]] = []
    raw_success: list[tuple[float, bool]] = []
    raw_cube: list[tuple[float, np.ndarray]] = []
    raw_images: dict[str, list[tuple[float, np.ndarray]]] = {}
    for file in files:
        try:
            with open(file, "rb") as stream:
                reader = make_reader(stream, decoder_factories=[DecoderFactory()])
                for _schema, channel, message, ros in reader.iter_decoded_messages(log_time_order=True):
                    received = message.log_time * 1e-9
                    topic = channel.topic
                    if topic.endswith("/" + contract.JOINT_STATES) and not topic.endswith(contract.LEADER_JOINT_STATES):
                        positions = joint_positions(ros)
                        if positions is not None:
                            raw_states.append((received, _stamp(ros.header), positions))
                    elif topic.endswith("/" + contract.JOINT_COMMANDS) or topic.endswith(
                        "/" + contract.FORWARD_POSITION_COMMANDS
                    ):
                        # A node drains /joint_commands before the array topic in each tick.
                        array = topic.endswith("/" + contract.FORWARD_POSITION_COMMANDS)
                        try:
                            if array:
                                targets = targets_from_array(list(ros.data))
                            else:
                                targets = targets_from_joint_state(list(ros.name), list(ros.position))
                        except CommandError as error:
                            targets = f"{topic}: {error}"
                        raw_commands.append((received, int(array), targets))
                    elif topic.endswith("/" + contract.TASK_REWARD):
                        raw_reward.append((received, float(ros.data)))
                    elif topic.endswith("/" + contract.TASK_SUCCESS):
                        raw_success.append((received, bool(ros.data)))
                    elif topic.endswith("/" + contract.CUBE_POSE):
                        raw_cube.append((_stamp(ros.header), cube_pose_vector(ros.pose)))
                    elif f"/{contract.CAMERA_PREFIX}/" in topic and topic.endswith("/" + contract.IMAGE_RAW):
                        name = topic.rstrip("/").split("/")[-2]
                        if cameras is not None and name not in cameras:
                            continue
                        try:
                            image = rgb_image(ros)
                        except ValueError as error:
                            raise BagError(f"{path.name}: {topic}: {error}") from error
                        frames = raw_images.setdefault(name, [])
                        if frames and frames[0][1].shape != image.shape:
                            first, now = frames[0][1].shape, image.shape
                            raise BagError(
                                f"{path.name}: camera {name!r} changed size from {first[1]}x{first[0]} "
                                f"to {now[1]}x{now[0]} at t={_stamp(ros.header):.3f} s"
                            )
                        frames.append((_stamp(ros.header), image))
        except BagError:
            raise
        except Exception as error:  # noqa: BLE001 - a damaged file is reported, not fatal
            raise BagError(f"{path.name}: cannot read {file.name} ({type(error).__name__}: {error})") from error

    if len(raw_states) < 2:
        raise BagError(f"{path.name}: no /joint_states (observation.state)")
    raw_commands.sort(key=lambda entry: (entry[0], entry[1]))
    accepted = [(t, c) for t, _, c in raw_commands if not isinstance(c, str)]
    reasons = [c for _, _, c in raw_commands if isinstance(c, str)]
    if not accepted:
        detail = f" ({len(reasons)} rejected, e.g. {reasons[0]})" if reasons else ""
        raise BagError(f"{path.name}: no valid /joint_commands or /forward_position_controller/commands (action){detail}")
    for name in cameras or []:
        if not raw_images.get(name):
            raise BagError(f"{path.name}: no frames of camera {name!r}")

    from .resample import WallToSim

    to_sim = WallToSim([r for r, _, _ in raw_states], [s for _, s, _ in raw_states])

    def stream(pairs: list[tuple[float, object]], stamped: bool = False) -> Stream:
        pairs = sorted(pairs, key=lambda pair: pair[0])
        times = [t for t, _ in pairs] if stamped else list(to_sim([t for t, _ in pairs]))
        return Stream(times=times, values=[v for _, v in pairs])

    # The robot held its measured position until the first command (so101.commands).
    raw_states.sort(key=lambda entry: entry[1])
    first_command = float(to_sim([accepted[0][0]])[0])
    held = [p for _, s, p in raw_states if s <= first_command + 1e-9] or [raw_states[0][2]]
    targets = obeyed_targets([c for _, c in accepted], held[-1])

    success_text = str(custom.get(contract.CUSTOM_SUCCESS, "")).lower()
    return Episode(
        path=path,
        task=str(custom.get(contract.CUSTOM_TASK) or ""),
        success={"true": True, "false": False}.get(success_text),
        seed=str(custom.get(contract.CUSTOM_SEED, "")),
        joint_states=stream([(s, p) for _, s, p in raw_states], stamped=True),
        joint_commands=stream([(t, target) for (t, _), target in zip(accepted, targets)]),
        reward=stream(raw_reward),
        task_success=stream(raw_success),
        cube_pose=stream(raw_cube, stamped=True),
        cameras={name: stream(frames, stamped=True) for name, frames in sorted(raw_images.items())},
        rejected_commands=len(reasons),
        rejection_reasons=reasons[:3],
    )
