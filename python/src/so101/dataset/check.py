"""so101-dataset-check: checks a converted LeRobot dataset (codebase v3.0) on disk, episode by
episode, the way LeRobot will read it when training:

- each episode's frame count: meta/episodes' length, its dataset_from/to_index span and its rows
  in data/ agree; frame_index runs 0..length-1 and index without a hole;
- timestamps start at 0 and step by 1/fps within LeRobot's tolerance (tolerance_s, 1e-4 s);
- no NaN or infinity in observation.state, action, observation.environment_state (every float
  feature that is not an image);
- every camera's video decodes (PyAV, each file once, sequentially), holds exactly the episode's
  frames in its [from_timestamp, to_timestamp) span, and has a frame within the tolerance of each
  of the episode's timestamps (what LeRobot's video decoding demands);
- meta/stats.json holds min, max, mean, std and count of every numeric and visual feature, all
  finite.

Each problem is a finding (episode, what, details), one line each; exit status 0 when there is
none, 1 otherwise. The converter (so101-bag-to-lerobot) runs this at its end unless --no-check.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .parquet import read_parquet

# LeRobotDataset's default tolerance_s: how far a frame's timestamp may be from its k/fps slot,
# and a video frame from the timestamp it is queried at.
TOLERANCE_S = 1e-4
STATS_FIELDS = ("min", "max", "mean", "std", "count")
NON_NUMERIC = {"string", "language"}


@dataclass(frozen=True)
class Finding:
    episode: int | None  # None: the dataset as a whole
    what: str  # e.g. "timestamps", "non-finite", "video", "stats", "length", "layout"
    details: str

    def __str__(self) -> str:
        where = "dataset" if self.episode is None else f"episode {self.episode}"
        return f"{where}: {self.what}: {self.details}"


def _progress(quiet: bool, **kwargs):
    from tqdm import tqdm

    return tqdm(disable=quiet, **kwargs)


def _read_info(root: Path) -> tuple[dict | None, list[Finding]]:
    path = root / "meta" / "info.json"
    try:
        info = json.loads(path.read_text())
    except (OSError, ValueError) as error:
        return None, [Finding(None, "layout", f"meta/info.json unreadable ({error})")]
    missing = [key for key in ("fps", "features", "data_path") if key not in info]
    if missing:
        return None, [Finding(None, "layout", f"meta/info.json lacks {', '.join(missing)}")]
    if info.get("codebase_version") != "v3.0":
        return info, [Finding(None, "layout", f"codebase_version {info.get('codebase_version')!r}, expected 'v3.0'")]
    return info, []


def _read_episodes(root: Path):
    import pandas as pd

    files = sorted((root / "meta" / "episodes").glob("chunk-*/file-*.parquet"))
    if not files:
        raise ValueError("no meta/episodes/chunk-*/file-*.parquet")
    frames = [read_parquet(f) for f in files]
    episodes = pd.concat(frames, ignore_index=True)
    return episodes.sort_values("episode_index").reset_index(drop=True)


def _stack(column) -> np.ndarray:
    values = column.to_numpy()
    if len(values) and isinstance(values[0], (list, np.ndarray)):
        return np.stack([np.asarray(v, dtype=np.float64) for v in values])
    return np.asarray(values, dtype=np.float64).reshape(len(values), -1)


def check_frames(
    episode: int, rows, row_span: tuple[int, int], length: int, fps: float, float_keys, tolerance_s
) -> list[Finding]:
    """The checks of one episode's rows of data/ (a DataFrame, in file order)."""
    findings = []
    first, last = row_span
    if len(rows) != length or last - first != length:
        findings.append(
            Finding(
                episode, "length", f"meta length {length}, dataset_from/to_index span {last - first}, {len(rows)} rows in data/"
            )
        )
    if len(rows) == 0:
        return findings
    frame_index = rows["frame_index"].to_numpy()
    if not np.array_equal(frame_index, np.arange(len(rows))):
        bad = int(np.argmax(frame_index != np.arange(len(rows))))
        findings.append(Finding(episode, "frame_index", f"not 0..{len(rows) - 1}: row {bad} has {frame_index[bad]}"))
    index = rows["index"].to_numpy()
    if not np.array_equal(index, np.arange(first, first + len(rows))):
        bad = int(np.argmax(index != np.arange(first, first + len(rows))))
        findings.append(Finding(episode, "index", f"not {first}..{first + len(rows) - 1}: row {bad} has {index[bad]}"))
    times = rows["timestamp"].to_numpy().astype(np.float64)
    period = 1.0 / fps
    if not np.all(np.isfinite(times)):
        bad = int(np.argmax(~np.isfinite(times)))
        findings.append(Finding(episode, "timestamps", f"frame {bad}: timestamp {times[bad]}"))
    else:
        if abs(times[0]) > tolerance_s:
            findings.append(
                Finding(episode, "timestamps", f"first timestamp {times[0]:.6f} s, expected 0 within {tolerance_s} s")
            )
        steps = np.diff(times)
        off = np.flatnonzero(np.abs(steps - period) > tolerance_s)
        if len(off):
            k = int(off[0])
            findings.append(
                Finding(
                    episode,
                    "timestamps",
                    f"{len(off)} step(s) off 1/fps = {period:.6f} s by more than {tolerance_s} s "
                    f"(first: frame {k} -> {k + 1}, {times[k]:.6f} -> {times[k + 1]:.6f} s)",
                )
            )
    for key in float_keys:
        if key not in rows:
            findings.append(Finding(episode, "layout", f"no {key} column in data/"))
            continue
        values = _stack(rows[key])
        bad_rows = np.flatnonzero(~np.all(np.isfinite(values), axis=1))
        if len(bad_rows):
            findings.append(
                Finding(episode, "non-finite", f"{key}: NaN/inf in {len(bad_rows)} frame(s) (first: frame {int(bad_rows[0])})")
            )
    return findings


def _decoded_times(path: Path, progress=None) -> tuple[np.ndarray, str | None]:
    """The presentation times (s) of every frame of the video that decodes, in order, and the
    error that stopped decoding (None when it reached the end)."""
    import av

    times: list[float] = []
    try:
        with av.open(str(path)) as container:
            stream = container.streams.video[0]
            for frame in container.decode(stream):
                if frame.pts is not None:
                    times.append(float(frame.pts * stream.time_base))
                if progress is not None:
                    progress.update()
    except Exception as error:  # noqa: BLE001 - any decoding failure is a finding
        return np.asarray(times), f"{type(error).__name__}: {error}"
    return np.asarray(times), None


def check_video_episode(
    episode: int, key: str, decoded: np.ndarray, error: str | None, span: tuple[float, float], times, tolerance_s
) -> list[Finding]:
    """One episode's frames of one camera: decoded frames within its span of the file, and one
    within tolerance of each frame's timestamp."""
    start, end = span
    count = int(np.sum((decoded >= start - tolerance_s) & (decoded < end - tolerance_s)))
    findings = []
    suffix = f" (decoding stopped: {error})" if error else ""
    if count != len(times):
        findings.append(
            Finding(
                episode, "video", f"{key}: {count} frame(s) decoded in [{start:.4f}, {end:.4f}) s, expected {len(times)}{suffix}"
            )
        )
    if len(times) and len(decoded):
        queries = start + np.asarray(times, dtype=np.float64)
        nearest = np.searchsorted(decoded, queries)
        below = np.abs(queries - decoded[np.clip(nearest - 1, 0, len(decoded) - 1)])
        above = np.abs(decoded[np.clip(nearest, 0, len(decoded) - 1)] - queries)
        missing = np.flatnonzero(np.minimum(below, above) >= tolerance_s)
        if len(missing):
            findings.append(
                Finding(
                    episode,
                    "video",
                    f"{key}: {len(missing)} of {len(times)} frame(s) have no decoded frame within {tolerance_s} s "
                    f"(first: frame {int(missing[0])} at {queries[missing[0]]:.4f} s){suffix if not findings else ''}",
                )
            )
    elif len(times) and not findings:
        findings.append(Finding(episode, "video", f"{key}: no frame decoded{suffix}"))
    return findings


def check_stats(root: Path, features: dict) -> list[Finding]:
    path = root / "meta" / "stats.json"
    try:
        stats = json.loads(path.read_text())
    except (OSError, ValueError) as error:
        return [Finding(None, "stats", f"meta/stats.json unreadable ({error})")]
    findings = []
    for key, feature in features.items():
        if feature.get("dtype") in NON_NUMERIC:
            continue
        entry = stats.get(key)
        if not isinstance(entry, dict):
            findings.append(Finding(None, "stats", f"meta/stats.json has no {key}"))
            continue
        absent = [field for field in STATS_FIELDS if field not in entry]
        if absent:
            findings.append(Finding(None, "stats", f"meta/stats.json {key} lacks {', '.join(absent)}"))
        for field in STATS_FIELDS:
            if field in entry:
                try:
                    values = np.asarray(entry[field], dtype=np.float64)
                except (TypeError, ValueError):
                    values = np.asarray([math.nan])
                if not np.all(np.isfinite(values)):
                    findings.append(Finding(None, "stats", f"meta/stats.json {key}/{field} is not finite"))
    return findings


def check_dataset(root: Path | str, tolerance_s: float = TOLERANCE_S, quiet: bool = True) -> tuple[list[Finding], dict]:
    """All checks of the dataset at `root`; the findings and a summary (episodes, frames, video
    frames decoded)."""
    root = Path(root)
    summary = {"episodes": 0, "frames": 0, "video_frames": 0}
    info, findings = _read_info(root)
    if info is None:
        return findings, summary
    fps = float(info["fps"])
    features = info["features"]
    try:
        episodes = _read_episodes(root)
    except Exception as error:  # noqa: BLE001 - unreadable metadata is a finding
        return findings + [Finding(None, "layout", f"meta/episodes unreadable ({error})")], summary
    summary["episodes"] = len(episodes)
    summary["frames"] = int(episodes["length"].sum()) if len(episodes) else 0
    if info.get("total_episodes") != len(episodes):
        findings.append(
            Finding(None, "layout", f"info.json total_episodes {info.get('total_episodes')}, meta/episodes has {len(episodes)}")
        )
    if info.get("total_frames") != summary["frames"]:
        findings.append(
            Finding(
                None, "layout", f"info.json total_frames {info.get('total_frames')}, episode lengths sum to {summary['frames']}"
            )
        )
    float_keys = [
        key for key, feature in features.items() if str(feature.get("dtype", "")).startswith("float") and key != "timestamp"
    ]
    video_keys = [key for key, feature in features.items() if feature.get("dtype") == "video"]

    # Data files: each read once, its episodes checked.
    timestamps: dict[int, np.ndarray] = {}
    by_file = defaultdict(list)
    for i in range(len(episodes)):
        by_file[(int(episodes["data/chunk_index"].iat[i]), int(episodes["data/file_index"].iat[i]))].append(i)
    bar = _progress(quiet, total=len(episodes), desc="checking episodes", unit="episode")
    for (chunk, file), members in by_file.items():
        relative = info["data_path"].format(chunk_index=chunk, file_index=file)
        try:
            data = read_parquet(root / relative)
        except Exception as error:  # noqa: BLE001
            for i in members:
                findings.append(Finding(int(episodes["episode_index"].iat[i]), "layout", f"{relative} unreadable ({error})"))
            continue
        grouped = dict(tuple(data.groupby("episode_index", sort=False)))
        for i in members:
            episode = int(episodes["episode_index"].iat[i])
            rows = grouped.get(episode, data.iloc[0:0])
            span = (int(episodes["dataset_from_index"].iat[i]), int(episodes["dataset_to_index"].iat[i]))
            findings += check_frames(episode, rows, span, int(episodes["length"].iat[i]), fps, float_keys, tolerance_s)
            timestamps[episode] = rows["timestamp"].to_numpy().astype(np.float64) if len(rows) else np.zeros(0)
            bar.update()
    bar.close()

    # Videos: each file decoded once, sequentially.
    for key in video_keys:
        files = defaultdict(list)
        for i in range(len(episodes)):
            files[(int(episodes[f"videos/{key}/chunk_index"].iat[i]), int(episodes[f"videos/{key}/file_index"].iat[i]))].append(i)
        bar = _progress(quiet, total=summary["frames"], desc=f"decoding {key}", unit="frame")
        for (chunk, file), members in files.items():
            relative = info.get("video_path", "").format(video_key=key, chunk_index=chunk, file_index=file)
            decoded, error = _decoded_times(root / relative, bar)
            decoded = np.sort(decoded)
            summary["video_frames"] += len(decoded)
            for i in members:
                episode = int(episodes["episode_index"].iat[i])
                span = (
                    float(episodes[f"videos/{key}/from_timestamp"].iat[i]),
                    float(episodes[f"videos/{key}/to_timestamp"].iat[i]),
                )
                times = timestamps.get(episode, np.zeros(0))
                findings += check_video_episode(episode, f"{key} ({relative})", decoded, error, span, times, tolerance_s)
        bar.close()
    findings += check_stats(root, features)
    return findings, summary


def check_loads(root: Path, repo_id: str) -> list[Finding]:
    """LeRobot itself opens the dataset from `root` (its metadata and data files)."""
    try:
        from lerobot.datasets.lerobot_dataset import LeRobotDataset

        dataset = LeRobotDataset(repo_id, root=root)
        if len(dataset) == 0:
            return [Finding(None, "load", "LeRobotDataset holds no frame")]
    except Exception as error:  # noqa: BLE001 - whatever LeRobot raises is the finding
        return [Finding(None, "load", f"LeRobotDataset({repo_id!r}, root=...) failed: {type(error).__name__}: {error}")]
    return []


def run(root: Path | str, repo_id: str | None = None, tolerance_s: float = TOLERANCE_S, quiet: bool = False, out=None) -> int:
    """Checks the dataset, prints one line per finding and a summary line; 0 when clean, 1 not.
    With `repo_id`, also opens it with LeRobotDataset when the other checks found nothing."""
    out = out or sys.stdout
    root = Path(root)
    findings, summary = check_dataset(root, tolerance_s=tolerance_s, quiet=quiet)
    if repo_id and not findings:
        findings += check_loads(root, repo_id)
    for finding in findings:
        print(f"  check: {finding}", file=out)
    episodes_hit = len({f.episode for f in findings if f.episode is not None})
    verdict = "clean" if not findings else f"{len(findings)} finding(s), {episodes_hit} episode(s) affected"
    print(
        f"check {root}: {summary['episodes']} episode(s), {summary['frames']} frames, "
        f"{summary['video_frames']} video frames decoded: {verdict}",
        file=out,
    )
    return 0 if not findings else 1


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="so101-dataset-check", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("root", type=Path, help="the dataset's root directory (holding meta/, data/, videos/)")
    parser.add_argument("--repo-id", default=None, help="also open it with LeRobotDataset under this id when the checks pass")
    parser.add_argument(
        "--tolerance-s", type=float, default=TOLERANCE_S, help=f"timestamp tolerance in s (LeRobot's default {TOLERANCE_S})"
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    if not args.root.is_dir():
        parser.error(f"{args.root}: not a directory")
    return run(args.root, repo_id=args.repo_id, tolerance_s=args.tolerance_s, quiet=args.quiet)


if __name__ == "__main__":
    sys.exit(main())
