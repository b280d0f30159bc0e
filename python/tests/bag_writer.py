"""Synthetic episode bags for the converter's tests, written independently of the stack: the MCAP
through mcap-ros2-support's writer with the standard ROS 2 message definitions, metadata.yaml in
rosbag2's format (version 9) as recorder_node writes it. No DDS.

Times are sim seconds; every message is logged at WALL_OFFSET + its sim time (a recorder that
received everything at once), so receive times map to sim time exactly."""

from __future__ import annotations

import math
from pathlib import Path

from mcap_ros2.writer import Writer

from so101 import contract

WALL_OFFSET = 1_000.0
SEPARATOR = "=" * 80

TIME = "int32 sec\nuint32 nanosec\n"
HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
DEFINITIONS = {
    "sensor_msgs/msg/JointState": (
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n",
        [("std_msgs/Header", HEADER), ("builtin_interfaces/Time", TIME)],
    ),
    "std_msgs/msg/Float64MultiArray": (
        "std_msgs/MultiArrayLayout layout\nfloat64[] data\n",
        [
            ("std_msgs/MultiArrayLayout", "std_msgs/MultiArrayDimension[] dim\nuint32 data_offset\n"),
            ("std_msgs/MultiArrayDimension", "string label\nuint32 size\nuint32 stride\n"),
        ],
    ),
    "sensor_msgs/msg/Image": (
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\nuint8[] data\n",
        [("std_msgs/Header", HEADER), ("builtin_interfaces/Time", TIME)],
    ),
    "sensor_msgs/msg/CompressedImage": (
        "std_msgs/Header header\nstring format\nuint8[] data\n",
        [("std_msgs/Header", HEADER), ("builtin_interfaces/Time", TIME)],
    ),
    "geometry_msgs/msg/PoseStamped": (
        "std_msgs/Header header\ngeometry_msgs/Pose pose\n",
        [
            ("std_msgs/Header", HEADER),
            ("builtin_interfaces/Time", TIME),
            ("geometry_msgs/Pose", "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n"),
            ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n"),
            ("geometry_msgs/Quaternion", "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n"),
        ],
    ),
    "std_msgs/msg/Float64": ("float64 data\n", []),
    "std_msgs/msg/Bool": ("bool data\n", []),
}


def schema_text(type_name: str) -> str:
    definition, dependencies = DEFINITIONS[type_name]
    return definition + "".join(f"{SEPARATOR}\nMSG: {name}\n{text}" for name, text in dependencies)


def header(t: float) -> dict:
    sec = math.floor(t)
    return {"stamp": {"sec": sec, "nanosec": int(round((t - sec) * 1e9))}, "frame_id": ""}


class EpisodeBag:
    """Messages of one episode, written by `close`."""

    def __init__(self, directory: Path):
        self.directory = Path(directory)
        self.messages: list[tuple[float, str, str, dict]] = []  # (sim time, topic, type, message)

    def add(self, t: float, topic: str, type_name: str, message: dict) -> None:
        self.messages.append((t, topic, type_name, message))

    def joint_state(self, t: float, positions, names=contract.JOINT_NAMES) -> None:
        self.add(
            t,
            "/" + contract.JOINT_STATES,
            "sensor_msgs/msg/JointState",
            {"header": header(t), "name": list(names), "position": [float(p) for p in positions], "velocity": [], "effort": []},
        )

    def command(self, t: float, names, positions, stamp: float | None = None) -> None:
        """A /joint_commands message received at `t`, stamped `stamp` (default `t`; 0: none)."""
        self.add(
            t,
            "/" + contract.JOINT_COMMANDS,
            "sensor_msgs/msg/JointState",
            {
                "header": header(t if stamp is None else stamp),
                "name": list(names),
                "position": [float(p) for p in positions],
                "velocity": [],
                "effort": [],
            },
        )

    def array_command(self, t: float, values) -> None:
        self.add(
            t,
            "/" + contract.FORWARD_POSITION_COMMANDS,
            "std_msgs/msg/Float64MultiArray",
            {"layout": {"dim": [], "data_offset": 0}, "data": [float(v) for v in values]},
        )

    def image(self, t: float, camera: str, width: int, height: int, value: int = 0, pixels: bytes | None = None) -> None:
        """An rgb8 sensor_msgs/Image: every byte `value`, or `pixels` (height x width x 3 bytes)."""
        self.add(
            t,
            "/" + contract.camera_topic(camera),
            "sensor_msgs/msg/Image",
            {
                "header": header(t),
                "height": height,
                "width": width,
                "encoding": "rgb8",
                "is_bigendian": 0,
                "step": width * 3,
                "data": pixels if pixels is not None else bytes([value % 256]) * (width * height * 3),
            },
        )

    def compressed_image(self, t: float, camera: str, data: bytes, format: str = "rgb8; jpeg compressed bgr8") -> None:
        """A sensor_msgs/CompressedImage on /camera/CAMERA/image_raw/compressed, as image_transport
        publishes it (`data`: the JPEG or PNG file's bytes)."""
        self.add(
            t,
            "/" + contract.camera_topic(camera, contract.IMAGE_COMPRESSED),
            "sensor_msgs/msg/CompressedImage",
            {"header": header(t), "format": format, "data": data},
        )

    def cube(self, t: float, x: float = 0.2, y: float = 0.0, z: float = 0.0125) -> None:
        self.add(
            t,
            "/" + contract.CUBE_POSE,
            "geometry_msgs/msg/PoseStamped",
            {
                "header": header(t),
                "pose": {"position": {"x": x, "y": y, "z": z}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
            },
        )

    def reward(self, t: float, value: float) -> None:
        self.add(t, "/" + contract.TASK_REWARD, "std_msgs/msg/Float64", {"data": float(value)})

    def success(self, t: float, value: bool) -> None:
        self.add(t, "/" + contract.TASK_SUCCESS, "std_msgs/msg/Bool", {"data": bool(value)})

    def close(
        self,
        task: str = "put the cube in the bin",
        success: bool | None = True,
        metadata: str | None = None,
        closed: bool = True,
        chunk_size: int = 1024 * 1024,
    ) -> Path:
        """Writes <directory>/<name>_0.mcap (in chunks of about `chunk_size` bytes) and
        metadata.yaml (`metadata`: its text instead; none unless `closed`: a recorder killed)."""
        self.directory.mkdir(parents=True, exist_ok=True)
        file_name = f"{self.directory.name}_0.mcap"
        messages = sorted(self.messages, key=lambda m: m[0])
        counts: dict[tuple[str, str], int] = {}
        with open(self.directory / file_name, "wb") as stream:
            writer = Writer(stream, chunk_size=chunk_size)
            schemas = {}
            for t, topic, type_name, message in messages:
                if type_name not in schemas:
                    schemas[type_name] = writer.register_msgdef(type_name, schema_text(type_name))
                writer.write_message(topic, schemas[type_name], message, log_time=int(round((WALL_OFFSET + t) * 1e9)))
                counts[(topic, type_name)] = counts.get((topic, type_name), 0) + 1
            writer.finish()
        if not closed:
            return self.directory
        if metadata is None:
            metadata = metadata_yaml(self.directory, file_name, messages, counts, task, success)
        (self.directory / contract.EPISODE_METADATA_FILE).write_text(metadata)
        return self.directory


def metadata_yaml(directory: Path, file_name: str, messages, counts, task: str, success: bool | None) -> str:
    start = int(round((WALL_OFFSET + messages[0][0]) * 1e9)) if messages else 0
    duration = int(round((messages[-1][0] - messages[0][0]) * 1e9)) if messages else 0
    lines = [
        "rosbag2_bagfile_information:",
        "  version: 9",
        "  storage_identifier: mcap",
        f"  duration:\n    nanoseconds: {duration}",
        f"  starting_time:\n    nanoseconds_since_epoch: {start}",
        f"  message_count: {len(messages)}",
        "  topics_with_message_count:",
    ]
    for (topic, type_name), count in counts.items():
        lines += [
            "    - topic_metadata:",
            f'        name: "{topic}"',
            f'        type: "{type_name}"',
            "        serialization_format: cdr",
            '        offered_qos_profiles: ""',
            '        type_description_hash: ""',
            f"      message_count: {count}",
        ]
    index = directory.name.rpartition("_")[2]
    custom = {contract.CUSTOM_EPISODE_INDEX: str(int(index)) if index.isdigit() else "0", contract.CUSTOM_TASK: task}
    if success is not None:
        custom[contract.CUSTOM_SUCCESS] = "true" if success else "false"
    custom[contract.CUSTOM_SEED] = "7"
    lines += [
        '  compression_format: ""',
        '  compression_mode: ""',
        "  relative_file_paths:",
        f'    - "{file_name}"',
        "  files:",
        f'    - path: "{file_name}"',
        f"      starting_time:\n        nanoseconds_since_epoch: {start}",
        f"      duration:\n        nanoseconds: {duration}",
        f"      message_count: {len(messages)}",
        "  custom_data:",
    ]
    lines += [f'    {key}: "{value}"' for key, value in custom.items()]
    lines.append('  ros_distro: "jazzy"')
    return "\n".join(lines) + "\n"
