"""so101_camera_node serving fake cameras (the in-process test source behind the same interface as
a V4L2 device), seen by rclpy: the JPEG frames decode (Pillow) to the picture the fake served,
stamped 1/fps apart at their capture instants; rgb8 frames and CameraInfo of the same instants;
YUYV cameras come out as JPEG; truncated frames are never published; device drops, stalls and an
unplug are reported on /diagnostics and the camera is reopened when it comes back."""

from __future__ import annotations

import io
import subprocess
import time

import numpy as np
import pytest
from harness import SimNode, node_binary, node_environment, reliable_qos, stamp_seconds, wait_until

BINARY = "so101_camera_node"


def picture(width: int, height: int, sequence: int) -> np.ndarray:
    """The fake camera's picture of frame `sequence` (so101_camera_node::fake::picture)."""
    x = np.arange(width) * 255 // max(width - 1, 1)
    y = np.arange(height) * 255 // max(height - 1, 1)
    image = np.zeros((height, width, 3), dtype=np.int64)
    image[:, :, 0] = x[None, :]
    image[:, :, 1] = y[:, None]
    image[:, :, 2] = (sequence * 8) % 256
    return image


def decoded(message) -> np.ndarray:
    from PIL import Image as PilImage

    return np.asarray(PilImage.open(io.BytesIO(bytes(message.data))).convert("RGB")).astype(np.int64)


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
        by_stamp = {stamp_seconds(m.header.stamp): m for m in compressed.messages()}
        image = raw.messages()[-1]
        assert (image.width, image.height, image.encoding) == (64, 48, "rgb8")
        pixels = np.frombuffer(bytes(image.data), dtype=np.uint8).reshape(48, 64, 3).astype(np.int64)
        twin = by_stamp.get(stamp_seconds(image.header.stamp))
        assert twin is not None, "no JPEG frame of the rgb8 frame's instant"
        assert np.abs(pixels - decoded(twin)).mean() < 2.0
        camera_info = info.messages()[-1]
        assert (camera_info.width, camera_info.height) == (64, 48)
        assert stamp_seconds(camera_info.header.stamp) in by_stamp
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
        assert int(values["broken_frames"]) > 0 and int(values["device_drops"]) > 0, values
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
        (["--camera", "top=/dev/video7"], "no V4L2 backend"),
        (["--camera", "top=fake:hdr"], "not understood"),
        (["--camera", "top"], "NAME=DEVICE"),
        ([], "--camera"),
    ],
)
def test_bad_cameras_are_refused_with_the_reason(args, says):
    done = run(*args)
    assert done.returncode != 0 and says in done.stderr, done.stderr


def test_list_prints_the_modes_a_camera_offers():
    done = run("--list", "--camera", "top=fake:yuyv,320x240@15")
    assert done.returncode == 0, done.stderr
    assert "top=fake:yuyv,320x240@15: YUYV 320x240@15,7.5" in done.stdout, done.stdout
