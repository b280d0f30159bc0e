"""Child processes of the tools, benchmarks and environments (nodes, rclpy helpers): started, and
stopped the way the nodes expect, SIGINT first (the recorder closes its bag, the driver turns torque
off), SIGKILL only for one that does not exit in time."""

from __future__ import annotations

import signal
import subprocess
import time
from collections.abc import Sequence


def start(command: Sequence[str], **popen_kwargs) -> subprocess.Popen:
    """Starts `command` (stdin closed unless given); the arguments of subprocess.Popen otherwise."""
    popen_kwargs.setdefault("stdin", subprocess.DEVNULL)
    return subprocess.Popen([str(part) for part in command], **popen_kwargs)


def start_and_check(command: Sequence[str], settle: float, log, **popen_kwargs) -> subprocess.Popen:
    """Starts `command` with stderr to the file `log`, waits `settle` seconds and raises with the
    log's tail if it has already exited."""
    process = start(command, stderr=log, **popen_kwargs)
    time.sleep(settle)
    if process.poll() is not None:
        log.seek(0)
        raise RuntimeError(f"{command[0]} exited with {process.returncode}:\n{log.read()[-3000:]}")
    return process


def stop(process: subprocess.Popen, timeout: float = 10.0) -> int:
    """SIGINT, wait up to `timeout` s, then SIGKILL; the exit status (negative: the signal)."""
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            process.kill()
    return process.wait()


def interrupt_and_collect(process: subprocess.Popen, timeout: float = 30.0) -> tuple[str | None, str | None]:
    """SIGINT, then its remaining (stdout, stderr) once it exits (SIGKILL after `timeout`)."""
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
    try:
        return process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        return process.communicate()
