"""Values out of the stack's ROS messages, shared by the bag reader and the rclpy tools (the same
decoding whether a message comes from a bag or from a live topic)."""

from __future__ import annotations

import numpy as np

from .units import JOINT_NAMES


def joint_positions(msg) -> np.ndarray | None:
    """The six positions (rad) of a sensor_msgs/JointState in contract order, or None when it does
    not name all six (messages may name joints in any order, or only some of them)."""
    by_name = dict(zip(msg.name, msg.position))
    if not all(name in by_name for name in JOINT_NAMES):
        return None
    return np.array([by_name[name] for name in JOINT_NAMES], dtype=np.float64)


def rgb_image(msg) -> np.ndarray:
    """A sensor_msgs/Image as an H x W x 3 uint8 RGB array of its own (writable; rgb8 or bgr8, rows
    may be padded). Raises ValueError for other encodings or a short buffer."""
    if msg.encoding not in ("rgb8", "bgr8"):
        raise ValueError(f"image encoding {msg.encoding!r}, expected rgb8 or bgr8")
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    if msg.step < msg.width * 3 or data.size < msg.step * msg.height:
        raise ValueError(f"image of {data.size} bytes too short for {msg.width}x{msg.height} (step {msg.step})")
    image = data[: msg.step * msg.height].reshape(msg.height, msg.step)[:, : msg.width * 3].reshape(msg.height, msg.width, 3)
    return (image[..., ::-1] if msg.encoding == "bgr8" else image).copy()


def cube_pose_vector(pose) -> np.ndarray:
    """A geometry_msgs/Pose as [x, y, z, qw, qx, qy, qz] (the environment state's layout)."""
    p, q = pose.position, pose.orientation
    return np.array([p.x, p.y, p.z, q.w, q.x, q.y, q.z], dtype=np.float64)
