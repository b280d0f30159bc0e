"""What the camera VM run left (scripts/vm/vivid_guest.sh), read on the host: the driver's own view
through v4l2-ctl, the node's listing, log and summary, the timeline, and the bag the recorder wrote.
Pure reading; tests/vm/test_vivid.py judges. `python tests/vm/vivid_results.py DIR` prints the
figures docs/benchmarks.md reports."""

from __future__ import annotations

import io
import re
import statistics
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

COMPRESSED = "/camera/top/image_raw/compressed"
CAMERA_INFO = "/camera/top/camera_info"
# The mode the guest script asks for.
WIDTH, HEIGHT, FPS = 320, 180, 15.0
GAIN = 10
# Formats the node takes (modes::PixelFormat).
NODE_FORMATS = ("MJPG", "YUYV")

Modes = dict[tuple[str, int, int], frozenset[float]]


@dataclass(frozen=True)
class Frame:
    stamp: float  # capture instant (header stamp), s
    received: float  # when the recorder logged it, s
    jpeg: bytes


def modes_of_v4l2_ctl(text: str) -> Modes:
    """The (format, width, height) -> rates of `v4l2-ctl --list-formats-ext`, for the formats the
    node takes."""
    modes: dict[tuple[str, int, int], set[float]] = {}
    fourcc = size = None
    for line in text.splitlines():
        if found := re.match(r"\s*\[\d+\]: '(\w{4})'", line):
            fourcc, size = found.group(1), None
        elif found := re.match(r"\s*Size: Discrete (\d+)x(\d+)", line):
            size = (int(found.group(1)), int(found.group(2)))
            if fourcc in NODE_FORMATS:
                modes.setdefault((fourcc, *size), set())
        elif (found := re.search(r"Interval: Discrete [\d.]+s \(([\d.]+) fps\)", line)) and fourcc in NODE_FORMATS:
            modes[(fourcc, *size)].add(float(found.group(1)))
    return {mode: frozenset(rates) for mode, rates in modes.items()}


def modes_of_node(listing: str) -> Modes:
    """The modes of one line of `so101_camera_node --list`: `FMT WxH@r1,r2; ...`."""
    modes = {}
    for fourcc, width, height, rates in re.findall(r"(\w{4}) (\d+)x(\d+)@([\d.,]+)", listing):
        modes[(fourcc, int(width), int(height))] = frozenset(float(rate) for rate in rates.split(","))
    return modes


def summary_counts(log: str) -> dict[str, float]:
    """The numbers of the node's exit summary line for camera `top`."""
    line = next(line for line in log.splitlines() if line.startswith("top: "))
    patterns = {
        "frames": r"top: (\d+) frames",
        "seconds": r"frames in ([\d.]+) s",
        "device_drops": r"(\d+) dropped by the camera",
        "node_drops": r"(\d+) dropped while the node was behind",
        "broken": r"(\d+) broken",
        "unplugs": r"(\d+) unplugs",
        "stream_errors": r"(\d+) stream errors",
        "latency_p50_ms": r"latency p50 ([\d.]+) ms",
        "stamped_ahead": r"(\d+) frames stamped after the node's clock",
    }
    counts = {}
    for key, pattern in patterns.items():
        found = re.search(pattern, line)
        # Latency: only of frames stamped before the node's clock; none stamped after: 0.
        counts[key] = float(found.group(1)) if found else (None if key == "latency_p50_ms" else 0.0)
    return counts


def controls_of(text: str) -> dict[str, int]:
    """`v4l2-ctl --get-ctrl=a,b` output as {name: value}."""
    return {name: int(value) for name, value in re.findall(r"^(\w+): (-?\d+)$", text, re.MULTILINE)}


class Results:
    def __init__(self, directory: Path):
        self.dir = Path(directory)

    def text(self, name: str) -> str:
        return (self.dir / name).read_text(errors="replace")

    def exit_code(self, name: str) -> int:
        return int(self.text(name).strip())

    def events(self) -> dict[str, float]:
        """Each step of the guest script and its wall-clock time (the clock the bag's stamps use)."""
        events = {}
        for line in self.text("events.txt").splitlines():
            stamp, name = line.split(" ", 1)
            events[name] = float(stamp)
        return events

    def reference_rate(self) -> float:
        """The rate v4l2-ctl streamed at, alone in the VM: the median of its per-second reports."""
        reports = [float(rate) for rate in re.findall(r"([\d.]+) fps", self.text("v4l2-stream.txt"))]
        return statistics.median(reports)

    def node_cpu_seconds(self) -> float:
        """User + system CPU time of the node's run (bash's `times`: the children's line)."""
        children = self.text("node-cpu.txt").splitlines()[1]
        return sum(float(m) * 60 + float(s) for m, s in re.findall(r"(\d+)m([\d.]+)s", children))

    def bag(self) -> Path:
        (bag,) = sorted(self.dir.glob("bags/*/*.mcap"))
        return bag

    def messages(self, topic: str) -> list[tuple[object, int]]:
        """The decoded messages of `topic` with their log times (ns), read by MCAP's own reader."""
        from mcap.reader import make_reader
        from mcap_ros2.decoder import DecoderFactory

        with self.bag().open("rb") as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            return [(ros, message.log_time) for _, _, message, ros in reader.iter_decoded_messages(topics=[topic])]

    def frames(self) -> list[Frame]:
        frames = []
        for ros, log_time in self.messages(COMPRESSED):
            stamp = ros.header.stamp
            frames.append(Frame(stamp.sec + stamp.nanosec * 1e-9, log_time * 1e-9, bytes(ros.data)))
        return frames

    def diagnostics(self) -> list[tuple[float, dict[str, str]]]:
        """The node's /diagnostics for camera top: (log time in s, its key-values), in order."""
        found = []
        for array, log_time in self.messages("/diagnostics"):
            for status in array.status:
                if status.name.endswith(": top"):
                    found.append((log_time * 1e-9, {kv.key: kv.value for kv in status.values}))
        return found

    def driver_picture(self) -> np.ndarray:
        """v4l2-ctl's own frame (YUYV), as OpenCV turns it into RGB (BT.601, limited range)."""
        import cv2

        yuyv = np.fromfile(self.dir / "frame.yuyv", dtype=np.uint8).reshape(HEIGHT, WIDTH, 2)
        return cv2.cvtColor(yuyv, cv2.COLOR_YUV2RGB_YUYV)


def decoded(jpeg: bytes) -> np.ndarray:
    from PIL import Image

    with Image.open(io.BytesIO(jpeg)) as image:
        return np.asarray(image.convert("RGB"))


def steady_rate(frames: list[Frame], start: float, end: float) -> float:
    """Frames per second by capture stamp within [start, end]."""
    stamps = [frame.stamp for frame in frames if start <= frame.stamp <= end]
    return (len(stamps) - 1) / (stamps[-1] - stamps[0])


def report(results: Results) -> str:
    events = results.events()
    frames = results.frames()
    rate = steady_rate(frames, events["node start"] + 5.0, events["disconnect"])
    counts = summary_counts(results.text("node.log"))
    reference = results.reference_rate()
    cpu_ms = 1000 * results.node_cpu_seconds() / (counts["frames"] + counts["node_drops"])
    return (
        f"kernel {results.text('kernel.txt').strip()}, {results.text('accel.txt').strip()}, VM run "
        f"{results.text('vm-seconds.txt').strip()} s; v4l2-ctl {reference:.2f} fps, node {rate:.2f} fps "
        f"({rate / reference:.3f} of it) at {WIDTH}x{HEIGHT} YUYV; node summary: {counts['frames']:.0f} frames, "
        f"{counts['node_drops']:.0f} dropped while behind, {counts['device_drops']:.0f} by the camera, "
        f"{counts['broken']:.0f} broken, {counts['stamped_ahead']:.0f} stamped after the node's clock, "
        f"CPU {cpu_ms:.1f} ms a frame"
    )


if __name__ == "__main__":
    print(report(Results(Path(sys.argv[1]))))
