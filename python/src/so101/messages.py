"""Values out of the stack's ROS messages, shared by the bag reader and the rclpy tools (the same
decoding whether a message comes from a bag or from a live topic)."""

from __future__ import annotations

import io

import numpy as np

from .units import JOINT_NAMES


def stamp_seconds(message) -> float:
    """A stamped message's header stamp in seconds (sim time from the sim, ROS time from the arm)."""
    return message.header.stamp.sec + message.header.stamp.nanosec * 1e-9


def joint_positions(msg) -> np.ndarray | None:
    """The six positions (rad) of a sensor_msgs/JointState in contract order, or None when it does
    not name all six (messages may name joints in any order, or only some of them)."""
    by_name = dict(zip(msg.name, msg.position))
    if not all(name in by_name for name in JOINT_NAMES):
        return None
    return np.array([by_name[name] for name in JOINT_NAMES], dtype=np.float64)


def rgb_image(msg) -> np.ndarray:
    """A sensor_msgs/Image (rgb8 or bgr8, rows may be padded) or sensor_msgs/CompressedImage (JPEG or
    PNG, decoded with Pillow; gray or RGBA ones converted) as an H x W x 3 uint8 RGB array of its own
    (writable). Raises ValueError for other encodings or formats, a short buffer, or compressed data
    that does not decode (corrupt or truncated)."""
    if is_compressed(msg):
        image = _opened(msg)
        try:
            return np.array(image.convert("RGB"))
        except (OSError, ValueError, SyntaxError) as error:  # Pillow's decoders: truncated or corrupt data
            raise ValueError(f"{image.format} image that does not decode ({error})") from error
    _check_raw(msg)
    data = np.frombuffer(_bytes(msg.data), dtype=np.uint8)
    image = data[: msg.step * msg.height].reshape(msg.height, msg.step)[:, : msg.width * 3].reshape(msg.height, msg.width, 3)
    return (image[..., ::-1] if msg.encoding == "bgr8" else image).copy()


def is_compressed(msg) -> bool:
    """A sensor_msgs/CompressedImage (it has `format`), not a sensor_msgs/Image."""
    return hasattr(msg, "format") and not hasattr(msg, "encoding")


# What a CompressedImage's `format` may say, as image_transport writes it ("rgb8; jpeg compressed
# bgr8", "bgr8; png compressed bgr8") or as older publishers do ("jpeg", "png"); and what Pillow
# must find in the data for each.
_COMPRESSED_KINDS = {"jpeg": "JPEG", "jpg": "JPEG", "png": "PNG"}


def _bytes(data) -> bytes | bytearray | memoryview:
    """A message's uint8[] as a buffer: as it is when it is one (mcap-ros2-support's bytes, rclpy's
    array), else copied into bytes (a list of ints)."""
    return data if isinstance(data, bytes | bytearray | memoryview) else bytes(data)


def _opened(msg):
    """The PIL image of a CompressedImage's data, its header read (pixels not yet decoded)."""
    from PIL import Image, UnidentifiedImageError

    text = msg.format.lower()
    if "compresseddepth" in text:
        raise ValueError(f"compressed image format {msg.format!r}: depth images are not camera frames")
    words = text.replace(";", " ").split()
    kinds = {_COMPRESSED_KINDS[w] for w in words if w in _COMPRESSED_KINDS}
    if len(kinds) != 1:
        raise ValueError(f"compressed image format {msg.format!r}, expected jpeg or png")
    try:
        image = Image.open(io.BytesIO(_bytes(msg.data)))
    except UnidentifiedImageError as error:
        raise ValueError(f"{len(msg.data)} bytes that are no {kinds.pop()} image (no image format recognised)") from error
    except OSError as error:  # a header cut short
        raise ValueError(f"{len(msg.data)} bytes that are no {kinds.pop()} image ({error})") from error
    if image.format not in kinds:
        raise ValueError(f"format {msg.format!r} but the data is {image.format}")
    if image.mode not in ("RGB", "L", "RGBA", "P", "LA", "CMYK", "YCbCr"):
        raise ValueError(f"{image.format} image of mode {image.mode} (16-bit or float), expected 8-bit color or gray")
    return image


def image_size(msg) -> tuple[int, int]:
    """(width, height) of a sensor_msgs/Image or CompressedImage without decoding its pixels (a
    compressed one's header is read). Raises ValueError for a frame rgb_image cannot decode: an
    encoding or format it does not take, a short raw buffer, data that is no image."""
    if is_compressed(msg):
        return _opened(msg).size
    _check_raw(msg)
    return msg.width, msg.height


def _check_raw(msg) -> None:
    if msg.encoding not in ("rgb8", "bgr8"):
        raise ValueError(f"image encoding {msg.encoding!r}, expected rgb8 or bgr8")
    if msg.step < msg.width * 3 or len(msg.data) < msg.step * msg.height:
        raise ValueError(f"image of {len(msg.data)} bytes too short for {msg.width}x{msg.height} (step {msg.step})")


def cube_pose_vector(pose) -> np.ndarray:
    """A geometry_msgs/Pose as [x, y, z, qw, qx, qy, qz] (the environment state's layout)."""
    p, q = pose.position, pose.orientation
    return np.array([p.x, p.y, p.z, q.w, q.x, q.y, q.z], dtype=np.float64)
