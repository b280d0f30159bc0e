"""so101-bag-to-lerobot: recorder_node's episode bags -> a LeRobot dataset (codebase v3.0), written
through LeRobot's own LeRobotDataset API.

Per frame (docs/lerobot.md): observation.state (the arm's /joint_states), action (the target
the robot obeyed: /joint_commands and /forward_position_controller/commands validated, clamped and
merged as the nodes do, so101.dataset.commands), observation.environment_state (the cube's pose from /cube/pose: x y z
in m and the orientation quaternion w x y z, world frame; --no-environment-state leaves it out),
observation.images.<camera> (video), next.reward, next.success, and the episode's task. With
--action-space ee the action is the end-effector target the joint command reaches and
observation.ee_state the arm's end-effector state (so101.dataset.ee_columns). Units are LeRobot's SO-101 conventions (degrees, gripper 0-100) unless
--units radians. An episode that cannot be converted faithfully (unreadable, a stream missing, a
camera changing size, malformed metadata, a file that is no MCAP or holds none of the stack's
topics) is reported and skipped, naming the file and why; the others are converted. A recording
cut short (the recorder killed: no metadata.yaml, its last file cut in the middle) is converted
from what its files hold up to the cut, with a note. A silence longer than --max-gap in the joint states, cube pose or a camera splits an
episode into parts, each converted as an episode of its own when it has at least two frames.
Cameras recorded raw (sensor_msgs/Image) or compressed (sensor_msgs/CompressedImage, JPEG or PNG:
so101-launch's default) alike. Episodes are streamed: a first read of a bag keeps every stream's
times and small values, a second decodes only the camera frames that go into the dataset, one
dataset frame at a time, so memory does not grow with an episode's length.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .. import contract
from ..arguments import picture_size
from ..ee import EE_FEATURE_NAMES
from ..messages import rgb_image, stamp_seconds
from ..units import FEATURE_NAMES, lerobot_from_radians
from .bags import BagError, Episode, camera_frames, episode_dirs, read_episode
from .ee_columns import with_ee_columns
from .resample import frame_times, gaps, parts_between, sample_and_hold

ROBOT_TYPE = "so_follower"
EE_STATE = "observation.ee_state"
# The fewest frames an episode (or a part of one split at a gap) needs to be kept.
MIN_FRAMES = 2
log = logging.getLogger("so101.dataset.convert")


@dataclass
class Frames:
    """One episode on the frame grid."""

    state: np.ndarray  # [N, 6] float32
    action: np.ndarray  # [N, 6] float32
    reward: np.ndarray  # [N] float32
    success: np.ndarray  # [N] bool
    images: dict[str, list]  # per camera, the FrameRef of each frame (bags.camera_frames reads them)
    environment_state: np.ndarray | None  # [N, 7] float32 cube pose, or None
    ee_state: np.ndarray | None = None  # [N, 6] float32 end-effector state (--action-space ee), or None


def frames_of(episode: Episode, fps: float, units: str, environment_state: bool = True) -> Frames:
    """Resamples an episode onto the fps grid (alignment: so101.dataset.resample). With
    `environment_state`, the cube's pose (/cube/pose) of each frame too; an episode without it is
    a BagError then."""
    if environment_state and not episode.cube_pose.times:
        raise BagError(
            f"{episode.path.name}: no /cube/pose (observation.environment_state; --no-environment-state leaves it out)"
        )
    streams = {"joint_states": episode.joint_states.times, "joint_commands": episode.joint_commands.times}
    if environment_state:
        streams["cube_pose"] = episode.cube_pose.times
    streams.update({f"camera {name}": stream.times for name, stream in episode.cameras.items()})
    # Commands stay in force after the last one (a teleop stops sending while holding); every
    # other stream may be held for one frame past its last message.
    instants = frame_times(streams, fps, hold_limit={"joint_commands": float("inf")})
    if len(instants) < 2:
        raise BagError(f"{episode.path.name}: its streams do not overlap for two frames")

    def held(stream, default):
        if not stream.times:
            return [default] * len(instants)
        indices = [max(0, i) for i in np.searchsorted(stream.times, instants + 1e-9, side="right") - 1]
        return [stream.values[i] if stream.times[i] <= t + 1e-9 else default for i, t in zip(indices, instants)]

    convert = (lambda v: v) if units == "radians" else lerobot_from_radians
    state = convert(np.stack([episode.joint_states.values[i] for i in sample_and_hold(episode.joint_states.times, instants)]))
    action = convert(
        np.stack([episode.joint_commands.values[i] for i in sample_and_hold(episode.joint_commands.times, instants)])
    )
    images = {
        name: [stream.values[i] for i in sample_and_hold(stream.times, instants)] for name, stream in episode.cameras.items()
    }
    cube = None
    if environment_state:
        cube = np.stack([episode.cube_pose.values[i] for i in sample_and_hold(episode.cube_pose.times, instants)])
    success = np.array(held(episode.task_success, False), dtype=bool)
    if episode.success is not None:
        # The episode's verdict (metadata.yaml, from the operator or the expert) is its last
        # frame's: the recording may stop before the sim's /task/success of that instant arrived.
        success[-1] = episode.success
    return Frames(
        state=state.astype(np.float32),
        action=action.astype(np.float32),
        reward=np.array(held(episode.reward, 0.0), dtype=np.float32),
        success=success,
        images=images,
        environment_state=None if cube is None else cube.astype(np.float32),
    )


def stamped_streams(episode: Episode, environment_state: bool) -> dict[str, list[float]]:
    """The streams whose silence is a gap in what was observed (the commands are not: while no
    command arrives the robot holds the last target, which is exactly what `action` holds)."""
    streams = {"/joint_states": episode.joint_states.times}
    if environment_state:
        streams["/cube/pose"] = episode.cube_pose.times
    streams.update({episode.camera_topics[name]: stream.times for name, stream in episode.cameras.items()})
    return streams


def episode_parts(episode: Episode, max_gap: float, environment_state: bool) -> tuple[list[Episode], str | None]:
    """The episode cut at every gap longer than `max_gap` s in its joint states, cube pose or
    camera frames, and a message naming the gaps (None when there is none). Each part keeps the
    messages of those streams within its span; commands, reward and success are kept whole (they
    are held: each frame takes the latest at or before its instant). Only the last part keeps the
    episode's verdict from metadata.yaml."""
    found = gaps(stamped_streams(episode, environment_state), max_gap)
    if not found:
        return [episode], None
    spans = parts_between(found)

    def within(stream, start, end):
        keep = [i for i, t in enumerate(stream.times) if start <= t <= end]
        return type(stream)(times=[stream.times[i] for i in keep], values=[stream.values[i] for i in keep])

    parts = []
    for k, (start, end) in enumerate(spans):
        parts.append(
            replace(
                episode,
                success=episode.success if k == len(spans) - 1 else None,
                joint_states=within(episode.joint_states, start, end),
                cube_pose=within(episode.cube_pose, start, end),
                cameras={name: within(stream, start, end) for name, stream in episode.cameras.items()},
            )
        )
    listed = ", ".join(f"{name} {after - before:.2f} s at t={before:.2f} s" for name, before, after in found[:5])
    more = f" and {len(found) - 5} more" if len(found) > 5 else ""
    message = f"{episode.path.name}: gap(s) longer than {max_gap} s ({listed}{more}): split into {len(spans)} parts"
    return parts, message


# observation.environment_state: the cube's pose in the world frame, position in m, orientation as
# a unit quaternion (the sim's /cube/pose; the so101_sim env's environment_state).
ENVIRONMENT_STATE_NAMES = ["cube.x", "cube.y", "cube.z", "cube.qw", "cube.qx", "cube.qy", "cube.qz"]


def features_for(
    cameras: dict[str, tuple[int, int]], use_videos: bool, environment_state: bool = False, action_space: str = "joint"
) -> dict:
    """The dataset's features; with action_space "ee", the action is the end-effector target and
    observation.ee_state the end-effector state, both named EE_FEATURE_NAMES (so101.ee)."""
    ee = action_space == "ee"
    features = {
        "observation.state": {"dtype": "float32", "shape": (6,), "names": FEATURE_NAMES},
        "action": {"dtype": "float32", "shape": (6,), "names": EE_FEATURE_NAMES if ee else FEATURE_NAMES},
        "next.reward": {"dtype": "float32", "shape": (1,), "names": None},
        "next.success": {"dtype": "bool", "shape": (1,), "names": None},
    }
    if environment_state:
        features["observation.environment_state"] = {
            "dtype": "float32",
            "shape": (len(ENVIRONMENT_STATE_NAMES),),
            "names": ENVIRONMENT_STATE_NAMES,
        }
    if ee:
        features[EE_STATE] = {"dtype": "float32", "shape": (len(EE_FEATURE_NAMES),), "names": EE_FEATURE_NAMES}
    for name, (height, width) in cameras.items():
        features[f"observation.images.{name}"] = {
            "dtype": "video" if use_videos else "image",
            "shape": (height, width, 3),
            "names": ["height", "width", "channels"],
        }
    return features


# SVT-AV1 3.0 (LeRobot's video encoder) dies with SIGFPE on frames under ~26 px wide (24 crashes,
# 28 encodes; the height does not matter): measured with PyAV, so narrower episodes are refused.
MIN_VIDEO_WIDTH = 32


def resized(images: list[np.ndarray], width: int, height: int) -> list[np.ndarray]:
    """The frames scaled to width x height (area averaging when shrinking, as for a small policy's input)."""
    from PIL import Image

    if images and images[0].shape[:2] == (height, width):
        return images
    return [np.asarray(Image.fromarray(image).resize((width, height), Image.BOX)) for image in images]


# --image-size: WIDTHxHEIGHT, each side at least 8 pixels.
image_size = picture_size(8)


def quiet_video_encoder() -> None:
    """The AV1 encoder (SVT-AV1) and FFmpeg's muxer print their settings for every video: keep
    their warnings and errors only, so the progress bar and the summary stay readable."""
    import os

    os.environ.setdefault("SVT_LOG", "1")  # SVT-AV1: 1 error, 2 warning, 3 info
    import av.logging

    av.logging.set_level(av.logging.WARNING)
    # LeRobot hands FFmpeg's own logger back after every encode (restore_default_callback), which
    # then printed a line per video it joined (hundreds for 100 episodes): its threshold too.
    av.logging.set_libav_level(av.logging.WARNING)


class PartError(Exception):
    """Why one episode (or part) cannot be written: a camera frame that does not decode, a frame
    LeRobot refuses, a bag that cannot be read a second time."""


def write_part(dataset, frames: Frames, task: str, images, image_size, label: str) -> str | None:
    """Adds the frames of one episode (or part) to the dataset's episode buffer, each camera frame
    decoded when its dataset frame is written, from `images` (bags.camera_frames over the parts
    being written; advanced by exactly this part's frames whatever happens). Returns None, or why
    the part was left out (then nothing of it stays in the buffer)."""
    count = len(frames.state)
    decoded: dict[str, tuple[int, np.ndarray]] = {}  # per camera, the last frame decoded (a held frame repeats)
    read = 0  # frames taken from `images`
    try:
        for k in range(count):
            try:
                messages = next(images) if images is not None else {}
            except (BagError, StopIteration) as error:
                read = count  # the reader is done for: nothing left to pass over
                raise PartError(f"cannot read the camera frames again ({str(error).split(': ', 1)[-1]})") from error
            read += 1
            frame = {
                "observation.state": frames.state[k],
                "action": frames.action[k],
                "next.reward": frames.reward[k : k + 1],
                "next.success": frames.success[k : k + 1],
                "task": task,
            }
            if frames.environment_state is not None:
                frame["observation.environment_state"] = frames.environment_state[k]
            if frames.ee_state is not None:
                frame[EE_STATE] = frames.ee_state[k]
            for name, message in messages.items():
                ordinal = frames.images[name][k].ordinal
                if decoded.get(name, (None,))[0] != ordinal:
                    try:
                        image = rgb_image(message)
                    except ValueError as error:
                        raise PartError(f"camera {name!r}: the frame at t={stamp_seconds(message):.3f} s: {error}") from error
                    if image_size:
                        image = resized([image], *image_size)[0]
                    decoded[name] = (ordinal, image)
                frame[f"observation.images.{name}"] = decoded[name][1]
            try:
                dataset.add_frame(frame)
            except Exception as error:  # noqa: BLE001 - LeRobot's frame validation: this part only
                raise PartError(f"refused by LeRobot ({type(error).__name__}: {error})") from error
    except PartError as error:
        # Nothing of the part is saved: its buffer (and images written so far) is dropped, and the
        # rest of its camera frames are passed over, so the next part reads its own.
        dataset.clear_episode_buffer()
        try:
            for _ in range(count - read):
                next(images)
        except (BagError, StopIteration):
            pass
        return f"{label}: {error}"
    return None


SIMULATION_FILE = "meta/so101_simulation.json"


def write_simulation_settings(output: Path, episodes: list[dict]) -> None:
    """meta/so101_simulation.json: per episode of the dataset, the servo model, randomization
    ranges and draw its bag says the sim used (null for a real arm's), so a dataset says what it
    was made on. LeRobot reads only its own meta files and leaves this one alone."""
    if not any(entry["simulation"] for entry in episodes):
        return
    (output / SIMULATION_FILE).write_text(json.dumps({"episodes": episodes}, indent=1))


def convert(args) -> int:
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from tqdm import tqdm

    paths = episode_dirs([Path(p) for p in args.bags])
    if not paths:
        log.error("no episode directories in %s", ", ".join(args.bags))
        return 1
    cameras = args.cameras.split(",") if args.cameras else None
    dataset = None
    converted, successful, skipped, frames_written = 0, 0, [], 0
    started = time.monotonic()
    notes: list[str] = []
    simulation: list[dict] = []  # per dataset episode: what the sim simulated it with
    ee_targets = ee_clamped = 0  # --action-space ee: end-effector actions, and those out of reach
    # None: decided by the first episode (a real arm records no /cube/pose: then none has it).
    environment_state: bool | None = False if args.no_environment_state else None
    for path in tqdm(paths, desc="episodes", unit="episode", disable=args.quiet):
        try:
            episode = read_episode(path, cameras)
            for note in episode.notes:  # what was recovered rather than read as recorded
                log.warning("%s", note)
                notes.append(note)
            if environment_state is None:
                environment_state = bool(episode.cube_pose.times)
                if not environment_state:
                    log.info("%s has no /cube/pose (a real arm): observation.environment_state left out", path.name)
            if args.successful_only and episode.success is not True:
                skipped.append(f"{path.name}: not marked successful")
                continue
            if episode.rejected_commands:
                note = (
                    f"{path.name}: {episode.rejected_commands} command(s) rejected as the nodes reject them, "
                    f"left out of the action (e.g. {episode.rejection_reasons[0]})"
                )
                log.warning("%s", note)
                notes.append(note)
            parts, message = episode_parts(episode, args.max_gap, environment_state)
            if message:
                log.warning("%s", message)
                notes.append(message)
            # Every part's frames first: nothing of an episode goes into the dataset before all of
            # it is known to fit.
            all_frames = []
            for k, part in enumerate(parts):
                label = path.name if len(parts) == 1 else f"{path.name} part {k + 1}/{len(parts)}"
                try:
                    frames = frames_of(part, args.fps, args.units, environment_state=environment_state)
                except BagError as error:
                    if len(parts) == 1:
                        raise
                    frames, reason = None, str(error).removeprefix(f"{path.name}: ")
                else:
                    reason = None if len(frames.state) >= MIN_FRAMES else f"{len(frames.state)} frame(s)"
                    if not reason and args.action_space == "ee":
                        frames, clamped = with_ee_columns(frames, args.units)
                        ee_clamped += clamped
                        ee_targets += len(frames.action)
                if reason:
                    note = f"{label}: left out ({reason}; at least {MIN_FRAMES} frames needed)"
                    log.warning("%s", note)
                    notes.append(note)
                    continue
                all_frames.append((label, episode.task or args.task, frames))
            if not all_frames:
                raise BagError(f"{path.name}: no part of it long enough after splitting at gaps")
        except BagError as error:
            log.warning("skipped %s", error)
            skipped.append(str(error))
            continue
        # The checks that need no pixels, on every part before any frame is written.
        accepted = []
        for label, task, frames in all_frames:
            shapes = {name: (refs[0].height, refs[0].width) for name, refs in frames.images.items()}
            if args.image_size:
                shapes = {name: (args.image_size[1], args.image_size[0]) for name in shapes}
            narrow = {name: width for name, (_, width) in shapes.items() if width < MIN_VIDEO_WIDTH}
            if narrow and not args.no_videos:
                error = (
                    f"{label}: camera(s) {narrow} narrower than {MIN_VIDEO_WIDTH} px, which the AV1 video encoder "
                    "(SVT-AV1) cannot encode (it crashes the process): --image-size or --no-videos"
                )
                log.warning("skipped %s", error)
                skipped.append(error)
                continue
            if dataset is None:
                cameras = list(shapes)
                dataset = LeRobotDataset.create(
                    repo_id=args.repo_id,
                    fps=args.fps,
                    features=features_for(
                        shapes, not args.no_videos, environment_state=environment_state, action_space=args.action_space
                    ),
                    root=args.output,
                    robot_type=ROBOT_TYPE,
                    use_videos=not args.no_videos,
                )
            elif list(shapes) != cameras or any(
                dataset.features[f"observation.images.{n}"]["shape"][:2] != tuple(s) for n, s in shapes.items()
            ):
                error = f"{label}: cameras {shapes} differ from the dataset's ({cameras})"
                log.warning("skipped %s", error)
                skipped.append(error)
                continue
            accepted.append((label, task, frames))
        # The camera frames of every accepted part, read from the bag frame after frame.
        plan = {name: [ref for _, _, frames in accepted for ref in frames.images[name]] for name in cameras or []}
        images = camera_frames(episode, plan) if plan and accepted else None
        for label, task, frames in accepted:
            reason = write_part(dataset, frames, task, images, args.image_size, label)
            if reason:
                log.warning("skipped %s", reason)
                skipped.append(reason)
                continue
            dataset.save_episode(parallel_encoding=not args.sequential_encoding)
            simulation.append({"episode_index": converted, "bag": label, "simulation": episode.simulation})
            converted += 1
            successful += bool(frames.success[-1])  # the verdict of the episode (its last frame)
            frames_written += len(frames.state)
    check_status = 0
    if dataset is not None:
        dataset.finalize()
        write_simulation_settings(Path(args.output), simulation)
    seconds = time.monotonic() - started
    summary = (
        f"{converted} episode(s) ({successful} successful), {frames_written} frames at {args.fps} fps -> {args.output} "
        f"({seconds:.1f} s, {frames_written / max(seconds, 1e-9):.0f} frames/s); {len(skipped)} skipped"
    )
    print(summary)
    if ee_targets:
        print(
            f"  end-effector actions: {ee_clamped} of {ee_targets} ({100 * ee_clamped / ee_targets:.2f} %) out of reach of the IK"
        )
    for note in notes:
        print(f"  note: {note}")
    for reason in skipped:
        print(f"  skipped: {reason}")
    if dataset is not None and not args.no_check:
        # What LeRobot will read, checked once it is all on disk (so101.dataset.check).
        from .check import run as check_dataset

        sys.stdout.flush()
        check_status = check_dataset(args.output, quiet=args.quiet)
    if dataset is not None and args.push_to_hub:
        if check_status:
            log.error("not pushed to the Hub: the dataset check found problems (--no-check skips it)")
        else:
            dataset.push_to_hub(private=args.private)
    return 0 if converted and not check_status else 1


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="so101-bag-to-lerobot", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "bags", nargs="+", help=f"episode bag directories, or directories holding {contract.EPISODE_DEFAULT_PREFIX}_* directories"
    )
    parser.add_argument("--output", type=Path, required=True, help="dataset root directory (must not exist yet)")
    parser.add_argument("--repo-id", default="local/so101_cube_to_bin", help="dataset id (Hub repo id when pushed)")
    parser.add_argument("--fps", type=int, default=int(contract.CONTROL_RATE), help="frames per second of the dataset")
    parser.add_argument(
        "--units",
        choices=["lerobot", "radians"],
        default="lerobot",
        help="joint units: LeRobot's SO-101 conventions (degrees, gripper 0-100) or the stack's radians",
    )
    parser.add_argument(
        "--action-space",
        choices=["joint", "ee"],
        default="joint",
        help="the action: the joint targets, or the end-effector target they reach (ee.x ee.y ee.z m in the "
        "arm's base frame, ee.pitch ee.roll rad, ee.gripper in the joint units), with observation.ee_state "
        "(the same for the measured joints) beside observation.state",
    )
    parser.add_argument("--cameras", default=None, help="cameras to keep, comma-separated (default: every camera in the bags)")
    parser.add_argument(
        "--image-size",
        type=image_size,
        default=None,
        metavar="WxH",
        help="scale every kept camera's frames to WIDTHxHEIGHT, e.g. 128x96 for a small vision policy (default: as recorded)",
    )
    parser.add_argument(
        "--task",
        default=contract.TASKS["cube_to_bin"].description,
        help="task text of episodes whose bag names none",
    )
    parser.add_argument(
        "--no-environment-state",
        action="store_true",
        help="leave out observation.environment_state (the cube's pose from /cube/pose); without it, the "
        "dataset has it when the first episode has /cube/pose (the sim), and then every episode needs it",
    )
    parser.add_argument(
        "--max-gap",
        type=float,
        default=0.5,
        metavar="SECONDS",
        help="a silence longer than this in the joint states, the cube pose or a camera splits the episode (default 0.5)",
    )
    parser.add_argument("--successful-only", action="store_true", help="keep only episodes marked successful")
    parser.add_argument("--no-videos", action="store_true", help="store camera frames as images, not video")
    parser.add_argument("--sequential-encoding", action="store_true", help="encode one camera's video at a time")
    parser.add_argument("--push-to-hub", action="store_true", help="upload the dataset to the Hugging Face Hub (--repo-id)")
    parser.add_argument("--private", action="store_true", help="with --push-to-hub: a private repo")
    parser.add_argument(
        "--no-check",
        action="store_true",
        help="skip the check of the written dataset (so101-dataset-check: timestamps, videos, NaN, lengths, stats)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    if args.fps <= 0:
        parser.error("--fps must be positive")
    if args.image_size and args.image_size[0] < MIN_VIDEO_WIDTH and not args.no_videos:
        parser.error(f"--image-size: videos need a width of at least {MIN_VIDEO_WIDTH} px (or --no-videos)")
    if not args.max_gap > 0:
        parser.error("--max-gap must be positive")
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    quiet_video_encoder()
    try:
        return convert(args)
    except BagError as error:
        log.error("%s", error)
        return 1


if __name__ == "__main__":
    sys.exit(main())
