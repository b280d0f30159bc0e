"""so101-launch's plan (no process started): recording keeps the cameras' JPEG frames by default
(the sim publishes them, the recorder keeps image_raw/compressed instead of the raw images, the
rest of recorder_node's default set unchanged), --raw-images records the raw frames, and flags the
user gives the nodes win over the launcher's."""

from __future__ import annotations

import re

import pytest

from so101 import launch
from so101.paths import repo_root


@pytest.fixture
def binaries(tmp_path, monkeypatch):
    for name in ("so101_sim_node", "recorder_node", "teleop_node"):
        (tmp_path / name).touch()
    monkeypatch.setenv("SO101_BIN_DIR", str(tmp_path))


def argv_of(argv: list[str]) -> dict[str, list[str]]:
    args = launch.parser().parse_args(argv)
    return {spec.name: spec.argv[1:] for spec in launch.plan(args)}


def regexes(argv: list[str]) -> list[str]:
    return [argv[i + 1] for i, arg in enumerate(argv) if arg == "--regex"]


def test_recording_keeps_compressed_cameras_by_default(binaries):
    nodes = argv_of(["--control", "expert", "--record", "--sim-args", "--cameras top"])
    sim = nodes["so101_sim_node"]
    assert "--jpeg" in sim and sim[sim.index("--jpeg-quality") + 1] == str(launch.DEFAULT_JPEG_QUALITY)
    assert sim[-2:] == ["--cameras", "top"]
    assert regexes(nodes["recorder_node"]) == launch.COMPRESSED_RECORDING
    assert "camera/[^/]+/image_raw/compressed" in launch.COMPRESSED_RECORDING


def test_raw_images_and_the_users_own_flags(binaries):
    nodes = argv_of(["--control", "expert", "--record", "--raw-images"])
    assert "--jpeg" not in nodes["so101_sim_node"] and not regexes(nodes["recorder_node"])
    nodes = argv_of(["--control", "expert", "--record", "--jpeg-quality", "80", "--sim-args=--jpeg-quality 60"])
    sim = nodes["so101_sim_node"]
    assert sim.count("--jpeg") == 1 and sim.count("--jpeg-quality") == 1 and sim[sim.index("--jpeg-quality") + 1] == "60"
    nodes = argv_of(["--control", "expert", "--record", "--recorder-args=--topics joint_states"])
    assert not regexes(nodes["recorder_node"]) and nodes["recorder_node"][-2:] == ["--topics", "joint_states"]
    assert "--jpeg" not in argv_of(["--control", "expert"])["so101_sim_node"]  # not recording: no JPEG work
    with pytest.raises(SystemExit):
        launch.parser().parse_args(["--jpeg-quality", "0"])


def test_the_compressed_set_is_recorder_nodes_default_set_with_compressed_cameras():
    source = (repo_root() / "crates" / "recorder_node" / "src" / "topics.rs").read_text()
    block = re.search(r"pub const DEFAULT_PATTERNS: &\[&str\] = &\[(.*?)\];", source, re.S).group(1)
    defaults = re.findall(r'"([^"]+)"', block)
    assert "camera/[^/]+/image_raw" in defaults
    swapped = [p + "/compressed" if p == "camera/[^/]+/image_raw" else p for p in defaults]
    assert launch.COMPRESSED_RECORDING == swapped
