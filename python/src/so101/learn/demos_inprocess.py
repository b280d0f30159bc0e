"""`so101-learn demos --backend inprocess --workers N`: the expert's demonstrations recorded through
the in-process door (so101_native: the simulation core and the planner teleop_node's expert runs)
straight into a LeRobot dataset, N processes in parallel, without ROS, bags or conversion.

The dataset is the one the stack's path makes (`--backend ros`, the default: so101-launch records
bags that so101-bag-to-lerobot converts): the same features, units, fps, task text and provenance
(meta/so101_simulation.json), the same episodes of one `--seed` (the sim's sequence of cube
placements and randomization draws), each played as teleop_node plays it: the plan from the
settled cube, the targets each period, the verdict once the task succeeds (the episode goes on
SUCCESS_SHOWN seconds) or JUDGE seconds after the plan ends. The expert's noise differs: the
stack's draws follow ROS's timing, these are seeded per episode (the same for any N). One option
is this door's alone: --perturb pushes the arm off the expert's path while the dataset keeps the
expert's own targets (so101.learn.perturbation); --driver CKPT lets a trained policy send the arm
while the dataset keeps the expert's targets (so101.learn.dagger).

Each worker writes the dataset of its contiguous share of the episodes; LeRobot's
aggregate_datasets joins them in episode order, and so101-dataset-check checks the result.
"""

from __future__ import annotations

import argparse
import json
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import contract
from ..dataset.convert import (
    EE_STATE,
    MIN_VIDEO_WIDTH,
    ROBOT_TYPE,
    SIMULATION_FILE,
    features_for,
    image_size,
    write_simulation_settings,
)
from ..dataset.ee_columns import ee_columns
from ..evaluate.parallel import run_shares, split
from ..units import lerobot_from_radians
from .missed_grasps import draw_offset, from_frame, recovery_start, told
from .perturbation import Perturbation


def camera_sizes(text: str) -> dict[str, tuple[int, int]]:
    """The sim's --cameras notation with sizes ("none", "top:96x72,wrist:96x72") -> {name: (height,
    width)}. In-process every camera names its size: the sim node's default size is its own."""
    if text.strip().lower() in ("", "none"):
        return {}
    sizes = {}
    for item in text.split(","):
        name, _, size = item.strip().partition(":")
        if name not in contract.CAMERA_NAMES:
            raise ValueError(f"--cameras {text!r}: {name!r} is none of {', '.join(contract.CAMERA_NAMES)}")
        if not size:
            raise ValueError(f"--cameras {text!r}: name each camera's size in-process, e.g. {name}:96x72")
        try:
            width, height = image_size(size)
        except argparse.ArgumentTypeError as error:
            raise ValueError(f"--cameras {text!r}: {error}") from None
        if width < MIN_VIDEO_WIDTH:
            raise ValueError(
                f"--cameras {text!r}: {name} narrower than {MIN_VIDEO_WIDTH} px, which the video encoder cannot take"
            )
        sizes[name] = (height, width)
    return sizes


@dataclass(frozen=True)
class Options:
    """What every worker records with (picklable: sent to spawned processes)."""

    seed: int
    waypoint_noise: float
    action_noise: float
    cameras: dict[str, tuple[int, int]]
    lite: bool
    environment_state: bool
    keep_failures: bool
    servo_params: str
    randomize: str
    camera_poses: str | None
    repo_id: str
    task: str = "cube_to_bin"
    action_space: str = "joint"  # "ee": end-effector actions and state (so101.dataset.ee_columns)
    perturb: float = 0.0  # rad: so101.learn.perturbation's sigma (0: the expert's own path)
    missed_grasps: float = 0.0  # share of episodes kept from a regrasp after a told miss (so101.learn.missed_grasps)
    driver: str | None = None  # a checkpoint whose policy sends the arm (so101.learn.dagger)
    driver_share: float = 1.0  # the policy's share of the target the arm is sent


@dataclass
class Recorded:
    """One episode as the expert played it, whether or not it went into the dataset."""

    episode: int  # 0-based index in the --seed sequence
    success: bool
    frames: int
    kept: bool
    note: str
    simulation: dict | None
    regrasps: int = 0
    missed_grasp: dict | None = None  # the told offset and the first frame kept (so101.learn.missed_grasps)

    @property
    def label(self) -> str:
        """The episode's name, as the stack's path names its bag (episode_0001 is the first)."""
        return f"{contract.EPISODE_DEFAULT_PREFIX}_{self.episode + 1:04d}"


def expert_seed(seed: int, episode: int) -> int:
    """The expert's noise seed of one episode: independent of how episodes are shared out."""
    return seed * 1_000_003 + episode + 1


def play_episode(
    env, expert, observation: dict, reward: float, success: bool, limit: int, drive: Callable | None = None
) -> tuple[dict, bool]:
    """Runs one episode as teleop_node's expert source does, from its first observation. Returns
    its frames (radians; per frame the observation and the expert's target then) and the verdict.
    With `drive` (a Perturbation or a PolicyDriver: (the expert's target, the observation) -> the
    target to execute), the env is sent what it answers, and the frames keep the expert's."""
    import so101_native

    period = 1.0 / contract.CONTROL_RATE
    frames: dict[str, list] = {"state": [], "action": [], "reward": [], "success": [], "cube": [], "images": [], "regrasps": []}
    action = np.asarray(observation["agent_pos"], dtype=np.float32)
    judged_from = succeeded_at = None
    for step in range(limit):
        now = step * period
        judging = judged_from is not None  # teleop_node judges from the period after the plan's end
        if not judging:
            action = expert(observation)
            if expert.done:
                judged_from = now
        frames["state"].append(np.asarray(observation["agent_pos"], dtype=np.float64))
        frames["action"].append(np.asarray(action, dtype=np.float64))
        frames["reward"].append(reward)
        frames["success"].append(success)
        frames["cube"].append(np.asarray(observation["environment_state"], dtype=np.float32))
        frames["images"].append(observation.get("pixels", {}))
        frames["regrasps"].append(expert.regrasps)
        if judging:
            if success and succeeded_at is None:
                succeeded_at = now
            if succeeded_at is not None and now >= succeeded_at + so101_native.EXPERT_SUCCESS_SHOWN_SECONDS - 1e-9:
                return frames, True
            if succeeded_at is None and now > judged_from + so101_native.EXPERT_JUDGE_SECONDS:
                return frames, False
        observation, reward, _, _, info = env.step(action if drive is None else drive(action, observation))
        success = bool(info["is_success"])
    return frames, False


def record_share(options: Options, first: int, count: int, root: str, workers: int = 1) -> list[Recorded]:
    """Records episodes first .. first+count-1 of the --seed sequence into a dataset at `root`
    (created when an episode is kept). Runs in a worker process, one of `workers`."""
    import datasets
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from ..dataset.convert import quiet_video_encoder
    from ..envs.inprocess import So101InProcessEnv
    from ..evaluate.expert import ExpertPolicy

    quiet_video_encoder()
    datasets.disable_progress_bars()  # one bar per saved episode otherwise, from every worker
    env = So101InProcessEnv(
        task=options.task,
        lite=options.lite,
        cameras=options.cameras or None,
        servo_params=options.servo_params,
        randomize=options.randomize,
        camera_poses=options.camera_poses,
    )
    task_text = contract.TASKS[options.task].description
    limit = 2 * contract.TASKS[options.task].episode_steps
    driver = policy_driver(options, workers)
    dataset = None
    recorded: list[Recorded] = []
    # The sim node's sequence: its first /sim/reset gives the seed's first placement and draw.
    observation, info = env.reset(seed=options.seed)
    for _ in range(first):
        observation, info = env.reset()
    for episode in range(first, first + count):
        if episode > first:
            observation, info = env.reset()
        settings = info["episode_settings"]
        expert = ExpertPolicy(
            waypoint_noise=options.waypoint_noise,
            action_noise=options.action_noise,
            seed=expert_seed(options.seed, episode),
            task=options.task,
        )
        offset = draw_offset(options.missed_grasps, options.seed, episode)  # None: the expert is told the truth
        try:
            expert.reset(observation if offset is None else told(observation, offset))
        except ValueError as error:  # out of reach: teleop_node counts it, records nothing
            recorded.append(Recorded(episode, False, 0, False, str(error), settings))
            continue
        drive = driver
        if options.perturb > 0:
            drive = Perturbation(options.perturb, seed=(options.seed, episode))
        elif driver is not None:
            driver.reset()
        frames, success = play_episode(env, expert, observation, 0.0, bool(info["is_success"]), limit, drive)
        kept = success or options.keep_failures
        missed = None
        if offset is not None:
            start = recovery_start(frames["regrasps"])
            if start is None:  # the told grasp held the cube: nothing to recover from, nothing kept
                note = "the grasp beside the cube held it: no recovery to keep"
                recorded.append(Recorded(episode, success, 0, False, note, settings, expert.regrasps))
                continue
            frames = from_frame(frames, start)
            missed = {"told_offset_m": [round(float(v), 4) for v in offset], "from_frame": start}
        if kept:
            if dataset is None:
                dataset = LeRobotDataset.create(
                    repo_id=options.repo_id,
                    fps=int(contract.CONTROL_RATE),
                    features=features_for(
                        options.cameras,
                        use_videos=True,
                        environment_state=options.environment_state,
                        action_space=options.action_space,
                    ),
                    root=root,
                    robot_type=ROBOT_TYPE,
                    use_videos=True,
                )
            # One encoder process per camera and episode is LeRobot's default; beside other
            # workers it oversubscribes the cores (2 workers with 3 cameras: 3x one's time).
            write_episode(dataset, frames, success, task_text, options, parallel_encoding=workers == 1)
        note = "the task succeeded" if success else "the task did not succeed"
        if missed is not None:
            note += f"; a recovery from a grasp {1000 * np.linalg.norm(offset):.0f} mm off, from its frame {start}"
        recorded.append(Recorded(episode, success, len(frames["state"]), kept, note, settings, expert.regrasps, missed))
    if dataset is not None:
        dataset.finalize()
    return recorded


def policy_driver(options: Options, workers: int):
    """The worker's PolicyDriver of --driver (its torch threads its share of the cores), or None."""
    if options.driver is None:
        return None
    import torch

    from ..evaluate.parallel import threads_per_worker
    from .dagger import load_driver

    torch.set_num_threads(threads_per_worker(workers))
    return load_driver(options.driver, options.driver_share, options.cameras)


def write_episode(dataset, frames: dict, success: bool, task: str, options: Options, parallel_encoding: bool) -> None:
    state = lerobot_from_radians(np.stack(frames["state"])).astype(np.float32)
    action = lerobot_from_radians(np.stack(frames["action"])).astype(np.float32)
    ee_state = None
    if options.action_space == "ee":
        action, ee_state, _ = ee_columns(state, action, "lerobot")
    verdicts = np.array(frames["success"], dtype=bool)
    verdicts[-1] = success  # the episode's verdict is its last frame's, as in a converted bag
    for k in range(len(state)):
        frame = {
            "observation.state": state[k],
            "action": action[k],
            "next.reward": np.array([frames["reward"][k]], dtype=np.float32),
            "next.success": verdicts[k : k + 1],
            "task": task,
        }
        if options.environment_state:
            frame["observation.environment_state"] = frames["cube"][k]
        if ee_state is not None:
            frame[EE_STATE] = ee_state[k]
        for name, image in frames["images"][k].items():
            frame[f"observation.images.{name}"] = image
        dataset.add_frame(frame)
    dataset.save_episode(parallel_encoding=parallel_encoding)


def record(options: Options, episodes: int, workers: int, output: Path, after: Path | None = None) -> list[Recorded]:
    """`episodes` demonstrations on `workers` processes into the dataset at `output` (which must
    not exist), after the episodes of the dataset `after` if one is given (DAgger trains on all
    it has gathered); every new episode's record, in order. Nothing is left at `output` unless all
    of it was written."""
    shares = [(first, len(seeds)) for first, seeds in split(list(range(episodes)), 0, workers)]
    work = output.parent / f".{output.name}-partial"
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    try:
        jobs = [(options, first, count, str(work / f"share-{k:03d}"), len(shares)) for k, (first, count) in enumerate(shares)]
        results = (
            record_share(*jobs[0])
            if len(jobs) == 1
            else run_shares(record_share, jobs, len(jobs), preload=("lerobot.datasets.lerobot_dataset",))
        )
        roots = [Path(job[3]) for job in jobs if (Path(job[3]) / "meta" / "info.json").exists()]
        if roots:
            joined = work / "joined"
            join(options.repo_id, roots, joined)
            kept = [r for r in results if r.kept]
            # The pushes' sigma goes with each episode, so the dataset says its states were pushed.
            pushed = {"perturb": options.perturb} if options.perturb > 0 else {}
            settings = [
                {"episode_index": index, "bag": r.label, "simulation": r.simulation, **pushed}
                | ({"missed_grasp": r.missed_grasp} if r.missed_grasp else {})
                for index, r in enumerate(kept)
            ]
            if after is not None:
                settings = simulation_settings(after) + [
                    dict(entry, episode_index=entry["episode_index"] + episode_count(after)) for entry in settings
                ]
                join(options.repo_id, [after, joined], work / "after", keep=True)
                joined = work / "after"
            write_simulation_settings(joined, settings)
            joined.rename(output)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return results


def episode_count(dataset: Path) -> int:
    return int(json.loads((dataset / "meta" / "info.json").read_text())["total_episodes"])


def simulation_settings(dataset: Path) -> list[dict]:
    """The per-episode entries of a dataset's meta/so101_simulation.json (none if it has none)."""
    path = dataset / SIMULATION_FILE
    return json.loads(path.read_text())["episodes"] if path.exists() else []


def features_problem(dataset: Path, options: Options) -> str | None:
    """Why the dataset's episodes cannot come before the ones `options` record (--after), or None:
    LeRobot aggregates datasets of the same features only."""
    info = dataset / "meta" / "info.json"
    if not info.exists():
        return f"{dataset} is not a LeRobot dataset (no meta/info.json)"
    theirs = json.loads(info.read_text())["features"]
    ours = features_for(
        options.cameras, use_videos=True, environment_state=options.environment_state, action_space=options.action_space
    )
    shape = {key: list(feature["shape"]) for key, feature in ours.items()}
    if (found := {key: list(theirs[key]["shape"]) for key in theirs if key in shape or key.startswith("observation.")}) != shape:
        return f"{dataset} has the features {found}, these demonstrations {shape} (the same --cameras, pose and action space)"
    return None


def join(repo_id: str, roots: list[Path], output: Path, keep: bool = False) -> None:
    """The shards as one dataset at `output`, in their order (LeRobot's own aggregation); `keep`:
    the roots stay as they are (one is otherwise moved to `output`)."""
    if len(roots) == 1 and not keep:
        roots[0].rename(output)
        return
    from lerobot.datasets.aggregate import aggregate_datasets

    from ..dataset.convert import quiet_video_encoder

    quiet_video_encoder()  # joining the shards' videos printed a muxer line per video
    aggregate_datasets(repo_ids=[repo_id] * len(roots), aggr_repo_id=repo_id, roots=roots, aggr_root=output)
