"""Building blocks of test_recorder.py: reading recorder_node's bags back with an independent reader
(the Python `mcap` and `mcap-ros2-support` packages, never the recorder's own code), checking
rosbag2's metadata.yaml field by field, and running so101_load_publisher, whose messages can be
verified byte by byte.

The recorder process itself is started by conftest's `recorder_factory` fixture (a SimNode with
`.output`; set `node.exit_expected = True` before killing it on purpose).
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import yaml
from harness import SimNode, node_binary, node_environment

RECORDER = "recorder_node"
LOAD_PUBLISHER = "so101_load_publisher"

# What so101_sim_node publishes that the recorder's default set holds (/clock is not in it).
SIM_RECORDED_TOPICS = {
    "/joint_states": "sensor_msgs/msg/JointState",
    "/task/reward": "std_msgs/msg/Float64",
    "/task/success": "std_msgs/msg/Bool",
    "/cube/pose": "geometry_msgs/msg/PoseStamped",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
}
CUSTOM_DATA_KEYS = {
    "episode_index",
    "task",
    "success",
    "seed",
    "start_time_ns",
    "stop_time_ns",
    "dropped_messages",
    "error",
    "simulation",  # the sim's /sim/episode settings, empty without a sim
}
# The keys of one rosbag2 (Jazzy) QoS profile.
QOS_KEYS = {
    "history",
    "depth",
    "reliability",
    "durability",
    "deadline",
    "lifespan",
    "liveliness",
    "liveliness_lease_duration",
    "avoid_ros_namespace_conventions",
}
MCAP_MAGIC = b"\x89MCAP0\r\n"
EPISODE_NAME = re.compile(r"^episode_(\d{6})$")


# =========================================================================== bag directories
def episode_dirs(output: Path) -> list[Path]:
    """Episode directories under `output`, by number."""
    if not output.is_dir():
        return []
    return sorted(p for p in output.iterdir() if p.is_dir() and EPISODE_NAME.match(p.name))


def mcap_files(episode: Path) -> list[Path]:
    """The episode's .mcap files in split order (NAME_0, NAME_1, ...); fails on a stray name."""
    files = []
    for path in episode.glob("*.mcap"):
        match = re.fullmatch(re.escape(episode.name) + r"_(\d+)\.mcap", path.name)
        assert match, f"unexpected file name {path.name} in {episode}"
        files.append((int(match.group(1)), path))
    files.sort()
    assert [i for i, _ in files] == list(range(len(files))), f"split files not numbered 0..n-1: {[p.name for _, p in files]}"
    return [p for _, p in files]


def wait_episode(output: Path, index: int, recorder: SimNode, timeout: float = 20.0) -> Path:
    """Waits until episode `index` has its directory and first .mcap file (the episode runs)."""
    episode = output / f"episode_{index:06d}"
    first = episode / f"episode_{index:06d}_0.mcap"
    _wait(lambda: first.is_file(), timeout, f"{first} to appear (episode {index} started)", recorder)
    return episode


def wait_metadata(episode: Path, recorder: SimNode, timeout: float = 10.0) -> dict:
    """Waits until the episode is closed (metadata.yaml written); returns rosbag2_bagfile_information."""
    _wait(lambda: (episode / "metadata.yaml").is_file(), timeout, f"{episode}/metadata.yaml (episode closed)", recorder)
    return load_metadata(episode)


def wait_gone(path: Path, recorder: SimNode, timeout: float = 10.0) -> None:
    _wait(lambda: not path.exists(), timeout, f"{path} to be deleted", recorder)


def _wait(predicate, timeout: float, what: str, recorder: SimNode | None) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if recorder is not None and not recorder.alive():
            pytest.fail(
                f"the recorder exited (code {recorder.proc.returncode}) while waiting for {what}:\n{recorder.log_tail()}",
                pytrace=False,
            )
        if time.monotonic() > deadline:
            log = f"\nrecorder log:\n{recorder.log_tail()}" if recorder is not None else ""
            pytest.fail(f"timeout after {timeout:.1f} s waiting for {what}{log}", pytrace=False)
        time.sleep(0.02)


# =========================================================================== metadata.yaml
def load_metadata(episode: Path) -> dict:
    text = (episode / "metadata.yaml").read_text()
    doc = yaml.safe_load(text)
    assert isinstance(doc, dict) and list(doc) == ["rosbag2_bagfile_information"], f"metadata.yaml top level: {doc!r:.300}"
    return doc["rosbag2_bagfile_information"]


def topic_counts(info: dict) -> dict[str, int]:
    """topic -> message_count of metadata.yaml, leaving out topics listed with 0 messages (rosbag2
    lists every subscribed topic; the MCAP file has channels only for topics with messages)."""
    return {t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"] if t["message_count"]}


def topic_types(info: dict) -> dict[str, str]:
    return {t["topic_metadata"]["name"]: t["topic_metadata"]["type"] for t in info["topics_with_message_count"]}


def check_qos_profiles(value: Any, where: str) -> list[dict]:
    """offered_qos_profiles: a YAML list of rosbag2 QoS profiles (given parsed, or as YAML text)."""
    profiles = yaml.safe_load(value) if isinstance(value, str) else value
    assert isinstance(profiles, list) and profiles, f"{where}: offered_qos_profiles is not a non-empty list: {value!r}"
    for profile in profiles:
        assert isinstance(profile, dict) and set(profile) == QOS_KEYS, f"{where}: QoS profile keys {sorted(profile)}"
        assert profile["reliability"] in ("reliable", "best_effort"), f"{where}: reliability {profile['reliability']!r}"
        assert profile["history"] in ("keep_last", "keep_all"), f"{where}: history {profile['history']!r}"
        assert profile["durability"] in ("volatile", "transient_local"), f"{where}: durability {profile['durability']!r}"
        assert isinstance(profile["depth"], int) and profile["depth"] >= 0, f"{where}: depth {profile['depth']!r}"
        for key in ("deadline", "lifespan", "liveliness_lease_duration"):
            assert set(profile[key]) == {"sec", "nsec"}, f"{where}: {key} = {profile[key]!r}"
    return profiles


def check_metadata_fields(info: dict, episode: Path) -> None:
    """Every field of rosbag2's version-9 metadata that the recorder's contract lists, by type and
    against the files of the episode directory."""
    assert info["version"] == 9, info["version"]
    assert info["storage_identifier"] == "mcap"
    assert info["ros_distro"] == "jazzy"
    assert set(info["duration"]) == {"nanoseconds"} and isinstance(info["duration"]["nanoseconds"], int)
    assert set(info["starting_time"]) == {"nanoseconds_since_epoch"}
    assert isinstance(info["starting_time"]["nanoseconds_since_epoch"], int)
    assert isinstance(info["message_count"], int)
    assert isinstance(info["compression_format"], str) and isinstance(info["compression_mode"], str)
    for entry in info["topics_with_message_count"]:
        meta = entry["topic_metadata"]
        assert set(meta) == {"name", "type", "serialization_format", "offered_qos_profiles", "type_description_hash"}, sorted(
            meta
        )
        assert meta["name"].startswith("/"), meta["name"]
        assert re.fullmatch(r"[a-z0-9_]+/msg/[A-Za-z0-9]+", meta["type"]), meta["type"]
        assert meta["serialization_format"] == "cdr"
        check_qos_profiles(meta["offered_qos_profiles"], f"metadata.yaml {meta['name']}")
        assert isinstance(meta["type_description_hash"], str)
        assert isinstance(entry["message_count"], int) and entry["message_count"] >= 0
    names = [t["topic_metadata"]["name"] for t in info["topics_with_message_count"]]
    assert len(names) == len(set(names)), f"a topic listed twice: {names}"
    assert info["message_count"] == sum(topic_counts(info).values()), "message_count != sum of the topics' counts"
    files = mcap_files(episode)
    assert info["relative_file_paths"] == [p.name for p in files], (info["relative_file_paths"], files)
    assert [f["path"] for f in info["files"]] == [p.name for p in files]
    for entry in info["files"]:
        assert set(entry) == {"path", "starting_time", "duration", "message_count"}, sorted(entry)
        assert isinstance(entry["starting_time"]["nanoseconds_since_epoch"], int)
        assert isinstance(entry["duration"]["nanoseconds"], int) and entry["duration"]["nanoseconds"] >= 0
        assert isinstance(entry["message_count"], int)
    assert sum(f["message_count"] for f in info["files"]) == info["message_count"], "files' counts do not add up"
    custom = info["custom_data"]
    assert set(custom) == CUSTOM_DATA_KEYS, sorted(custom)
    assert all(isinstance(v, str) for v in custom.values()), f"custom_data values must be strings: {custom}"
    assert custom["episode_index"] == str(int(EPISODE_NAME.match(episode.name).group(1)))
    assert custom["success"] in ("true", "false", "unknown")
    assert custom["seed"] == "" or re.fullmatch(r"-?\d+", custom["seed"]), custom["seed"]
    assert re.fullmatch(r"\d+", custom["start_time_ns"]) and re.fullmatch(r"\d+", custom["stop_time_ns"]), custom
    assert int(custom["start_time_ns"]) <= int(custom["stop_time_ns"])
    assert re.fullmatch(r"\d+", custom["dropped_messages"]), custom["dropped_messages"]
    # The sim's settings are JSON with the servo model; empty when no sim published any.
    assert custom["simulation"] == "" or "servo_model" in json.loads(custom["simulation"]), custom["simulation"]


# =========================================================================== MCAP reading
@dataclass
class Recorded:
    topic: str
    record: Any  # mcap.records.Message (log_time, publish_time, sequence, data)
    ros: Any  # the decoded ROS message


@dataclass
class Bag:
    header: Any
    summary: Any
    messages: list[Recorded]
    records: dict[str, dict[str, str]]  # metadata records by name
    record_names: list[str] = field(default_factory=list)

    def on(self, topic: str) -> list[Recorded]:
        return [m for m in self.messages if m.topic == topic]

    def channel_counts(self) -> dict[str, int]:
        """topic -> message count from the summary's statistics."""
        counts: dict[str, int] = {}
        for channel_id, count in self.summary.statistics.channel_message_counts.items():
            topic = self.summary.channels[channel_id].topic
            counts[topic] = counts.get(topic, 0) + count
        return counts


def read_bag(path: Path) -> Bag:
    """A complete (closed) MCAP file: header, summary, every message decoded, metadata records."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        summary = reader.get_summary()
        assert summary is not None, f"{path} has no summary section (not closed properly)"
        messages = [
            Recorded(channel.topic, message, ros)
            for _, channel, message, ros in reader.iter_decoded_messages(log_time_order=False)
        ]
        metadata = list(reader.iter_metadata())
    return Bag(header, summary, messages, {m.name: dict(m.metadata) for m in metadata}, [m.name for m in metadata])


@dataclass
class Recovered:
    """What a reader gets out of an MCAP file without a summary (killed writer, full disk)."""

    messages: list[Recorded]
    error: Exception | None  # what stopped the stream reader (None: the file ended cleanly)
    footer: bool  # a Footer record was read

    def on(self, topic: str) -> list[Recorded]:
        return [m for m in self.messages if m.topic == topic]


def recover(path: Path) -> Recovered:
    """Reads an MCAP file front to back, record by record, decoding every message, until the end or
    the first damaged record (the truncated tail of a crashed writer)."""
    from mcap.records import Channel, Footer, Message, Schema
    from mcap.stream_reader import StreamReader
    from mcap_ros2.decoder import DecoderFactory

    factory = DecoderFactory()
    schemas, channels, decoders = {}, {}, {}
    messages: list[Recorded] = []
    footer, error = False, None
    with open(path, "rb") as f:
        try:
            for record in StreamReader(f, skip_magic=False, emit_chunks=False).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Footer):
                    footer = True
                elif isinstance(record, Message):
                    channel = channels[record.channel_id]
                    decoder = decoders.get(channel.id)
                    if decoder is None:
                        decoder = decoders[channel.id] = factory.decoder_for(channel.message_encoding, schemas[channel.schema_id])
                    messages.append(Recorded(channel.topic, record, decoder(record.data)))
        except Exception as exc:  # noqa: BLE001 - the damaged tail ends the read
            error = exc
    return Recovered(messages, error, footer)


def ends_with_magic(path: Path) -> bool:
    with open(path, "rb") as f:
        f.seek(0, 2)
        if f.tell() < len(MCAP_MAGIC):
            return False
        f.seek(-len(MCAP_MAGIC), 2)
        return f.read() == MCAP_MAGIC


def stamp_ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def all_finite(values) -> bool:
    return all(math.isfinite(v) for v in values)


# =========================================================================== so101_load_publisher
def run_load_publisher(*args: str, timeout: float = 60.0, log_path: Path | None = None) -> dict:
    """Runs so101_load_publisher to its end; returns its JSON report (the last stdout line)."""
    command = [str(node_binary(LOAD_PUBLISHER)), *args]
    try:
        done = subprocess.run(command, env=node_environment(), capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired as error:
        pytest.fail(f"{LOAD_PUBLISHER} did not finish within {timeout} s: {error.stderr!r:.2000}", pytrace=False)
    if log_path is not None:
        log_path.write_text(done.stdout + "\n--- stderr\n" + done.stderr)
    assert done.returncode == 0, f"{' '.join(command)} exited {done.returncode}:\n{done.stderr[-3000:]}"
    lines = [line for line in done.stdout.splitlines() if line.strip()]
    assert lines, f"{LOAD_PUBLISHER} printed no report; stderr:\n{done.stderr[-3000:]}"
    try:
        report = json.loads(lines[-1])
    except json.JSONDecodeError:
        pytest.fail(f"{LOAD_PUBLISHER}'s last line is not JSON: {lines[-1]!r}", pytrace=False)
    assert isinstance(report.get("published"), dict), report
    return report


class ImagePattern:
    """Image k of the load publisher: data[i] = (i * 7 + k) % 256."""

    def __init__(self, length: int):
        import numpy as np

        self._np = np
        self.base = ((np.arange(length, dtype=np.int64) * 7) % 256).astype(np.uint8)

    def expected(self, k: int):
        # uint8 addition wraps: exactly (i * 7 + k) % 256.
        return self.base + self._np.uint8(k % 256)

    def matches(self, data: bytes, k: int) -> bool:
        np = self._np
        actual = np.frombuffer(data, dtype=np.uint8)
        return actual.size == self.base.size and bool(np.array_equal(actual, self.expected(k)))

    def first_mismatch(self, data: bytes, k: int) -> str:
        np = self._np
        actual = np.frombuffer(data, dtype=np.uint8)
        if actual.size != self.base.size:
            return f"{actual.size} bytes instead of {self.base.size}"
        wrong = np.nonzero(actual != self.expected(k))[0]
        if wrong.size == 0:
            return "no mismatch"
        i = int(wrong[0])
        return f"{wrong.size} bytes differ, first at {i}: {int(actual[i])} instead of {int(self.expected(k)[i])}"


# =========================================================================== recorder services
class RecorderServices:
    """One rclpy client per recorder service, created once (a fresh client per call would wait for
    discovery every time)."""

    TRIGGERS = ("start", "stop", "discard", "ready")

    def __init__(self, ros, recorder: SimNode | None, namespace: str = "", timeout: float = 15.0):
        from std_srvs.srv import SetBool, Trigger

        self._ros, self._recorder = ros, recorder
        self._types = {name: Trigger for name in self.TRIGGERS}
        self._types["mark_success"] = SetBool
        self._clients = {name: ros.node.create_client(srv, f"{namespace}/recorder/{name}") for name, srv in self._types.items()}
        for name, client in self._clients.items():
            _wait(client.service_is_ready, timeout, f"service /recorder/{name}", recorder)
        # The server's reply writer matches this client's reply reader a moment after the request
        # side is ready; a reply sent before that would be lost.
        time.sleep(0.5)

    def call(self, name: str, data: bool | None = None, timeout: float = 10.0):
        srv = self._types[name]
        request = srv.Request() if data is None else srv.Request(data=data)
        future = self._clients[name].call_async(request)
        _wait(future.done, timeout, f"the answer of /recorder/{name}", self._recorder)
        if future.exception() is not None:
            raise future.exception()
        return future.result()

    def close(self) -> None:
        for client in self._clients.values():
            self._ros.node.destroy_client(client)
