"""Reading recorder_node's episode bags: one directory per episode with metadata.yaml and its MCAP
file(s), read with the `mcap` and `mcap-ros2-support` packages. The layout's rules are
so101_core::episode_bag's (names and keys from so101.contract; both tested against
tests/fixtures/episode_bags.txt).

Camera frames are read twice, never all at once: `read_episode` goes through the files keeping
every stream's times and the small values (joint states, commands, cube pose, reward, success),
but of each camera frame only a reference (its place in the file, its size); `camera_frames` then
goes through the files again and hands out the frames the converter asks for, frame after frame,
holding only those still to be handed out. Memory does not grow with the episode's length.
Cameras may be recorded raw (sensor_msgs/Image on /camera/NAME/image_raw) or compressed
(sensor_msgs/CompressedImage, JPEG or PNG, on /camera/NAME/image_raw/compressed, the default of
so101-launch); a camera recorded both ways is read raw."""

from __future__ import annotations

import json
import logging
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import yaml

from .. import contract
from ..messages import cube_pose_vector, image_size, joint_positions, stamp_seconds
from .commands import CommandError, obeyed_targets, targets_from_array, targets_from_joint_state

log = logging.getLogger(__name__)


class BagError(Exception):
    """An episode that cannot be converted, and why."""


@dataclass
class Stream:
    """Messages of one topic: sim times (s) and values, in time order."""

    times: list[float] = field(default_factory=list)
    values: list = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class FrameRef:
    """One camera frame of a bag, not decoded: its place among its topic's messages in the order
    the files are read, and its size."""

    ordinal: int
    width: int
    height: int


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
    # Per camera: the frames' stamps and FrameRefs (camera_frames decodes them).
    cameras: dict[str, Stream]
    # Per camera: the topic its frames come from (raw or compressed).
    camera_topics: dict[str, str] = field(default_factory=dict)
    # The episode's MCAP files, in the order they are read.
    files: list[Path] = field(default_factory=list)
    # Command messages the nodes would have rejected (so101.dataset.commands), with the first reasons.
    rejected_commands: int = 0
    rejection_reasons: list[str] = field(default_factory=list)
    # What the sim simulated the episode with (/sim/episode: servo model, randomization and its
    # draw); None on the real arm or for a bag without it.
    simulation: dict | None = None
    # What was recovered rather than read as recorded: a recording cut short (no metadata.yaml),
    # a file cut short (read up to the cut).
    notes: list[str] = field(default_factory=list)


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


# The first bytes of every MCAP file.
MCAP_MAGIC = b"\x89MCAP0\r\n"


@dataclass
class ReadReport:
    """What a read of an episode's files met besides the messages: files cut short (what preceded
    the cut was read) and every topic found, with its encoding (to name a foreign recording)."""

    notes: list[str] = field(default_factory=list)
    topics: dict[str, str] = field(default_factory=dict)

    def foreign_topics(self) -> str:
        """The topics found, for the reason an episode lacks what the converter reads."""
        if not self.topics:
            return "its files hold no message"
        found = sorted(self.topics.items())
        listed = ", ".join(f"{topic} ({encoding})" for topic, encoding in found[:6])
        more = f" and {len(found) - 6} more" if len(found) > 6 else ""
        return f"its files hold {listed}{more}"


def _messages(files: list[Path], report: ReadReport | None = None) -> Iterator[tuple[Path, str, object, object]]:
    """(file, topic, MCAP message record, decode) of every message of `files`, file after file, each in
    log-time order when the file is indexed (a heap over its chunks: one chunk or so in memory) and
    in stored order when it is not (ordering an unindexed file would load it whole); `decode(record)`
    gives the ROS message. Both passes of an episode read it so, in the same order.
    A file cut short (a recorder killed mid-write: no summary, a record cut in the middle) is read
    in stored order up to the cut, each of its complete chunks whole; the cut is noted in `report`.
    A file that is no MCAP at all is a BagError."""
    from mcap.reader import NonSeekingReader, make_reader
    from mcap_ros2.decoder import DecoderFactory

    for file in files:
        with open(file, "rb") as stream:
            start = stream.read(len(MCAP_MAGIC))
            if start != MCAP_MAGIC:
                raise BagError(f"{file.parent.name}: {file.name} is not an MCAP file (it starts with {start!r})")
            stream.seek(0)
            try:
                summary = make_reader(stream).get_summary()
            except Exception:  # noqa: BLE001 - no readable summary: the file is read as a stream
                summary = None
            indexed = summary is not None and len(summary.chunk_indexes) > 0
            stream.seek(0)
            if indexed:
                records = make_reader(stream).iter_messages(log_time_order=True)
            else:
                records = NonSeekingReader(stream).iter_messages(log_time_order=False)
            factory = DecoderFactory()  # per file: schema ids are the file's own
            decoders: dict[int, object] = {}
            read = 0
            while True:
                try:
                    schema, channel, record = next(records)
                except StopIteration:
                    break
                except Exception as error:
                    if indexed:
                        raise
                    if report is not None:
                        report.notes.append(
                            f"{file.parent.name}: {file.name} is cut short after {read} message(s) "
                            f"({' '.join(str(error).split()) or type(error).__name__}); what precedes the cut is read"
                        )
                    break
                read += 1
                if report is not None and channel.topic not in report.topics:
                    schema_encoding = schema.encoding if schema is not None else "no schema"
                    report.topics[channel.topic] = f"{channel.message_encoding or 'no encoding'}, {schema_encoding}"
                decoder = decoders.get(channel.id)
                if decoder is None:
                    decoder = factory.decoder_for(channel.message_encoding, schema)
                    if decoder is None:
                        continue  # not CDR with a ros2msg schema: nothing the converter reads
                    decoders[channel.id] = decoder
                yield file, channel.topic, record, decoder


def camera_of(topic: str) -> tuple[str, bool] | None:
    """(camera name, compressed) of a camera frame topic (/camera/NAME/image_raw or
    /camera/NAME/image_raw/compressed, under any namespace), None for other topics."""
    for leaf, compressed in ((contract.IMAGE_COMPRESSED, True), (contract.IMAGE_RAW, False)):
        if topic.endswith("/" + leaf):
            parts = topic[: -len(leaf) - 1].split("/")
            if len(parts) >= 2 and parts[-2] == contract.CAMERA_PREFIX and parts[-1]:
                return parts[-1], compressed
    return None


def read_episode(path: Path, cameras: list[str] | None) -> Episode:
    """Everything of one episode the converter uses, in sim time, camera frames as FrameRefs
    (camera_frames decodes them). An episode that was not closed (no metadata.yaml: the recorder
    was killed) is read from its MCAP files, each up to where it was cut, its task and verdict
    unknown (Episode.notes says so). Raises BagError for malformed metadata, a file that is no
    MCAP or cannot be read, one that misses a stream (naming the topics it holds instead), or a
    camera frame that cannot be decoded (an unknown encoding or format, data that is no image) or
    that changes size."""
    metadata_file = path / contract.EPISODE_METADATA_FILE
    report = ReadReport()
    if metadata_file.is_file():
        custom, files = _metadata(path, metadata_file)
    else:
        custom, files = {}, mcap_files(path) if path.is_dir() else []
        if not files:
            raise BagError(f"{path.name}: no metadata.yaml and no MCAP file")
        report.notes.append(
            f"{path.name}: no metadata.yaml (the recording was cut short): read from "
            f"{', '.join(file.name for file in files)}; its task and verdict are unknown"
        )
    episode = _read_files(path, files, cameras, report)
    return replace(
        episode,
        task=str(custom.get(contract.CUSTOM_TASK) or ""),
        success=success_of(custom),
        seed=str(custom.get(contract.CUSTOM_SEED, "")),
        simulation=simulation_settings(path, custom),
    )


def success_of(custom: dict) -> bool | None:
    """An episode's verdict from its metadata's custom_data; None when it holds none."""
    return {"true": True, "false": False}.get(str(custom.get(contract.CUSTOM_SUCCESS, "")).lower())


def episode_verdict(path: Path) -> bool | None:
    """The verdict a closed episode's metadata.yaml records (None when it holds none). Raises
    BagError for a missing, unreadable or malformed file."""
    return success_of(_metadata(path, path / contract.EPISODE_METADATA_FILE)[0])


def _metadata(path: Path, metadata_file: Path) -> tuple[dict, list[Path]]:
    """(custom_data, the MCAP files it lists) of a closed episode's metadata.yaml."""
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
    return custom, files


def _read_files(path: Path, files: list[Path], cameras: list[str] | None, report: ReadReport) -> Episode:
    """The episode's streams out of `files` (read_episode's first pass), without its metadata."""

    raw_states: list[tuple[float, float, np.ndarray]] = []  # (receive time, stamp, positions)
    # (receive time, topic order, targets or the reason the nodes reject the message, stamp: 0 for none)
    raw_commands: list[tuple[float, int, object, float]] = []
    raw_reward: list[tuple[float, float]] = []
    raw_success: list[tuple[float, bool]] = []
    raw_cube: list[tuple[float, np.ndarray]] = []
    # Per camera topic: (stamp, FrameRef) in the order read.
    raw_images: dict[str, list[tuple[float, FrameRef]]] = {}
    file = files[0]  # the one being read, for the error message
    try:
        for in_file, topic, record, decode in _messages(files, report):
            file = in_file
            received = record.log_time * 1e-9
            camera = camera_of(topic)
            if camera is not None:
                if cameras is not None and camera[0] not in cameras:
                    continue
                frames = raw_images.setdefault(topic, [])
                ros = decode(record.data)
                try:
                    width, height = image_size(ros)
                except ValueError as error:
                    raise BagError(f"{path.name}: {topic}: {error}") from error
                if frames and (frames[0][1].width, frames[0][1].height) != (width, height):
                    first = frames[0][1]
                    raise BagError(
                        f"{path.name}: camera {camera[0]!r} changed size from {first.width}x{first.height} "
                        f"to {width}x{height} at t={stamp_seconds(ros):.3f} s"
                    )
                frames.append((stamp_seconds(ros), FrameRef(len(frames), width, height)))
            elif topic.endswith("/" + contract.JOINT_STATES) and not topic.endswith(contract.LEADER_JOINT_STATES):
                ros = decode(record.data)
                positions = joint_positions(ros)
                if positions is not None:
                    raw_states.append((received, stamp_seconds(ros), positions))
            elif topic.endswith("/" + contract.JOINT_COMMANDS) or topic.endswith("/" + contract.FORWARD_POSITION_COMMANDS):
                ros = decode(record.data)
                # A node drains /joint_commands before the array topic in each tick.
                array = topic.endswith("/" + contract.FORWARD_POSITION_COMMANDS)
                try:
                    if array:
                        targets = targets_from_array(list(ros.data))
                    else:
                        targets = targets_from_joint_state(list(ros.name), list(ros.position))
                except CommandError as error:
                    targets = f"{topic}: {error}"
                raw_commands.append((received, int(array), targets, 0.0 if array else stamp_seconds(ros)))
            elif topic.endswith("/" + contract.TASK_REWARD):
                raw_reward.append((received, float(decode(record.data).data)))
            elif topic.endswith("/" + contract.TASK_SUCCESS):
                raw_success.append((received, bool(decode(record.data).data)))
            elif topic.endswith("/" + contract.CUBE_POSE):
                ros = decode(record.data)
                raw_cube.append((stamp_seconds(ros), cube_pose_vector(ros.pose)))
    except BagError:
        raise
    except Exception as error:  # noqa: BLE001 - a damaged file is reported, not fatal
        raise BagError(f"{path.name}: cannot read {file.name} ({type(error).__name__}: {error})") from error

    cut = "".join(f"; {note.removeprefix(path.name + ': ')}" for note in report.notes)
    if len(raw_states) < 2:
        raise BagError(f"{path.name}: no /joint_states (observation.state); {report.foreign_topics()}{cut}")
    raw_commands.sort(key=lambda entry: (entry[0], entry[1]))
    accepted = [(t, c, stamp) for t, _, c, stamp in raw_commands if not isinstance(c, str)]
    reasons = [c for _, _, c, _ in raw_commands if isinstance(c, str)]
    if not accepted:
        detail = f" ({len(reasons)} rejected, e.g. {reasons[0]})" if reasons else ""
        raise BagError(f"{path.name}: no valid /joint_commands or /forward_position_controller/commands (action){detail}{cut}")
    # One topic per camera: the raw one where a camera was recorded both ways (lossless).
    camera_topics: dict[str, str] = {}
    for topic in sorted(raw_images, key=lambda topic: camera_of(topic)[1]):
        camera_topics.setdefault(camera_of(topic)[0], topic)
    for name in cameras or []:
        if name not in camera_topics:
            raise BagError(f"{path.name}: no frames of camera {name!r}")

    from .resample import WallToSim, command_times

    to_sim = WallToSim([r for r, _, _ in raw_states], [s for _, s, _ in raw_states])

    def stream(pairs: list[tuple[float, object]], stamped: bool = False) -> Stream:
        pairs = sorted(pairs, key=lambda pair: pair[0])
        times = [t for t, _ in pairs] if stamped else list(to_sim([t for t, _ in pairs]))
        return Stream(times=times, values=[v for _, v in pairs])

    # The robot held its measured position until the first command (so101.dataset.commands).
    raw_states.sort(key=lambda entry: entry[1])
    placed = command_times(
        to_sim([t for t, _, _ in accepted]), np.array([stamp for _, _, stamp in accepted]), [s for _, s, _ in raw_states]
    )
    first_command = float(placed[0])
    held = [p for _, s, p in raw_states if s <= first_command + 1e-9] or [raw_states[0][2]]
    targets = obeyed_targets([c for _, c, _ in accepted], held[-1])

    return Episode(
        path=path,
        task="",
        success=None,
        seed="",
        joint_states=stream([(s, p) for _, s, p in raw_states], stamped=True),
        joint_commands=stream(list(zip(placed.tolist(), targets)), stamped=True),
        reward=stream(raw_reward),
        task_success=stream(raw_success),
        cube_pose=stream(raw_cube, stamped=True),
        cameras={name: stream(raw_images[topic], stamped=True) for name, topic in sorted(camera_topics.items())},
        camera_topics=dict(sorted(camera_topics.items())),
        files=files,
        rejected_commands=len(reasons),
        rejection_reasons=reasons[:3],
        notes=report.notes,
    )


def camera_frames(episode: Episode, plan: dict[str, list[FrameRef]]) -> Iterator[dict[str, object]]:
    """The ROS messages (Image or CompressedImage, not decoded into pixels) of the frames `plan`
    names, frame after frame: for frame k, {camera: the message of plan[camera][k]}. The episode's
    files are read once more, in read_episode's order; a message is kept from where it is read
    until the last frame that uses it has been handed out, so memory holds the frames of about one
    instant (more only where one camera's frames were received far behind another's). Raises
    BagError when a planned frame is not found (the files changed since read_episode)."""
    count = len(next(iter(plan.values()), []))
    if not count:
        return
    wanted = {episode.camera_topics[name]: name for name in plan}
    # The last frame that uses each planned message, per camera.
    last_use = {name: {} for name in plan}
    for name, refs in plan.items():
        for k, ref in enumerate(refs):
            last_use[name][ref.ordinal] = k
    held: dict[str, dict[int, object]] = {name: {} for name in plan}
    ordinals = dict.fromkeys(plan, 0)
    k = 0
    for _file, topic, record, decode in _messages(episode.files):
        name = wanted.get(topic)
        if name is None:
            continue
        ordinal = ordinals[name]
        ordinals[name] += 1
        if ordinal in last_use[name]:
            held[name][ordinal] = decode(record.data)
        while k < count and all(plan[n][k].ordinal in held[n] for n in plan):
            yield {n: held[n][plan[n][k].ordinal] for n in plan}
            for n in plan:
                ordinal = plan[n][k].ordinal
                if last_use[n][ordinal] == k:
                    del held[n][ordinal]
            k += 1
        if k == count:
            return
    raise BagError(f"{episode.path.name}: {count - k} planned camera frame(s) not found on the second read")


def simulation_settings(path: Path, custom: dict) -> dict | None:
    """The episode's custom_data `simulation` (JSON), or None when absent or unreadable (a
    warning: the episode itself is still good)."""
    text = str(custom.get(contract.CUSTOM_SIMULATION) or "")
    if not text:
        return None
    try:
        settings = json.loads(text)
    except json.JSONDecodeError as error:
        log.warning("%s: the simulation settings in metadata.yaml are not JSON (%s); left out", path.name, error)
        return None
    return settings if isinstance(settings, dict) else None
