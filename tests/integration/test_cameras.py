"""Simulated cameras of so101_sim_node, seen from rclpy: frames of every camera at its configured
rate with CameraInfo, the cube's red pixels where its projected pose says (EGL and OSMesa), reset
moving them, real time kept while frames are skipped, every frame rendered in --speed and lockstep
modes, JPEG frames, and bad camera flags."""

from __future__ import annotations

import io
import math
import time
import xml.etree.ElementTree as ElementTree

import numpy as np
import pytest
from harness import (
    REPO_ROOT,
    best_effort_qos,
    reliable_qos,
    stamp_seconds,
    wait_until,
)

SCENE = REPO_ROOT / "assets" / "so101_cube_to_bin.xml"
CAMERA_STATUS = "so101_sim_node: cameras"


# =========================================================================== helpers
def image_array(msg) -> np.ndarray:
    assert msg.encoding == "rgb8", msg.encoding
    assert msg.step == 3 * msg.width and len(msg.data) == msg.step * msg.height, (msg.width, msg.height, msg.step, len(msg.data))
    return np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(msg.height, msg.width, 3)


def world_camera(name: str) -> tuple[np.ndarray, np.ndarray]:
    """Position and rotation (columns: camera x, y, z in the world) of a camera fixed in the
    scene's worldbody, read from the scene file independently of the node."""
    root = ElementTree.parse(SCENE).getroot()
    element = root.find(f"./worldbody/camera[@name='{name}']")
    assert element is not None, f"camera {name} not in the worldbody of {SCENE}"
    position = np.array([float(v) for v in element.get("pos").split()])
    axes = np.array([float(v) for v in element.get("xyaxes").split()])
    x = axes[:3] / np.linalg.norm(axes[:3])
    y = axes[3:] - x * (x @ axes[3:])
    y /= np.linalg.norm(y)
    return position, np.column_stack([x, y, np.cross(x, y)])


def project(point: np.ndarray, camera: str, info, pose: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[float, float]:
    """Pixel of a world point, through the camera pose of the scene file (or `pose`: position and
    rotation in the world) and the node's CameraInfo (MuJoCo cameras look along -z with y up; the
    optical frame has z forward and y down)."""
    position, rotation = pose if pose is not None else world_camera(camera)
    local = rotation.T @ (point - position)
    x, y, z = local[0], -local[1], -local[2]
    k = info.k
    return k[0] * x / z + k[2], k[4] * y / z + k[5]


def red_pixels(image: np.ndarray) -> np.ndarray:
    """(row, column) of the cube's pixels: strongly red (the scene has nothing else red)."""
    r, g, b = (image[..., c].astype(int) for c in range(3))
    return np.argwhere((r > 90) & (r > 3 * g) & (r > 3 * b))


def red_centroid(image: np.ndarray) -> tuple[float, float, int]:
    pixels = red_pixels(image)
    assert len(pixels) >= 20, f"only {len(pixels)} red pixels: the cube is not in the frame"
    row, column = pixels.mean(axis=0)
    return float(column), float(row), len(pixels)


def cube_position(msg) -> np.ndarray:
    p = msg.pose.position
    return np.array([p.x, p.y, p.z])


def camera_values(msgs) -> dict[str, str] | None:
    for msg in reversed(msgs):
        for status in msg.status:
            if status.name == CAMERA_STATUS:
                return {kv.key: kv.value for kv in status.values} | {
                    "_level": int.from_bytes(status.level, "little") if isinstance(status.level, bytes) else int(status.level)
                }
    return None


def subscribe_camera(ros, sim, name: str, depth: int = 50):
    from sensor_msgs.msg import CameraInfo, Image

    return (
        ros.subscribe(sim.name(f"camera/{name}/image_raw"), Image, reliable_qos(depth)),
        ros.subscribe(sim.name(f"camera/{name}/camera_info"), CameraInfo, reliable_qos(depth)),
    )


def step(ros, sim, times: int = 1):
    """`times` /sim/step calls through one client per node: a fresh client per call can see the
    server's request reader before the server sees its response reader, and lose the answer."""
    from std_srvs.srv import Trigger

    client = getattr(sim, "step_client", None)
    if client is None:
        client = ros.node.create_client(Trigger, sim.name("sim/step"))
        wait_until(client.service_is_ready, 20.0, "/sim/step", sim)
        time.sleep(0.3)  # both directions of the service matched
        sim.step_client = client
    for _ in range(times):
        future = client.call_async(Trigger.Request())
        wait_until(future.done, 10.0, "the response of /sim/step", sim)
        assert future.result().success, future.result().message


def test_a_camera_placed_by_a_file_renders_from_there_with_its_size_and_field_of_view(sim_factory, ros, tmp_path):
    """--camera-poses (so101-camera-align's file): the top camera moved 6 cm and turned 5 degrees
    renders the cube where that pose projects it, at the file's size and field of view."""
    import cv2
    from geometry_msgs.msg import PoseStamped

    from so101.cameras.placement import Placement, quaternion_from_matrix, write_placements
    from so101.cameras.sim_board import scene_cameras

    position, rotation, _fovy = scene_cameras(SCENE)["top"]
    world_position, world_rotation = world_camera("top")
    # The base frame is the world's, shifted: the same rotation, so the placement's world pose is known.
    np.testing.assert_allclose(rotation, world_rotation, atol=1e-12)
    turn, _ = cv2.Rodrigues(np.array([0.0, 1.0, 0.0]) * math.radians(5.0))
    shift = np.array([0.04, -0.03, -0.03])
    poses_file = tmp_path / "camera_poses.toml"
    write_placements(poses_file, {"top": Placement(position + shift, quaternion_from_matrix(turn @ rotation), 44.0, 320, 240)})

    sim = sim_factory("--lockstep", "--seed", "4", "--cameras", "top", "--camera-rate", "100", "--camera-poses", str(poses_file))
    images, infos = subscribe_camera(ros, sim, "top")
    poses = ros.subscribe(sim.name("cube/pose"), PoseStamped, reliable_qos(100))
    ros.wait_for_publisher(sim.name("camera/top/image_raw"), 30.0, "the camera publisher", sim)
    step(ros, sim, 3)
    wait_until(lambda: images.count() >= 3, 10.0, "frames of the first steps", sim)
    image = images.latest()
    stamp = stamp_seconds(image.header.stamp)
    wait_until(lambda: any(stamp_seconds(m.header.stamp) == stamp for m in infos.messages()), 10.0, "its camera_info", sim)
    info = next(m for m in infos.messages() if stamp_seconds(m.header.stamp) == stamp)
    pose = next(m for m in poses.messages() if stamp_seconds(m.header.stamp) == stamp)
    assert (image.width, image.height, info.width, info.height) == (320, 240, 320, 240)
    assert info.k[4] == pytest.approx(0.5 * 240 / math.tan(math.radians(44.0) / 2), rel=1e-6)
    u, v, _count = red_centroid(image_array(image))
    expected = project(cube_position(pose), "top", info, (world_position + shift, turn @ world_rotation))
    unplaced = project(cube_position(pose), "top", info)
    assert math.dist((u, v), expected) < 2.5, ((u, v), expected)
    assert math.dist((u, v), unplaced) > 10, "the placement did not move the camera"


# =========================================================================== rate and content
def test_every_camera_publishes_at_its_configured_rate_with_camera_info(sim_factory, ros):
    rates = {"top": 10.0, "front": 5.0, "wrist": 20.0}
    sizes = {"top": (160, 120), "front": (128, 96), "wrist": (80, 60)}
    sim = sim_factory("--cameras", "top:160x120@10,front:128x96@5,wrist@20", "--camera-size", "80x60")
    inboxes = {name: subscribe_camera(ros, sim, name) for name in rates}
    from diagnostic_msgs.msg import DiagnosticArray

    diagnostics = ros.subscribe(sim.name("diagnostics"), DiagnosticArray, best_effort_qos())

    wait_until(lambda: all(images.count() >= 3 for images, _ in inboxes.values()), 30.0, "frames of every camera", sim)
    for images, infos in inboxes.values():
        images.clear()
        infos.clear()
    time.sleep(3.0)

    missing = {}
    for name, (images, infos) in inboxes.items():
        frames = images.messages()
        stamps = [stamp_seconds(m.header.stamp) for m in frames]
        span = stamps[-1] - stamps[0]
        assert span > 1.0, f"{name}: frames cover only {span:.2f} s of sim time"
        # Every frame at its sim-time instant (the rates divide the 100 Hz control rate): frames are a
        # whole number of camera periods apart, one period unless the renderer skipped some (below).
        periods = np.diff(stamps) * rates[name]
        assert np.allclose(periods, np.round(periods), atol=1e-4) and np.all(np.round(periods) >= 1), (
            f"{name}: gaps between frames {sorted(set(np.round(np.diff(stamps), 4)))}"
        )
        missing[name] = int(np.round(periods).sum()) - len(periods)
        width, height = sizes[name]
        for msg in frames:
            assert (msg.width, msg.height) == (width, height), f"{name}: {msg.width}x{msg.height}"
            assert msg.header.frame_id == f"{name}_camera_optical_frame"
        image = image_array(frames[-1])
        assert image.std() > 5, f"{name}: a flat frame (std {image.std():.1f}): nothing rendered"

        info_by_stamp = {stamp_seconds(m.header.stamp): m for m in infos.messages()}
        matched = [info_by_stamp.get(s) for s in stamps]
        assert sum(m is not None for m in matched) >= len(stamps) - 1, f"{name}: CameraInfo missing for frames"
        info = next(m for m in matched if m is not None)
        assert (info.width, info.height) == (width, height)
        assert info.header.frame_id == frames[0].header.frame_id
        assert info.distortion_model == "plumb_bob" and list(info.d) == [0.0] * 5
        assert info.k[0] == pytest.approx(info.k[4]) and info.k[0] > 0, f"{name}: fx {info.k[0]} fy {info.k[4]}"
        assert (info.k[2], info.k[5]) == ((width - 1) / 2, (height - 1) / 2)
        assert list(info.p[:3]) == [info.k[0], 0.0, info.k[2]] and info.p[10] == 1.0

    # The fixed cameras' focal lengths follow their MJCF fovy.
    root = ElementTree.parse(SCENE).getroot()
    for name in ("top", "front"):
        fovy = float(root.find(f"./worldbody/camera[@name='{name}']").get("fovy"))
        info = inboxes[name][1].latest()
        assert info.k[4] == pytest.approx(0.5 * info.height / math.tan(math.radians(fovy) / 2), rel=1e-9)

    diagnostics.wait_for(lambda msgs: camera_values(msgs) is not None, 5.0, "the cameras' /diagnostics status", sim)
    values = camera_values(diagnostics.messages())
    assert "llvmpipe" in values["renderer"] or values["renderer"], values
    for name in rates:
        # A frame missing from the window is one the node counted as skipped (a busy machine's
        # renderer cannot always keep up in real time), never one lost without a word.
        assert int(values[f"{name}.rendered"]) > 0 and int(values[f"{name}.skipped"]) >= missing[name], (missing, values)


@pytest.mark.parametrize("renderer", ["egl", "osmesa"])
def test_the_cube_is_red_where_its_projected_pose_says_and_reset_moves_it(sim_factory, ros, renderer):
    from geometry_msgs.msg import PoseStamped
    from std_srvs.srv import Trigger

    # Seed 4 puts the cube of the second episode about 3 cm from the first, both in view of both
    # cameras (the upright arm hides a cube near y = 0 from the top camera).
    sim = sim_factory(
        "--lockstep", "--renderer", renderer, "--seed", "4", "--cameras", "top:320x240,front:320x240", "--camera-rate", "100"
    )
    cameras = {name: subscribe_camera(ros, sim, name) for name in ("top", "front")}
    poses = ros.subscribe(sim.name("cube/pose"), PoseStamped, reliable_qos(100))
    ros.wait_for_publisher(sim.name("camera/front/image_raw"), 30.0, "the camera publishers", sim)

    def frame_and_pose(name: str):
        """The newest frame of `name`, with the /cube/pose and CameraInfo of the same instant."""
        images, infos = cameras[name]
        image = images.latest()
        stamp = stamp_seconds(image.header.stamp)
        pose = next((m for m in reversed(poses.messages()) if stamp_seconds(m.header.stamp) == stamp), None)
        info = next((m for m in reversed(infos.messages()) if stamp_seconds(m.header.stamp) == stamp), None)
        assert pose is not None and info is not None, f"no /cube/pose or camera_info stamped {stamp}"
        return image_array(image), cube_position(pose), info

    def check_all(label: str) -> dict[str, tuple[float, float]]:
        found = {}
        for name in cameras:
            image, cube, info = frame_and_pose(name)
            u, v, count = red_centroid(image)
            expected = project(cube, name, info)
            error = math.dist((u, v), expected)
            assert error < 2.5, (
                f"{label}, {renderer}, {name}: red centroid ({u:.1f}, {v:.1f}) but the pose projects to ({expected[0]:.1f}, {expected[1]:.1f})"
            )
            found[name] = (u, v)
        return found

    # In lockstep a step is answered once its frames are published.
    step(ros, sim, 3)
    wait_until(lambda: all(images.count() >= 3 for images, _ in cameras.values()), 10.0, "frames of the first steps", sim)
    first = check_all("first episode")

    response = ros.call(Trigger, sim.name("sim/reset"), sim=sim)
    assert response.success, response.message
    # The reset's own frames are out by the time it answers.
    step(ros, sim, 1)
    wait_until(
        lambda: (
            poses.count() > 0
            and all(
                stamp_seconds(images.latest().header.stamp) == stamp_seconds(poses.latest().header.stamp)
                for images, _ in cameras.values()
            )
        ),
        10.0,
        "frames of the new episode",
        sim,
    )
    second = check_all("after /sim/reset")
    for name in cameras:
        moved = math.dist(first[name], second[name])
        assert moved > 5, f"{name}: the cube's pixels moved only {moved:.1f} px after /sim/reset"


def test_egl_and_osmesa_render_the_same_frame(sim_factory, ros):
    frames = {}
    for renderer in ("egl", "osmesa"):
        # A namespace each: the second node's services must not be confused with the first's.
        sim = sim_factory("--lockstep", "--renderer", renderer, "--cameras", "front:160x120@100", "--namespace", renderer)
        images, _ = subscribe_camera(ros, sim, "front")
        ros.wait_for_publisher(sim.name("camera/front/image_raw"), 30.0, "the camera publisher", sim)
        step(ros, sim, 2)
        wait_until(
            lambda: images.count() >= 1 and stamp_seconds(images.latest().header.stamp) >= 0.02 - 1e-9,
            10.0,
            "the frame of the second step",
            sim,
        )
        frames[renderer] = image_array(images.latest()).astype(int)
        assert sim.stop() == 0
    difference = np.abs(frames["egl"] - frames["osmesa"]).mean()
    assert difference < 1.0, f"EGL and OSMesa frames differ by {difference:.2f} levels on average"


# =========================================================================== time modes
def test_real_time_is_kept_while_frames_are_skipped_and_counted(sim_factory, ros):
    from diagnostic_msgs.msg import DiagnosticArray
    from rosgraph_msgs.msg import Clock

    # Far more than this CPU renders: 3 x 640x480 at 60 Hz.
    sim = sim_factory("--cameras", "top,front,wrist", "--camera-rate", "60")
    clock = ros.subscribe(sim.name("clock"), Clock, best_effort_qos(1000))
    diagnostics = ros.subscribe(sim.name("diagnostics"), DiagnosticArray, best_effort_qos())
    clock.wait_count(10, 30.0, sim)
    time.sleep(1.0)  # past the start-up
    clock.clear()
    time.sleep(4.0)
    items = clock.items()
    wall = items[-1][0] - items[0][0]
    simulated = stamp_seconds(items[-1][1].clock) - stamp_seconds(items[0][1].clock)
    assert simulated / wall == pytest.approx(1.0, abs=0.05), f"{simulated:.3f} s simulated in {wall:.3f} s of wall time"
    diagnostics.wait_for(lambda msgs: camera_values(msgs) is not None, 5.0, "the cameras' status", sim)
    values = camera_values(diagnostics.messages())
    skipped = sum(int(values[f"{n}.skipped"]) for n in ("top", "front", "wrist"))
    rendered = sum(int(values[f"{n}.rendered"]) for n in ("top", "front", "wrist"))
    assert skipped > 0 and rendered > 0, values
    assert values["_level"] == 1, f"skipped frames should raise a WARN: {values}"


@pytest.mark.parametrize("mode", [["--speed", "3"], ["--speed", "max"], ["--lockstep"]])
def test_speed_and_lockstep_modes_render_every_frame_at_its_instant(sim_factory, ros, mode):
    sim = sim_factory(*mode, "--cameras", "top:96x72@25")
    images, _ = subscribe_camera(ros, sim, "top", depth=1000)
    ros.wait_for_publisher(sim.name("camera/top/image_raw"), 30.0, "the camera publisher", sim)
    if "--lockstep" in mode:
        step(ros, sim, 60)
    wait_until(lambda: images.count() >= 15, 30.0, "frames", sim)
    stamps = [stamp_seconds(m.header.stamp) for m in images.messages()][:15]
    assert np.allclose(np.diff(stamps), 0.04, atol=1e-6), f"{mode}: frame instants {stamps}"
    assert sim.stop() == 0
    skipped = [line for line in sim.log().splitlines() if "camera frames" in line]
    assert skipped and all("skipped=0" in line for line in skipped), skipped


# =========================================================================== JPEG and flags
def test_jpeg_frames_decode_to_the_raw_frame(sim_factory, ros):
    from PIL import Image as PilImage
    from sensor_msgs.msg import CompressedImage

    sim = sim_factory("--lockstep", "--cameras", "front:160x120", "--jpeg", "--jpeg-quality", "95")
    raw, _ = subscribe_camera(ros, sim, "front")
    compressed = ros.subscribe(sim.name("camera/front/image_raw/compressed"), CompressedImage, reliable_qos(10))
    ros.wait_for_publisher(sim.name("camera/front/image_raw/compressed"), 30.0, "the JPEG publisher", sim)
    # The frame of the sim's start went out before these subscriptions existed, and a step of
    # 10 ms renders no frame of a 30 Hz camera: step until one is rendered after both subscriptions
    # were matched (each step is answered once its frames are published).
    for _ in range(100):
        step(ros, sim, 1)
        if raw.count() >= 1 and compressed.count() >= 1:
            break
    wait_until(
        lambda: raw.count() >= 1 and compressed.count() >= 1 and raw.latest().header.stamp == compressed.latest().header.stamp,
        10.0,
        "a raw and a JPEG frame of the same instant",
        sim,
    )
    jpeg = compressed.latest()
    assert "jpeg" in jpeg.format
    decoded = np.asarray(PilImage.open(io.BytesIO(bytes(jpeg.data))).convert("RGB")).astype(int)
    original = image_array(raw.latest()).astype(int)
    assert decoded.shape == original.shape
    assert np.abs(decoded - original).mean() < 4.0
    assert len(jpeg.data) < original.size / 3


def test_bad_camera_flags_are_refused_with_a_message():
    import subprocess

    from harness import node_binary, node_environment

    def run(*args):
        return subprocess.run(
            [str(node_binary()), "--lite", *args], env=node_environment(), capture_output=True, text=True, timeout=60
        )

    for args, words in {
        ("--cameras", "top:0x480"): "frame size",
        ("--cameras", "top@0"): "camera rate",
        ("--cameras", "top,top"): "twice",
        ("--camera-size", "640"): "frame size",
        ("--jpeg-quality", "0"): "--jpeg-quality",
        ("--renderer", "vulkan"): "--renderer",
    }.items():
        done = run(*args)
        assert done.returncode == 2 and words in done.stderr, (args, done.stderr)
    done = run("--cameras", "top,periscope", "--duration", "1")
    assert done.returncode == 1 and '"periscope"' in done.stderr, done.stderr


def test_every_venv_python_gets_the_fast_dds_profile_for_large_images():
    """rclpy receives 640x480 frames only with the project's socket buffers; the venv's Python sets
    them for itself, with nothing sourced (no DDS participant is opened here)."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k not in ("FASTRTPS_DEFAULT_PROFILES_FILE", "RMW_IMPLEMENTATION")}
    done = subprocess.run(
        [
            sys.executable,
            "-c",
            "import os; print(os.environ['FASTRTPS_DEFAULT_PROFILES_FILE']); print(os.environ['RMW_IMPLEMENTATION'])",
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    profile, rmw = done.stdout.split()
    assert profile == str(REPO_ROOT / "python" / "fastdds_profile.xml") and rmw == "rmw_fastrtps_cpp", done.stdout
    assert "listenSocketBufferSize" in (REPO_ROOT / "python" / "fastdds_profile.xml").read_text()
