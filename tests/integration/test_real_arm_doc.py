"""docs/real_arm.md, run: every command of its ```sh blocks, in the page's order, against two
servo-bus emulators standing in for the follower's and the leader's adapters.

The page's convention (written at its end): one command per line in ```sh blocks, no continuation
lines; the ports are written /dev/so101_follower and /dev/so101_leader. Here they become the
emulators' links; `sudo` and `scripts/isolated` are dropped (this test already runs in a private
network namespace, and the nodes must share it with the probe); find-port looks at the links
(--dev-glob); install-udev --install writes to a temporary --rules-dir; HOME is a temporary
directory, so the calibration files land where the page says, under ~/.cache/huggingface.
Commands run from a scratch directory that looks like the checkout (scripts/ and .venv linked), so
what they write (bags/, logs/, arm.rrd) stays there.

Each kind of command has a driver below that acts the user's part (unplugging the adapter,
connecting one servo at a time, centring and sweeping the joints, moving the leader) and checks
the outcome; long-running ones are checked for a sign of life and stopped with Ctrl-C (SIGINT to
their process group), which they must survive with exit code 0. A command the test does not know
fails it.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from driver_harness import ServoEmulator
from harness import JOINT_NAMES, REPO_ROOT, node_binary, node_environment
from tool_terminal import Terminal

DOC = REPO_ROOT / "docs" / "real_arm.md"
PORTS = ("/dev/so101_follower", "/dev/so101_leader")
CENTRE = {1: 1900, 2: 2200, 3: 2047, 4: 1600, 5: 2500, 6: 2100}  # raw ticks of the centred pose, by id


def sweep(servo_id: int) -> tuple[int, int]:
    """The range (centred ticks) the test sweeps joint `servo_id` through."""
    return 2047 - 600 - 10 * servo_id, 2047 + 700 + 10 * servo_id


def doc_commands(text: str) -> list[str]:
    """The commands of the page's ```sh blocks, one per line."""
    commands, block = [], None
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if block is None:
            if stripped.startswith("```"):
                block = stripped[3:].strip()
            continue
        if stripped.startswith("```"):
            block = None
            continue
        if block != "sh" or not stripped:
            continue
        assert not stripped.startswith("#"), f"line {number}: comments do not belong in the page's sh blocks"
        assert not stripped.endswith("\\"), f"line {number}: one command per line, no continuation"
        commands.append(stripped)
    assert block is None, "an unclosed code block"
    return commands


def test_the_page_is_parsed_as_one_command_per_line():
    text = "x\n```sh\na --b\n\nc\n```\n```text\nnot a command\n```\n  ```sh\n  d\n  ```\n"
    assert doc_commands(text) == ["a --b", "c", "d"]
    with pytest.raises(AssertionError):
        doc_commands("```sh\na \\\n  b\n```\n")


# =========================================================================== the user's setting
@dataclass
class Desk:
    """The emulated adapters, the environment and the working directory of the page's commands."""

    tmp: Path
    probe: object
    emulators: dict[str, ServoEmulator] = field(default_factory=dict)
    links: dict[str, Path] = field(default_factory=dict)
    running: list[Terminal] = field(default_factory=list)
    seen: list[str] = field(default_factory=list)

    def __post_init__(self):
        self.dev = self.tmp / "dev"
        self.dev.mkdir()
        self.home = self.tmp / "home"
        self.home.mkdir()
        self.cwd = self.tmp / "checkout"
        self.cwd.mkdir()
        (self.cwd / "scripts").symlink_to(REPO_ROOT / "scripts")
        (self.cwd / ".venv").symlink_to(Path(sys.prefix))
        self.bin_dir = node_binary("so101_feetech_driver").parent
        env = {k: v for k, v in node_environment().items() if not k.startswith("HF_")}
        env.update(
            HOME=str(self.home), CARGO_TARGET_DIR=str(self.bin_dir.parent), SO101_BIN_DIR=str(self.bin_dir), B=str(self.bin_dir)
        )
        env["PYTHONFAULTHANDLER"] = "1"  # a command that hangs shows its stacks (Terminal.dump_stacks)
        self.env = env
        for port in PORTS:
            link = self.dev / Path(port).name
            # Factory servos, all id 1: the user connects one at a time for setup-motors.
            self.emulators[port] = ServoEmulator(
                link, self.tmp / f"{link.name}.log", "--ids", "1,1,1,1,1,1", "--plugged", "0", "--timing", "instant"
            )
            self.links[port] = link

    def close(self):
        for terminal in self.running:
            terminal.kill()
        for emulator in self.emulators.values():
            emulator.stop()

    # ------------------------------------------------------------------ running a command
    def substitute(self, command: str) -> str:
        others = re.sub("|".join(map(re.escape, PORTS)), "", command)
        assert "/dev/" not in others, f"the page names a port the test cannot emulate: {command}"
        for port, link in self.links.items():
            command = command.replace(port, str(link))
        command = re.sub(r"^sudo ", "", command)
        return re.sub(r"^scripts/isolated ", "", command)

    def start(self, command: str, extra: str = "") -> Terminal:
        terminal = Terminal(["bash", "-c", self.substitute(command) + extra], env=self.env, cwd=self.cwd)
        self.running.append(terminal)
        return terminal

    def run(self, command: str, extra: str = "", timeout: float = 60.0) -> str:
        terminal = self.start(command, extra)
        code = terminal.wait(timeout)
        assert code == 0, f"`{command}` failed with {code}:\n{terminal.text()}"
        return terminal.text()

    def stop(self, terminal: Terminal, command: str) -> str:
        code = terminal.interrupt(timeout=30)
        assert code == 0, f"`{command}` ended with {code} on Ctrl-C:\n{terminal.text()}"
        return terminal.text()

    def slots_by_id(self, port: str) -> dict[int, dict]:
        return {slot["id"]: slot for slot in self.emulators[port].slots()}

    def wait_for(self, condition, what: str, terminal: Terminal, timeout: float = 20.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            value = condition()
            if value:
                return value
            assert terminal.proc.poll() is None, f"ended while waiting for {what}:\n{terminal.text()}"
            time.sleep(0.1)
        raise AssertionError(f"timeout waiting for {what}; output:\n{terminal.text()}")

    def calibration_file(self, leader: bool, robot_id: str) -> Path:
        kind = "teleoperators/so_leader" if leader else "robots/so_follower"
        return self.home / ".cache" / "huggingface" / "lerobot" / "calibration" / kind / f"{robot_id}.json"


# =========================================================================== one driver per kind
def setup_line(desk: Desk, command: str, match: re.Match) -> None:
    env = {k: v for k, v in desk.env.items() if k != "B"}
    done = subprocess.run(
        check=False,
        args=["bash", "-c", command + '; printf %s "$B"'],
        env=env,
        cwd=desk.cwd,
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert done.returncode == 0, done.stderr
    assert Path(done.stdout) == desk.bin_dir, f"B is {done.stdout!r}, not the binaries' directory {desk.bin_dir}"


def find_port(desk: Desk, command: str, match: re.Match) -> None:
    follower = PORTS[0]
    terminal = desk.start(command, f" --dev-glob '{desk.dev}/*'")
    terminal.expect("Remove the USB cable")
    desk.emulators[follower].command("hangup 3")  # the user unplugs the follower's adapter
    assert not desk.links[follower].exists()
    terminal.press_enter()
    assert terminal.wait() == 0, terminal.text()
    assert f"The port of this adapter is {desk.links[follower]}\n" in terminal.text()
    assert "Reconnect the USB cable." in terminal.text()
    deadline = time.monotonic() + 10  # the user plugs it back in
    while not desk.links[follower].exists():
        assert time.monotonic() < deadline, "the emulated adapter did not come back"
        time.sleep(0.05)


def udev_print(desk: Desk, command: str, match: re.Match) -> None:
    out = desk.run(command)
    rules = [line for line in out.splitlines() if line and not line.startswith("#")]
    serials = re.findall(r"--(follower|leader)-serial (\S+)", command)
    for role, serial in serials:
        assert any(
            f'ATTRS{{serial}}=="{serial}", SYMLINK+="so101_{role}", GROUP="dialout", MODE="0660"' in rule for rule in rules
        ), out


def udev_install(desk: Desk, command: str, match: re.Match) -> None:
    rules_dir = desk.tmp / "rules.d"
    rules_dir.mkdir()
    out = desk.run(command, f" --rules-dir '{rules_dir}'")
    rules = (rules_dir / "99-so101.rules").read_text()
    assert 'SYMLINK+="so101_follower"' in rules and 'SYMLINK+="so101_leader"' in rules
    page = DOC.read_text()
    for step in ("sudo udevadm control --reload-rules && sudo udevadm trigger", "sudo usermod -aG dialout $USER"):
        assert step in out and step in page, step


def setup_motors(desk: Desk, command: str, match: re.Match) -> None:
    port = match["port"]
    emulator = desk.emulators[port]
    terminal = desk.start(command)
    for slot, joint in enumerate(reversed(JOINT_NAMES)):
        terminal.expect(f"'{joint}' servo ONLY")
        if slot:
            emulator.command(f"unplug {slot - 1}")
            emulator.command(f"plug {slot}")
        terminal.press_enter()
        terminal.expect(f"'{joint}' servo: id 1 -> {6 - slot}")
    assert terminal.wait() == 0, terminal.text()
    for slot in range(6):
        emulator.command(f"plug {slot}")  # the servos daisy-chained
    assert sorted(desk.slots_by_id(port)) == [1, 2, 3, 4, 5, 6]


def calibrate(desk: Desk, command: str, match: re.Match) -> None:
    port, robot_id, leader = match["port"], match["id"], bool(match["leader"])
    emulator = desk.emulators[port]
    for servo_id, raw in CENTRE.items():  # the user centres the arm
        emulator.command(f"move {servo_id} {raw}")
    terminal = desk.start(command)
    terminal.expect("middle of its range")
    terminal.press_enter()
    terminal.expect("press Enter when done")
    for servo_id, raw in CENTRE.items():  # ... and sweeps every joint, back to the centre
        low, high = sweep(servo_id)
        for centred in (low, high, 2047):
            emulator.command(f"move {servo_id} {raw + centred - 2047}")
            time.sleep(0.15)
    terminal.press_enter()
    assert terminal.wait() == 0, terminal.text()
    path = desk.calibration_file(leader, robot_id)
    assert f"Calibration written to the servos and to {path}" in terminal.text()
    calibration = json.loads(path.read_text())
    slots = desk.slots_by_id(port)
    for servo_id, (name, motor) in enumerate(calibration.items(), start=1):
        assert name == JOINT_NAMES[servo_id - 1] and motor["id"] == servo_id
        assert motor["homing_offset"] == CENTRE[servo_id] - 2047 == slots[servo_id]["homing_offset"]
        expected = (0, 4095) if name == "wrist_roll" else sweep(servo_id)
        assert (motor["range_min"], motor["range_max"]) == expected
        assert (slots[servo_id]["min_position_limit"], slots[servo_id]["max_position_limit"]) == expected


def driver(desk: Desk, command: str, match: re.Match) -> None:
    from sensor_msgs.msg import JointState

    port, leader = match["port"], bool(match["leader"])
    topic = "/leader/joint_states" if leader else "/joint_states"
    inbox = desk.probe.subscribe(topic, JointState)
    terminal = desk.start(command)
    desk.wait_for(lambda: inbox.count() >= 10, f"10 messages on {topic}", terminal)
    assert list(inbox.latest().name) == JOINT_NAMES
    torque = [slot["torque_enable"] for slot in desk.slots_by_id(port).values()]
    assert torque == ([0] * 6 if leader else [1] * 6), torque
    desk.stop(terminal, command)
    assert [slot["torque_enable"] for slot in desk.slots_by_id(port).values()] == [0] * 6, "torque on after Ctrl-C"


def move_leader_and_see_the_follower_follow(desk: Desk, terminal: Terminal, delta: int) -> None:
    follower, leader = (desk.emulators[port] for port in PORTS)
    start = desk.slots_by_id(PORTS[0])[1]["present_position"]
    leader.command(f"move 1 {CENTRE[1] + delta}")  # shoulder_pan of the leader, by hand
    desk.wait_for(
        lambda: abs(desk.slots_by_id(PORTS[0])[1]["present_position"] - (2047 + delta)) < 20,
        f"the follower's shoulder_pan to follow the leader from {start} to {2047 + delta}",
        terminal,
    )
    assert all(slot["torque_enable"] == 1 for slot in follower.slots())


def launch(desk: Desk, command: str, match: re.Match) -> None:
    """so101-launch with the leader teleop: plain, with --rerun FILE, or with --record."""
    flags = match["flags"]
    assert "--robot real" in flags and "--teleop-source leader" in flags, f"a launch profile the test does not know: {command}"
    terminal = desk.start(command)
    terminal.expect("so101-launch: all nodes up", timeout=90)
    move_leader_and_see_the_follower_follow(desk, terminal, 300)
    move_leader_and_see_the_follower_follow(desk, terminal, -250)
    if rerun := re.search(r"--rerun (\S+)", flags):
        rrd = desk.cwd / rerun[1]
        desk.wait_for(lambda: rrd.is_file() and rrd.stat().st_size > 0, f"{rrd} to be written", terminal)
    time.sleep(1.0)
    out = desk.stop(terminal, command)
    assert "so101-launch: stopped" in out
    assert [slot["torque_enable"] for slot in desk.emulators[PORTS[0]].slots()] == [0] * 6, "torque on after Ctrl-C"
    if bags := re.search(r"--bags (\S+)", flags):
        assert "--record" in flags
        episodes = [path.parent for path in (desk.cwd / bags[1]).glob("*/metadata.yaml")]
        assert len(episodes) == 1, f"episodes in {bags[1]}: {episodes}\n{out}"
        assert list(episodes[0].glob("*.mcap")), f"no MCAP file in {episodes[0]}"


def viewer(desk: Desk, command: str, match: re.Match) -> None:
    """The viewer needs a display: the file it opens is checked with Rerun's own tools instead."""
    rrd = desk.cwd / match["file"]
    rerun = Path(sys.prefix) / "bin" / "rerun"
    for check in (["rrd", "verify"], ["rrd", "print"]):
        done = subprocess.run(
            check=False, args=[str(rerun), *check, str(rrd)], env=desk.env, capture_output=True, text=True, timeout=120
        )
        assert done.returncode == 0, f"rerun {' '.join(check)} {rrd}: {done.stderr}"
    assert "shoulder_pan" in done.stdout + done.stderr, done.stdout[-3000:]


def scan(desk: Desk, command: str, match: re.Match) -> None:
    out = desk.run(command, timeout=120)
    assert "1000000 baud: 6 servo(s)" in out, out
    for servo_id in range(1, 7):
        assert re.search(rf"^\s+id\s+{servo_id}\s+STS3215\s+firmware", out, re.MULTILINE), out
    if match["all"]:  # every rate tried (the emulator answers at any: a pty has no baud rate)
        for baud in (1_000_000, 500_000, 250_000, 128_000, 115_200):
            assert f"{baud} baud: " in out, out


PORT = r"(?P<port>/dev/so101_(?:follower|leader))"
DRIVERS = [
    ("setup", r"\. scripts/common\.sh; B=\$CARGO_TARGET_DIR/release", setup_line),
    ("find-port", r"\$B/so101_feetech_driver find-port", find_port),
    (
        "install-udev --print",
        r"\$B/so101_feetech_driver install-udev --follower-serial \w+ --leader-serial \w+ --print",
        udev_print,
    ),
    (
        "install-udev --install",
        r"sudo \$B/so101_feetech_driver install-udev --follower-serial \w+ --leader-serial \w+ --install",
        udev_install,
    ),
    ("setup-motors", rf"\$B/so101_feetech_driver setup-motors --port {PORT}", setup_motors),
    ("calibrate", rf"\$B/so101_feetech_driver calibrate --port {PORT} --robot-id (?P<id>\w+)(?P<leader> --leader)?", calibrate),
    ("driver", rf"scripts/isolated \$B/so101_feetech_driver --port {PORT} --robot-id \w+(?P<leader> --leader)?", driver),
    ("so101-launch", r"\.venv/bin/so101-launch (?P<flags>.*)", launch),
    ("rerun viewer", r"\.venv/bin/rerun (?P<file>\S+\.rrd)", viewer),
    ("scan", rf"\$B/so101_feetech_driver scan --port {PORT}(?P<all> --all-bauds)?", scan),
]


def test_every_command_of_the_real_arm_page_runs_against_the_emulator(tmp_path, ros):
    commands = doc_commands(DOC.read_text())
    unknown = [command for command in commands if not any(re.fullmatch(pattern, command) for _, pattern, _ in DRIVERS)]
    assert not unknown, f"docs/real_arm.md has commands this test does not know how to run: {unknown}"
    desk = Desk(tmp_path, ros)
    try:
        for command in commands:
            kind, match, run = next((kind, m, run) for kind, pattern, run in DRIVERS if (m := re.fullmatch(pattern, command)))
            started = time.monotonic()
            run(desk, command, match)
            desk.seen.append(kind)
            print(f"ran in {time.monotonic() - started:.1f} s: {command}")
    except BaseException:
        for port, emulator in desk.emulators.items():
            print(f"--- emulator {port}:\n{emulator.log_tail()}")
        raise
    finally:
        desk.close()
    missing = {kind for kind, _, _ in DRIVERS} - set(desk.seen)
    assert not missing, f"the page lost its {sorted(missing)} step(s)"
    assert desk.seen.count("calibrate") == 2 and desk.seen.count("setup-motors") == 2


def test_a_command_the_test_does_not_know_is_refused():
    for command in (
        "$B/so101_feetech_driver calibrate --port /dev/ttyACM0 --robot-id x",
        "$B/so101_feetech_driver reboot --port /dev/so101_follower",
        "scripts/isolated $B/teleop_node --source leader",
    ):
        assert not any(re.fullmatch(pattern, command) for _, pattern, _ in DRIVERS), command
