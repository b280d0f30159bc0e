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
    for name in ("so101_sim_node", "recorder_node", "teleop_node", "so101_state_publisher"):
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


def test_rviz_needs_rviz2_on_path_and_says_how_to_get_it(binaries, tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    args = launch.parser().parse_args(["--control", "none", "--rviz", "--log-dir", str(tmp_path / "logs")])
    with pytest.raises(SystemExit, match="rviz2 on PATH.*ros-jazzy-rviz2"):
        launch.plan(args)


def test_rviz_opens_the_view_with_the_description_package_on_the_ament_path(binaries, tmp_path, monkeypatch):
    bin_dir = tmp_path / "ros_bin"
    bin_dir.mkdir()
    (bin_dir / "rviz2").write_text("#!/bin/sh\n")
    (bin_dir / "rviz2").chmod(0o755)
    monkeypatch.setenv("PATH", str(bin_dir))
    monkeypatch.setenv("AMENT_PREFIX_PATH", "/opt/ros/jazzy")
    from so101 import description

    monkeypatch.setattr(description, "install", lambda prefix: description.share_directory(prefix))
    args = launch.parser().parse_args(["--control", "none", "--rviz", "--log-dir", str(tmp_path / "logs")])
    specs = {spec.name: spec for spec in launch.plan(args)}
    assert "so101_state_publisher" in specs  # --rviz implies --tf
    rviz = specs["rviz2"]
    prefix = tmp_path / "logs" / "ros_prefix"
    assert rviz.argv == [str(bin_dir / "rviz2"), "-d", str(prefix / "share/so101_description/rviz/so101.rviz")]
    assert rviz.env["AMENT_PREFIX_PATH"] == f"{prefix}:/opt/ros/jazzy"
