"""The converter on a directory of bags where some are damaged or foreign (synthetic bags, no DDS):
a recording cut short (the recorder killed: no metadata.yaml, its MCAP cut in the middle) is
converted from what precedes the cut; a file that is no MCAP, an MCAP of other topics and
encodings, and a file cut before any message are each reported with the file and why; every other
episode is converted."""

from __future__ import annotations

import io
import json
from contextlib import redirect_stdout

import pytest
from bag_writer import metadata_yaml
from mcap.writer import Writer as McapWriter
from test_convert_checks import simple_episode

from so101 import contract
from so101.dataset.bags import read_episode
from so101.dataset.convert import main

FRAMES_OF_A_WHOLE_EPISODE = 60  # 2 s at 30 fps, from half a frame after every stream has started


def cut(directory, keep: float) -> int:
    """Cuts the episode's MCAP file to `keep` of its bytes (a recorder killed mid-write)."""
    mcap = directory / f"{directory.name}_0.mcap"
    data = mcap.read_bytes()
    mcap.write_bytes(data[: int(len(data) * keep)])
    return len(data)


def foreign_episode(directory) -> None:
    """An MCAP of another application: JSON messages on a topic of its own, with a metadata.yaml."""
    directory.mkdir(parents=True)
    name = f"{directory.name}_0.mcap"
    with open(directory / name, "wb") as stream:
        writer = McapWriter(stream)
        writer.start()
        schema = writer.register_schema("Reading", "jsonschema", json.dumps({"type": "object"}).encode())
        channel = writer.register_channel("/weather", "json", schema)
        for k in range(10):
            writer.add_message(channel, log_time=k, publish_time=k, data=json.dumps({"t": k}).encode())
        writer.finish()
    (directory / contract.EPISODE_METADATA_FILE).write_text(metadata_yaml(directory, name, [], {}, "task", True))


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    bags = tmp_path_factory.mktemp("bags")
    simple_episode(bags / "episode_000000").close()
    simple_episode(bags / "episode_000001").close(closed=False, chunk_size=2048)
    cut(bags / "episode_000001", 0.6)
    foreign_episode(bags / "episode_000002")
    not_mcap = simple_episode(bags / "episode_000003").close()
    (not_mcap / "episode_000003_0.mcap").write_bytes(b"PK\x03\x04 a zip file, not a bag" * 10)
    simple_episode(bags / "episode_000004").close(closed=False)
    cut(bags / "episode_000004", 0.01)  # nothing but the header
    simple_episode(bags / "episode_000005").close()
    output = tmp_path_factory.mktemp("out") / "dataset"
    out = io.StringIO()
    with redirect_stdout(out):
        status = main([str(bags), "--output", str(output), "--no-videos", "--quiet", "--repo-id", "local/damaged"])
    return status, out.getvalue(), output


def test_a_recording_cut_short_is_read_up_to_the_cut(tmp_path):
    whole = simple_episode(tmp_path / "whole" / "episode_000000").close()
    episode = simple_episode(tmp_path / "killed" / "episode_000000").close(closed=False, chunk_size=2048)
    cut(episode, 0.6)
    full, recovered = read_episode(whole, None), read_episode(episode, None)
    assert 0 < len(recovered.joint_states.times) < len(full.joint_states.times)
    # What was read is what was recorded, from the start.
    assert recovered.joint_states.times == full.joint_states.times[: len(recovered.joint_states.times)]
    assert recovered.task == "" and recovered.success is None
    assert any("no metadata.yaml (the recording was cut short)" in note for note in recovered.notes)
    assert any("episode_000000_0.mcap is cut short" in note for note in recovered.notes)


def test_the_good_and_the_recovered_episodes_are_converted(converted):
    status, summary, output = converted
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    assert status == 0, summary
    assert summary.startswith("3 episode(s)"), summary
    dataset = LeRobotDataset("local/damaged", root=output)
    lengths = list(dataset.meta.episodes["length"])
    assert lengths[0] == lengths[2] == FRAMES_OF_A_WHOLE_EPISODE, lengths
    assert 10 < lengths[1] < FRAMES_OF_A_WHOLE_EPISODE, lengths  # episode_000001 up to its cut


def test_each_bad_file_is_named_with_the_reason(converted):
    _, summary, _ = converted
    skipped = [line for line in summary.splitlines() if line.startswith("  skipped: ")]
    notes = [line for line in summary.splitlines() if line.startswith("  note: ")]
    assert len(skipped) == 3, summary
    assert "episode_000002: no /joint_states (observation.state); its files hold /weather (json, jsonschema)" in skipped[0]
    assert "episode_000003: episode_000003_0.mcap is not an MCAP file (it starts with b'PK\\x03\\x04" in skipped[1]
    assert "episode_000004: no /joint_states (observation.state); its files hold no message" in skipped[2]
    assert "episode_000004_0.mcap is cut short" in skipped[2]
    assert any("episode_000001: no metadata.yaml (the recording was cut short)" in note for note in notes), summary
    assert any("episode_000001: episode_000001_0.mcap is cut short after " in note for note in notes), summary
    assert "3 skipped" in summary.splitlines()[0]


def test_a_bag_cut_short_without_a_verdict_is_skipped_by_successful_only(tmp_path, capsys):
    bags = tmp_path / "bags"
    simple_episode(bags / "episode_000000").close()
    simple_episode(bags / "episode_000001").close(closed=False, chunk_size=2048)
    cut(bags / "episode_000001", 0.6)
    assert main([str(bags), "--output", str(tmp_path / "dataset"), "--no-videos", "--quiet", "--successful-only"]) == 0
    summary = capsys.readouterr().out
    assert summary.startswith("1 episode(s)") and "skipped: episode_000001: not marked successful" in summary, summary


def test_an_episode_bag_with_neither_metadata_nor_mcap_is_reported(tmp_path):
    from so101.dataset.bags import BagError

    (tmp_path / "episode_000000").mkdir()
    with pytest.raises(BagError, match="no metadata.yaml and no MCAP file"):
        read_episode(tmp_path / "episode_000000", None)
