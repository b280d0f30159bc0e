"""Building blocks of the recorder's integration tests: reading bags back with an independent reader
(the Python `mcap` and `mcap-ros2-support` packages), rosbag2's metadata.yaml, and the synthetic load
publisher's expected contents."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import yaml

from harness import node_binary, node_environment

RECORDER = "recorder_node"
LOAD_PUBLISHER = "so101_load_publisher"


def episode_dirs(output: Path) -> list[Path]:
    return sorted(p for p in output.glob("episode_*") if p.is_dir())


def metadata(episode: Path) -> dict:
    return yaml.safe_load((episode / "metadata.yaml").read_text())["rosbag2_bagfile_information"]


def topic_counts(meta: dict) -> dict[str, int]:
    return {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]}


def mcap_files(episode: Path) -> list[Path]:
    return sorted(episode.glob("*.mcap"), key=lambda p: int(p.stem.rsplit("_", 1)[1]))


def read_bag(path: Path):
    """(header, summary, decoded messages [(channel topic, message record, decoded ROS message)],
    metadata records {name: dict}) of a complete MCAP file."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        summary = reader.get_summary()
        messages = [(channel.topic, message, ros) for _, channel, message, ros in reader.iter_decoded_messages(log_time_order=False)]
        records = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    return header, summary, messages, records


def stream_messages(path: Path):
    """Every decodable message of an MCAP file read front to back, for files without a summary
    (killed writer, full disk): stops at the truncated tail. Returns ([(topic, decoded)], error)."""
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader
    from mcap_ros2.decoder import DecoderFactory

    factory = DecoderFactory()
    schemas, channels, decoders, out = {}, {}, {}, []
    error = None
    with open(path, "rb") as f:
        try:
            for record in StreamReader(f, skip_magic=False).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    channel = channels[record.channel_id]
                    if channel.id not in decoders:
                        decoders[channel.id] = factory.decoder_for(channel.message_encoding, schemas[channel.schema_id])
                    out.append((channel.topic, decoders[channel.id](record.data)))
        except Exception as exc:  # noqa: BLE001 - the truncated tail of a crashed file
            error = exc
    return out, error


def run_load_publisher(*args: str, timeout: float = 120.0) -> dict:
    """Runs so101_load_publisher to the end; returns its JSON report."""
    done = subprocess.run(
        [str(node_binary(LOAD_PUBLISHER)), *args], env=node_environment(), capture_output=True, text=True, timeout=timeout
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def expected_image(k: int, length: int):
    import numpy as np

    return ((np.arange(length, dtype=np.int64) * 7 + k) % 256).astype(np.uint8)
