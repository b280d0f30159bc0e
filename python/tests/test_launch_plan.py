"""so101-launch's plan (no process started): recording keeps the cameras' JPEG frames by default
(the sim publishes them, the recorder keeps image_raw/compressed instead of the raw images, the
rest of recorder_node's default set unchanged), --raw-images records the raw frames, and flags the
user gives the nodes win over the launcher's."""

from __future__ import annotations

import re

import pytest

from so101.paths import repo_root
from so101.stack import launch, launch_plan


@pytest.fixture
def binaries(tmp_path, monkeypatch):
    for name in ("so101_sim_node", "recorder_node", "teleop_node", "so101_state_publisher"):
        (tmp_path / name).touch()
    monkeypatch.setenv("SO101_BIN_DIR", str(tmp_path))


def argv_of(argv: list[str]) -> dict[str, list[str]]:
    args = launch.parser().parse_args(argv)
    return {spec.name: spec.argv[1:] for spec in launch_plan.plan(args)}


def regexes(argv: list[str]) -> list[str]:
    return [argv[i + 1] for i, arg in enumerate(argv) if arg == "--regex"]


def test_recording_keeps_compressed_cameras_by_default(binaries):
    nodes = argv_of(["--control", "expert", "--record", "--sim-args", "--cameras top"])
    sim = nodes["so101_sim_node"]
    assert "--jpeg" in sim and sim[sim.index("--jpeg-quality") + 1] == str(launch_plan.DEFAULT_JPEG_QUALITY)
    assert sim[-2:] == ["--cameras", "top"]
    assert regexes(nodes["recorder_node"]) == launch_plan.COMPRESSED_RECORDING
    assert "camera/[^/]+/image_raw/compressed" in launch_plan.COMPRESSED_RECORDING


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


def test_lockstep_steps_the_sim_once_per_command_of_the_expert(binaries, capsys):
    nodes = argv_of(["--control", "expert", "--speed", "lockstep"])
    sim, teleop = nodes["so101_sim_node"], nodes["teleop_node"]
    assert "--lockstep" in sim and "--step-on-command" in sim and "--speed" not in sim
    assert "--lockstep" in teleop and "--sim-time" not in teleop
    timed = argv_of(["--control", "expert", "--speed", "2"])
    assert timed["so101_sim_node"][timed["so101_sim_node"].index("--speed") + 1] == "2"
    assert "--sim-time" in timed["teleop_node"] and "--lockstep" not in timed["teleop_node"]
    # A person cannot keep pace with a sim that waits for each command.
    with pytest.raises(SystemExit, match="lockstep"):
        argv_of(["--control", "teleop", "--speed", "lockstep"])
    # Neither a factor nor lockstep: refused at the command line, before any node starts.
    with pytest.raises(SystemExit):
        launch.parser().parse_args(["--control", "expert", "--speed", "fast"])
    assert "neither a factor of real time" in capsys.readouterr().err


def test_the_compressed_set_is_recorder_nodes_default_set_with_compressed_cameras():
    source = (repo_root() / "crates" / "recorder_node" / "src" / "topics.rs").read_text()
    block = re.search(r"pub const DEFAULT_PATTERNS: &\[&str\] = &\[(.*?)\];", source, re.S).group(1)
    defaults = re.findall(r'"([^"]+)"', block)
    assert "camera/[^/]+/image_raw" in defaults
    swapped = [p + "/compressed" if p == "camera/[^/]+/image_raw" else p for p in defaults]
    assert launch_plan.COMPRESSED_RECORDING == swapped


def test_rviz_needs_rviz2_on_path_and_says_how_to_get_it(binaries, tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    args = launch.parser().parse_args(["--control", "none", "--rviz", "--log-dir", str(tmp_path / "logs")])
    with pytest.raises(SystemExit, match="rviz2 on PATH.*ros-jazzy-rviz2"):
        launch_plan.plan(args)


def test_rviz_opens_the_view_with_the_description_package_on_the_ament_path(binaries, tmp_path, monkeypatch):
    bin_dir = tmp_path / "ros_bin"
    bin_dir.mkdir()
    (bin_dir / "rviz2").write_text("#!/bin/sh\n")
    (bin_dir / "rviz2").chmod(0o755)
    monkeypatch.setenv("PATH", str(bin_dir))
    monkeypatch.setenv("AMENT_PREFIX_PATH", "/opt/ros/jazzy")
    from so101.stack import description

    monkeypatch.setattr(description, "install", lambda prefix: description.share_directory(prefix))
    args = launch.parser().parse_args(["--control", "none", "--rviz", "--log-dir", str(tmp_path / "logs")])
    specs = {spec.name: spec for spec in launch_plan.plan(args)}
    assert "so101_state_publisher" in specs  # --rviz implies --tf
    rviz = specs["rviz2"]
    prefix = tmp_path / "logs" / "ros_prefix"
    assert rviz.argv == [str(bin_dir / "rviz2"), "-d", str(prefix / "share/so101_description/rviz/so101.rviz")]
    assert rviz.env["AMENT_PREFIX_PATH"] == f"{prefix}:/opt/ros/jazzy"


@pytest.fixture
def real_binaries(binaries, tmp_path):
    for name in ("so101_camera_node", "so101_feetech_driver", "so101_servo_emulator", "so101_rerun"):
        (tmp_path / name).touch()


def test_cameras_are_served_beside_the_driver_and_recorded_as_jpeg(real_binaries, tmp_path):
    argv = ["--robot", "real", "--emulate", "--control", "none", "--record", "--log-dir", str(tmp_path / "logs")]
    argv += ["--camera", "top=/dev/video0", "--camera", "wrist=/dev/v4l/by-id/usb-Cam-video-index0:640x480@30"]
    argv += ["--camera-args", "--control top.exposure=156", "--rerun", str(tmp_path / "run.rrd")]
    args = launch.parser().parse_args(argv)
    specs = {spec.name: spec for spec in launch_plan.plan(args)}
    camera = specs["so101_camera_node"]
    assert camera.argv[1:] == [
        "--camera",
        "top=/dev/video0",
        "--camera",
        "wrist=/dev/v4l/by-id/usb-Cam-video-index0:640x480@30",
        "--control",
        "top.exposure=156",
    ]
    assert camera.ready == "publisher /camera/top/image_raw/compressed"
    names = list(specs)
    assert names.index("so101_feetech_driver") < names.index("so101_camera_node") < names.index("recorder_node")
    assert "camera/[^/]+/image_raw/compressed" in regexes(specs["recorder_node"].argv)
    rerun = specs["so101_rerun"].argv
    assert rerun[rerun.index("--cameras") + 1] == "top,wrist", "Rerun shows the real cameras by their names"


def test_the_sim_has_its_own_cameras(binaries, tmp_path):
    args = launch.parser().parse_args(["--control", "none", "--camera", "top=/dev/video0", "--log-dir", str(tmp_path)])
    with pytest.raises(SystemExit, match="the sim renders its own"):
        launch_plan.plan(args)


def test_an_emulated_leader_arm_stands_beside_the_emulated_follower(real_binaries, tmp_path):
    logs = tmp_path / "logs"
    args = launch.parser().parse_args(["--robot", "real", "--emulate", "--teleop-source", "leader", "--log-dir", str(logs)])
    specs = {spec.name: spec for spec in launch_plan.plan(args)}
    leader_bus = str(logs / "leader_bus")
    assert specs["leader_emulator"].argv[1:3] == ["--link", leader_bus]
    leader = specs["leader_arm"].argv
    assert leader[leader.index("--port") + 1] == leader_bus and "--leader" in leader
    assert leader[leader.index("--calibration") + 1] == specs["leader_emulator"].argv[-1]
    without = launch.parser().parse_args(["--robot", "real", "--port", "/dev/ttyACM0", "--teleop-source", "leader"])
    with pytest.raises(SystemExit, match="--leader-port"):
        launch_plan.plan(without)


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["--control", "expert", "--record", "--episode-time", "5"], "the expert marks its own episodes"),
        (["--control", "teleop", "--record", "--episode-time", "5"], "the keyboard teleop marks episodes itself"),
        (["--control", "none", "--episode-time", "5"], "add --record"),
    ],
)
def test_a_timed_session_is_refused_where_someone_else_marks_the_episodes(argv, says):
    with pytest.raises(SystemExit, match=says):
        launch_plan.check_session(launch.parser().parse_args(argv))


def test_a_timed_session_records_no_episode_by_itself(binaries, tmp_path):
    args = launch.parser().parse_args(
        ["--control", "none", "--record", "--episode-time", "5", "--teleop-source", "gamepad", "--log-dir", str(tmp_path)]
    )
    launch_plan.check_session(args)
    recorder = {spec.name: spec for spec in launch_plan.plan(args)}["recorder_node"].argv
    assert "--start" not in recorder


@pytest.mark.parametrize(
    "task, sim_task, text",
    [
        ("lift_cube", "lift_cube", "lift the cube"),
        ("place-cube", "place_cube", "place the cube on the pad"),
        ("lift the cube", "lift_cube", "lift the cube"),  # a task's own text names it
        ("stack the blocks", "cube_to_bin", "stack the blocks"),  # any other text: cube_to_bin's episodes
    ],
)
def test_the_task_is_scored_played_and_recorded_alike(binaries, task, sim_task, text):
    nodes = argv_of(["--control", "expert", "--record", "--task", task])
    sim, teleop, recorder = nodes["so101_sim_node"], nodes["teleop_node"], nodes["recorder_node"]
    assert (sim[sim.index("--task") + 1] if "--task" in sim else "cube_to_bin") == sim_task
    assert teleop[teleop.index("--sim-task") + 1] == sim_task and teleop[teleop.index("--task") + 1] == text
    assert recorder[recorder.index("--task") + 1] == text


def test_a_policy_is_told_the_task(binaries):
    runner = argv_of(["--control", "policy", "--policy", "some/policy", "--task", "lift_cube"])["so101-run-policy"]
    assert runner[runner.index("--task") + 1] == "lift the cube" and runner[runner.index("--sim-task") + 1] == "lift_cube"


def closed_episode(bags, name: str, custom: dict | None, text: str | None = None) -> None:
    """An episode directory as recorder_node closes it: an MCAP file and metadata.yaml (or `text`
    in its place, e.g. a damaged file)."""
    import yaml

    episode = bags / name
    episode.mkdir(parents=True)
    (episode / f"{name}_0.mcap").write_bytes(b"")
    info = {"relative_file_paths": [f"{name}_0.mcap"], "custom_data": custom}
    (episode / "metadata.yaml").write_text(text if text is not None else yaml.safe_dump({"rosbag2_bagfile_information": info}))


def test_the_launcher_reports_each_closed_episode_once_with_the_verdict_the_converter_reads(tmp_path, capsys):
    from so101.dataset.bags import episode_verdict

    closed_episode(tmp_path, "episode_0001", {"success": "true", "task": "cube_to_bin"})
    closed_episode(tmp_path, "episode_0002", {"success": "false"})
    closed_episode(tmp_path, "episode_0003", None)
    closed_episode(tmp_path, "episode_0004", None, text="rosbag2_bagfile_information: {relative_file_paths: [")
    reported: set = set()
    launch.report_closed_episodes(tmp_path, reported)
    launch.report_closed_episodes(tmp_path, reported)
    lines = capsys.readouterr().out.splitlines()
    assert lines[:3] == [
        "so101-launch: recorded episode_0001 (success)",
        "so101-launch: recorded episode_0002 (failure)",
        "so101-launch: recorded episode_0003 (no verdict)",
    ]
    # A damaged file is named with the converter's reason, before a conversion meets it.
    assert len(lines) == 4, lines
    assert lines[3].startswith("so101-launch: recorded episode_0004 (no verdict: episode_0004: unreadable metadata.yaml"), lines
    assert [episode_verdict(tmp_path / f"episode_000{n}") for n in (1, 2, 3)] == [True, False, None]
