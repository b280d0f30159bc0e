"""so101_camera_node serving fake cameras (the in-process test source behind the same interface as
a V4L2 device), seen by rclpy: the JPEG frames decode (Pillow) to the picture the fake served,
stamped 1/fps apart at their capture instants; rgb8 frames and CameraInfo of the same instants;
YUYV cameras come out as JPEG; truncated frames are never published; device drops, stalls and an
unplug are reported on /diagnostics and the camera is reopened when it comes back."""

from __future__ import annotations

import re
import signal
import subprocess
import time

import numpy as np
import pytest
from fake_camera import decoded, picture
from harness import SimNode, node_binary, node_environment, reliable_qos, stamp_seconds, wait_until

BINARY = "so101_camera_node"


def start(tmp_path, *cameras: str, extra: tuple[str, ...] = ()) -> SimNode:
    args = [arg for camera in cameras for arg in ("--camera", camera)]
    return SimNode(node_binary(BINARY), [*args, *extra], tmp_path / "camera_node.log")


def subscribe(ros, name: str, depth: int = 200):
    from sensor_msgs.msg import CameraInfo, CompressedImage, Image

    base = f"/camera/{name}"
    return (
        ros.subscribe(f"{base}/image_raw/compressed", CompressedImage, reliable_qos(depth)),
        ros.subscribe(f"{base}/image_raw", Image, reliable_qos(depth)),
        ros.subscribe(f"{base}/camera_info", CameraInfo, reliable_qos(depth)),
    )


def camera_status(array, name: str):
    return next((status for status in array.status if status.name == f"so101_camera_node: {name}"), None)


def test_mjpeg_frames_arrive_as_served_stamped_at_capture_with_raw_and_camera_info(ros, tmp_path):
    node = start(tmp_path, "top=fake:64x48@30", extra=("--raw",))
    try:
        compressed, raw, info = subscribe(ros, "top")
        frames = compressed.wait_count(20, 20.0, node)
        received_at = time.time()
        for message in frames:
            assert message.format == "rgb8; jpeg compressed bgr8"
            assert bytes(message.data[:2]) == b"\xff\xd8" and bytes(message.data[-2:]) == b"\xff\xd9"
            image = decoded(message)
            sequence = int(round(image[:, :, 2].mean() / 8))
            assert np.abs(image - picture(64, 48, sequence)).mean() < 3.0, f"frame {sequence} is not the fake's picture"
        stamps = [stamp_seconds(m.header.stamp) for m in frames]
        gaps = np.diff(stamps)
        assert np.all(np.abs(gaps - 1 / 30) < 1e-3), f"capture instants not 1/30 s apart: {gaps}"
        assert stamps[-1] <= received_at, "a stamp after the frame arrived: not the capture instant"
        assert frames[0].header.frame_id == "top_camera_optical_frame"
        # The rgb8 frame and the CameraInfo of an instant carry its stamp.
        wait_until(lambda: raw.count() >= 5 and info.count() >= 5, 10.0, "rgb8 frames and camera_info", node)
        image = raw.messages()[-1]
        camera_info = info.messages()[-1]
        # The three topics arrive in no set order: the JPEG of each instant may still be on its way.
        wanted = {stamp_seconds(image.header.stamp), stamp_seconds(camera_info.header.stamp)}
        wait_until(
            lambda: wanted <= {stamp_seconds(m.header.stamp) for m in compressed.messages()},
            10.0,
            "the JPEG frames of the rgb8 frame's and the camera_info's instants",
            node,
        )
        by_stamp = {stamp_seconds(m.header.stamp): m for m in compressed.messages()}
        assert (image.width, image.height, image.encoding) == (64, 48, "rgb8")
        pixels = np.frombuffer(bytes(image.data), dtype=np.uint8).reshape(48, 64, 3).astype(np.int64)
        twin = by_stamp[stamp_seconds(image.header.stamp)]
        assert np.abs(pixels - decoded(twin)).mean() < 2.0
        assert (camera_info.width, camera_info.height) == (64, 48)
        node.assert_alive()
    finally:
        assert node.stop() == 0, node.log_tail()


def test_broken_dropped_stalled_and_unplugged_frames_are_counted_and_the_camera_comes_back(ros, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

    node = start(
        tmp_path,
        "top=fake:32x24@50,truncate_every=5,drop_every=7,unplug_at=40:3",
        "wrist=fake:yuyv,32x24@25",
    )
    try:
        top, _, _ = subscribe(ros, "top", depth=1000)
        wrist, _, _ = subscribe(ros, "wrist")
        diagnostics = ros.subscribe("/diagnostics", DiagnosticArray, reliable_qos(100))

        def seen(level: int) -> bool:
            return any((s := camera_status(m, "top")) is not None and s.level == level for m in diagnostics.messages())

        wait_until(lambda: seen(DiagnosticStatus.ERROR), 20.0, "the unplug on /diagnostics", node)
        unplugged_count = top.count()
        wait_until(lambda: top.count() > unplugged_count + 20, 20.0, "frames after the camera came back", node)
        wait_until(lambda: seen(DiagnosticStatus.OK), 10.0, "the camera streaming again on /diagnostics", node)
        values = {kv.key: kv.value for kv in camera_status(diagnostics.latest(), "top").values}
        # A gap counts as the node's when the frame after it had waited (a loaded machine): either way
        # it is counted.
        drops = int(values["device_drops"]) + int(values["node_drops"])
        assert int(values["broken_frames"]) > 0 and drops > 0, values
        assert int(values["unplugs"]) >= 1, values
        # No truncated frame was published: every JPEG is whole and decodes.
        for message in top.messages():
            assert bytes(message.data[-2:]) == b"\xff\xd9"
            decoded(message)
        # The YUYV camera comes out as JPEG of its picture.
        message = wrist.wait_count(3, 10.0, node)[-1]
        image = decoded(message)
        sequence = int(round(image[:, :, 2].mean() / 8))
        assert np.abs(image - picture(32, 24, sequence)).mean() < 4.0
        node.assert_alive()
    finally:
        assert node.stop() == 0, node.log_tail()


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(node_binary(BINARY)), *args], env=node_environment(), capture_output=True, text=True, timeout=60)


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--camera", "top=/dev/video77"], "--camera top: no camera at /dev/video77"),
        (["--camera", "top=fake:", "--control", "top.exposure=99999"], "exposure 99999 is outside the camera's 1..=5000"),
        (["--camera", "top=fake:", "--control", "top.focus=10"], "the camera has no focus control"),
        (["--camera", "top=fake:", "--control", "wrist.gain=10"], "no --camera wrist"),
        (["--camera", "top=fake:", "--control", "top.gain=auto"], "the camera has no automatic gain"),
        (["--camera", "top=fake:", "--calibration", "top=/nonexistent.yaml"], "--calibration top=/nonexistent.yaml"),
        (["--camera", "top=fake:hdr"], "not understood"),
        (["--camera", "top"], "NAME=DEVICE"),
        ([], "--camera"),
    ],
)
def test_bad_cameras_are_refused_with_the_reason(args, says):
    done = run(*args)
    assert done.returncode != 0 and says in done.stderr, done.stderr


def test_a_calibration_of_another_size_or_shape_is_refused(tmp_path):
    wrong_size = tmp_path / "wrong_size.yaml"
    wrong_size.write_text(calibration_yaml(1280, 720))
    done = run("--camera", "top=fake:", "--calibration", f"top={wrong_size}")
    assert done.returncode != 0 and "the calibration is of 1280x720 images, the camera streams 640x480" in done.stderr, (
        done.stderr
    )
    malformed = tmp_path / "malformed.yaml"
    malformed.write_text(calibration_yaml(640, 480).replace("rows: 3\n  cols: 4", "rows: 4\n  cols: 4"))
    done = run("--camera", "top=fake:", "--calibration", f"top={malformed}")
    assert done.returncode != 0 and "projection_matrix is 4x4" in done.stderr, done.stderr


def test_list_without_cameras_lists_this_machine_s_video_devices():
    from pathlib import Path

    done = run("--list")
    assert done.returncode == 0, done.stderr
    devices = sorted(Path("/dev").glob("video*"))
    if devices:
        assert str(devices[0]) in done.stdout, done.stdout
    else:
        assert "no video device" in done.stdout, done.stdout


def test_list_prints_the_modes_a_camera_offers():
    done = run("--list", "--camera", "top=fake:yuyv,320x240@15")
    assert done.returncode == 0, done.stderr
    assert "top=fake:yuyv,320x240@15: YUYV 320x240@15,7.5" in done.stdout, done.stdout


def calibration_yaml(width: int, height: int) -> str:
    """A calibration file as ROS's camera_calibration writes it (ost.yaml)."""
    return f"""image_width: {width}
image_height: {height}
camera_name: top
camera_matrix:
  rows: 3
  cols: 3
  data: [61.25, 0, 31.5, 0, 61.5, 23.5, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [0.11, -0.24, 0.001, -0.002, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [62.0, 0, 31.0, 0, 0, 62.5, 23.0, 0, 0, 0, 1, 0]
"""


def test_camera_info_carries_the_calibration_file_s_matrices(ros, tmp_path):
    from sensor_msgs.msg import CameraInfo

    calibration = tmp_path / "top.yaml"
    calibration.write_text(calibration_yaml(64, 48))
    node = start(tmp_path, "top=fake:64x48@30", extra=("--calibration", f"top={calibration}"))
    try:
        info = ros.subscribe("/camera/top/camera_info", CameraInfo, reliable_qos(10))
        message = info.wait_count(1, 20.0, node)[-1]
        assert (message.width, message.height) == (64, 48)
        assert message.distortion_model == "plumb_bob"
        assert list(message.d) == pytest.approx([0.11, -0.24, 0.001, -0.002, 0.0])
        assert list(message.k) == pytest.approx([61.25, 0, 31.5, 0, 61.5, 23.5, 0, 0, 1])
        assert list(message.p) == pytest.approx([62.0, 0, 31.0, 0, 0, 62.5, 23.0, 0, 0, 0, 1, 0])
    finally:
        assert node.stop() == 0, node.log_tail()


def test_image_controls_are_parameters_set_at_start_and_at_run_time_and_kept_over_an_unplug(ros, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    from parameter_peer import ParameterPeer

    node = start(
        tmp_path,
        "top=fake:32x24@30,unplug_at=300:2",
        extra=("--control", "top.exposure=156", "--control", "top.white_balance=4000"),
    )
    try:
        diagnostics = ros.subscribe("/diagnostics", DiagnosticArray, reliable_qos(100))

        def controls() -> dict[str, str]:
            latest = diagnostics.latest()
            status = camera_status(latest, "top") if latest is not None else None
            return {kv.key: kv.value for kv in status.values} if status is not None else {}

        wait_until(lambda: controls().get("exposure") == "156", 20.0, "the start exposure on /diagnostics", node)
        assert controls()["white_balance"] == "4000" and controls()["gain"] == "32", controls()
        peer = ParameterPeer(ros, "/so101_camera_node", node)
        assert peer.get("top.exposure", "top.gain", "top.white_balance") == [156, 32, 4000]
        assert "top.focus" not in peer.names(), "the fake camera has no focus control"
        # At run time: automatic exposure, a manual gain; a gain outside the camera's range is refused.
        results = peer.set(**{"top.exposure": -1, "top.gain": 50})
        assert all(result.successful for result in results), results
        refused = peer.set(**{"top.gain": 500})[0]
        assert not refused.successful and "100" in refused.reason, refused
        wait_until(
            lambda: controls().get("exposure") == "-1" and controls().get("gain") == "50",
            10.0,
            "the new controls on /diagnostics",
            node,
        )
        assert controls()["unplugs"] == "0", "the camera went away before the run-time settings were seen"
        # The fake forgets its controls when unplugged (as a camera does); the node sets them again.
        wait_until(
            lambda: controls().get("unplugs") == "1" and controls().get("mode", "").startswith("MJPG"),
            20.0,
            "the camera back after its unplug",
            node,
        )
        wait_until(lambda: controls().get("gain") == "50", 10.0, "the gain set again after the unplug", node)
        assert controls()["exposure"] == "-1" and controls()["white_balance"] == "4000", controls()
        node.assert_alive()
    finally:
        assert node.stop() == 0, node.log_tail()


def test_wait_waits_for_a_camera_that_is_not_plugged_in(tmp_path):
    node = start(tmp_path, f"top={tmp_path / 'video9'}", extra=("--wait",))
    try:
        wait_until(lambda: "waiting for the camera" in node.log_tail(), 20.0, "the wait in the log", node)
        time.sleep(1.0)
        node.assert_alive()
    finally:
        assert node.stop() == 0, node.log_tail()


def test_rerun_shows_the_camera_node_s_jpeg_frames(ros, tmp_path):
    from harness import rrd_entities

    node = start(tmp_path, "top=fake:64x48@30")
    output = tmp_path / "live.rrd"
    bridge = subprocess.Popen(
        [str(node_binary("so101_rerun")), "live", "--save", str(output), "--cameras", "top", "--image-rate", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=node_environment(),
    )
    try:
        ros.wait_for_graph(lambda: ros.node.count_subscribers("/camera/top/image_raw/compressed") >= 1, 20.0, "the bridge", node)
        time.sleep(2.0)
    finally:
        bridge.send_signal(signal.SIGINT)  # it flushes the recording and exits
        out, _ = bridge.communicate(timeout=60)
        assert node.stop() == 0, node.log_tail()
    assert bridge.returncode == 0, out
    frames = rrd_entities(output).get("/cameras/top", 0)
    assert frames > 40, f"{frames} camera frames in the recording of over 2 s at 30 fps"


def test_a_timed_run_ends_with_each_camera_s_rate_losses_and_latency():
    """What a user checks a camera with (docs/real_arm.md): a run of --duration seconds ends with
    one line per camera."""
    cameras = ["top=fake:64x48@30", "wrist=fake:64x48@30,drop_every=10", "front=fake:64x48@30,damage_every=10,fail_at=40"]
    done = run(*[arg for camera in cameras for arg in ("--camera", camera)], "--duration", "3")
    assert done.returncode == 0, done.stderr
    lines = {line.split(":", 1)[0]: line for line in done.stdout.splitlines() if ": " in line and "frames in" in line}
    counts = r"(\d+) dropped by the camera or USB, (\d+) dropped while the node was behind, (\d+) broken"
    top = re.match(r"top: (\d+) frames in ([\d.]+) s \(([\d.]+) fps\), " + counts, lines["top"])
    assert top is not None, done.stdout
    assert 25.0 <= float(top.group(3)) <= 35.0 and top.group(4, 5, 6) == ("0", "0", "0"), lines["top"]
    p50, p99 = map(float, re.search(r"latency p50 ([\d.]+) ms, p99 ([\d.]+) ms", lines["top"]).groups())
    assert 0.0 <= p50 <= p99 < 100.0, lines["top"]
    wrist = [int(n) for n in re.search(counts, lines["wrist"]).groups()]
    assert wrist[0] + wrist[1] >= 5 and wrist[2] == 0, lines["wrist"]
    # A frame the driver marks damaged is broken, and not also a gap in the sequence.
    front = [int(n) for n in re.search(counts, lines["front"]).groups()]
    assert front[2] >= 5 and front[:2] == [0, 0], lines["front"]
    # A failed stream (EIO) is started again and said so; it is not an unplug.
    errors = re.search(r"(\d+) unplugs, (\d+) stream errors", lines["front"])
    assert errors is not None and errors.group(1) == "0" and int(errors.group(2)) >= 1, lines["front"]
    # Without an image_raw reader the node does not log errors (ros2-client's per-publisher count
    # logged one every 50 ms until a reader matched).
    assert "not known to node" not in done.stderr and " ERROR " not in done.stderr, done.stderr[-3000:]


def test_rgb8_frames_are_decoded_for_an_image_raw_subscriber_without_raw(ros, tmp_path):
    node = start(tmp_path, "top=fake:64x48@30")
    try:
        compressed, raw, _ = subscribe(ros, "top")
        image = raw.wait_count(3, 20.0, node)[-1]
        assert (image.width, image.height, image.encoding) == (64, 48, "rgb8")
        pixels = np.frombuffer(bytes(image.data), dtype=np.uint8).reshape(48, 64, 3).astype(np.int64)
        sequence = int(round(pixels[:, :, 2].mean() / 8))
        assert np.abs(pixels - picture(64, 48, sequence)).mean() < 3.0
        node.assert_alive()
    finally:
        assert node.stop() == 0, node.log_tail()
