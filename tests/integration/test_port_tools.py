"""`find-port` and `install-udev` as a user runs them: the adapter is the servo-bus emulator's link,
which disappears while the emulator is told to hang up (like an unplugged USB cable)."""

from __future__ import annotations

import os
import re
import subprocess
import time

from driver_harness import DRIVER_NAME, ServoEmulator
from harness import node_binary, node_environment
from tool_terminal import Terminal

# One udev rule: comma-separated KEY op "VALUE" pairs.
RULE_FIELD = re.compile(r'^(?P<key>[A-Z_]+(?:\{[a-z_]+\})?)(?P<op>==|\+=|=)"(?P<value>[^"]*)"$')


def driver(*args: str) -> list[str]:
    return [str(node_binary(DRIVER_NAME)), *args]


def wait_for_path(path, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not os.path.exists(path):
        assert time.monotonic() < deadline, f"{path} did not come back"
        time.sleep(0.05)


def test_find_port_names_the_adapter_that_was_unplugged(tmp_path):
    ports = tmp_path / "dev"
    ports.mkdir()
    follower = ServoEmulator(ports / "so101_follower", tmp_path / "follower.log", "--timing", "instant")
    leader = ServoEmulator(ports / "so101_leader", tmp_path / "leader.log", "--timing", "instant")
    try:
        terminal = Terminal(driver("find-port", "--dev-glob", f"{ports}/*"), env=node_environment())
        terminal.expect("Remove the USB cable")
        before = terminal.text()
        assert f"{ports}/so101_follower -> /dev/pts/" in before and f"{ports}/so101_leader -> /dev/pts/" in before, before
        follower.command("hangup 4")
        # The unplugged adapter's name really stops resolving (what find-port relies on).
        assert not os.path.exists(ports / "so101_follower") and os.path.exists(ports / "so101_leader")
        terminal.press_enter()
        assert terminal.wait() == 0, terminal.text()
        assert f"The port of this adapter is {ports}/so101_follower\n" in terminal.text()
        assert "Reconnect the USB cable." in terminal.text()
        assert "so101_leader" not in terminal.text().split("Remove the USB cable")[1]
        wait_for_path(ports / "so101_follower")
    finally:
        follower.stop()
        leader.stop()


def test_find_port_fails_with_advice_when_nothing_or_several_disappeared(tmp_path):
    ports = tmp_path / "dev"
    ports.mkdir()
    first = ServoEmulator(ports / "bus_a", tmp_path / "a.log", "--timing", "instant")
    second = ServoEmulator(ports / "bus_b", tmp_path / "b.log", "--timing", "instant")
    try:
        # Nothing unplugged.
        terminal = Terminal(driver("find-port", "--dev-glob", f"{ports}/bus_*"), env=node_environment())
        terminal.expect("Remove the USB cable")
        terminal.press_enter()
        assert terminal.wait() != 0, terminal.text()
        assert "No port disappeared" in terminal.text() and "Reconnect the USB cable" in terminal.text()
        assert "The port of this adapter" not in terminal.text()

        # Both unplugged.
        terminal = Terminal(
            driver("find-port", "--dev-glob", f"{ports}/bus_a", "--dev-glob", f"{ports}/bus_b"), env=node_environment()
        )
        terminal.expect("Remove the USB cable")
        first.command("hangup 4")
        second.command("hangup 4")
        terminal.press_enter()
        assert terminal.wait() != 0, terminal.text()
        assert f"2 ports disappeared ({ports}/bus_a, {ports}/bus_b)" in terminal.text()
        assert "unplug only the adapter" in terminal.text()
        wait_for_path(ports / "bus_a")
        wait_for_path(ports / "bus_b")

        # No port at all where it looks: it says so before asking anything.
        done = subprocess.run(
            check=False,
            args=driver("find-port", "--dev-glob", f"{tmp_path}/nothing*"),
            env=node_environment(),
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
            timeout=30,
        )
        assert done.returncode != 0 and "no serial port found" in done.stderr + done.stdout
    finally:
        first.stop()
        second.stop()


def parse_rule(line: str) -> dict[str, tuple[str, str]]:
    fields = {}
    for part in line.split(", "):
        match = RULE_FIELD.match(part)
        assert match, f'not a udev KEY=="VALUE" field: {part!r} in {line!r}'
        fields[match["key"]] = (match["op"], match["value"])
    return fields


def test_install_udev_prints_rules_that_parse(tmp_path):
    done = subprocess.run(
        check=False,
        args=driver("install-udev", "--follower-serial", "5A46082351", "--leader-serial", "58FA083324", "--print"),
        env=node_environment(),
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert done.returncode == 0, done.stderr
    rules = [parse_rule(line) for line in done.stdout.splitlines() if line.strip() and not line.startswith("#")]
    naming = [rule for rule in rules if "SYMLINK" in rule]
    assert [rule["SYMLINK"] for rule in naming] == [("+=", "so101_follower"), ("+=", "so101_leader")]
    assert [rule["ATTRS{serial}"] for rule in naming] == [("==", "5A46082351"), ("==", "58FA083324")]
    for rule in naming:
        assert rule["SUBSYSTEM"] == ("==", "tty")
        assert rule["GROUP"] == ("=", "dialout") and rule["MODE"] == ("=", "0660")
    latency = [rule for rule in rules if "ATTR{latency_timer}" in rule]
    assert len(latency) == 2 and all(rule["ATTR{latency_timer}"] == ("=", "1") for rule in latency)
    assert all(rule["DRIVER"] == ("==", "ftdi_sio") and rule["SUBSYSTEM"] == ("==", "usb-serial") for rule in latency)
    assert len(rules) == 4
    # The default is printing, too.
    default = subprocess.run(
        check=False,
        args=driver("install-udev", "--follower-serial", "5A46082351", "--leader-serial", "58FA083324"),
        env=node_environment(),
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert default.returncode == 0 and default.stdout == done.stdout


def test_install_udev_writes_the_rules_file_and_refuses_bad_serials(tmp_path):
    done = subprocess.run(
        check=False,
        args=driver("install-udev", "--follower-serial", "A1B2", "--install", "--rules-dir", str(tmp_path)),
        env=node_environment(),
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert done.returncode == 0, done.stderr
    path = tmp_path / "99-so101.rules"
    text = path.read_text()
    assert 'ATTRS{serial}=="A1B2", SYMLINK+="so101_follower"' in text and "so101_leader" not in text
    assert oct(path.stat().st_mode & 0o777) == "0o644"
    assert f"Wrote {path}" in done.stdout
    assert "sudo udevadm control --reload-rules && sudo udevadm trigger" in done.stdout
    assert "sudo usermod -aG dialout $USER" in done.stdout

    for bad in (
        ["--follower-serial", 'x" MODE="0666'],
        ["--follower-serial", "A*"],
        ["--follower-serial", ""],
        ["--follower-serial", "S1", "--leader-serial", "S1"],
    ):
        refused = subprocess.run(
            check=False,
            args=driver("install-udev", *bad, "--install", "--rules-dir", str(tmp_path / "other")),
            env=node_environment(),
            capture_output=True,
            text=True,
            timeout=30,
        )
        assert refused.returncode != 0, bad
        assert "serial number" in refused.stderr, refused.stderr
    assert not (tmp_path / "other").exists()
    # --rules-dir only with --install; --print and --install exclude each other.
    for conflicting in (["--rules-dir", str(tmp_path)], ["--print", "--install"]):
        refused = subprocess.run(
            check=False,
            args=driver("install-udev", "--follower-serial", "A1", *conflicting),
            env=node_environment(),
            capture_output=True,
            text=True,
            timeout=30,
        )
        assert refused.returncode == 2, conflicting
