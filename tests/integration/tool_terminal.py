"""A command run as a user runs it in a terminal: stdin and stdout through pipes, `expect` waits for
text in its output, `press_enter` answers a prompt, `interrupt` is Ctrl-C (SIGINT to its process
group, as a terminal sends it)."""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
from pathlib import Path


class Terminal:
    def __init__(self, argv: list[str], env: dict[str, str] | None = None, cwd: Path | None = None):
        self.argv = argv
        self.proc = subprocess.Popen(
            argv,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            env=env,
            cwd=cwd,
            text=True,
            bufsize=0,
            start_new_session=True,  # its own process group, like a terminal's foreground job
        )
        self.output = ""
        self._lock = threading.Lock()
        self._pump_thread = threading.Thread(target=self._pump, daemon=True)
        self._pump_thread.start()

    def _pump(self) -> None:
        while chunk := self.proc.stdout.read(1):
            self._append(chunk)

    def text(self) -> str:
        with self._lock:
            return self.output

    def expect(self, text: str, timeout: float = 15.0) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if text in self.text():
                return
            if self.proc.poll() is not None:
                self._drain(timeout)
                if text in self.text():
                    return
                break
            time.sleep(0.02)
        raise AssertionError(f"{text!r} not seen in the output of {self.argv}:\n{self.text()}")

    def press_enter(self) -> None:
        self.proc.stdin.write("\n")
        self.proc.stdin.flush()

    def wait(self, timeout: float = 30.0) -> int:
        try:
            code = self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.dump_stacks()
            self.kill()
            raise AssertionError(f"{self.argv} did not end within {timeout} s; output:\n{self.text()}") from None
        self._drain(timeout)
        return code

    def _drain(self, timeout: float) -> None:
        """After the exit: the pump reads to the end of the pipe, so `output` holds everything the
        command printed (asserting on it right after the exit could miss its tail)."""
        self._pump_thread.join(timeout)

    def interrupt(self, timeout: float = 20.0) -> int:
        """Ctrl-C: SIGINT to the whole process group; the exit code."""
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGINT)
        return self.wait(timeout)

    def dump_stacks(self, timeout: float = 3.0) -> None:
        """abort_for_stacks on the command alone; the output then has its signal state and stacks."""
        if self.proc.poll() is None:
            abort_for_stacks(self.proc, self._append, timeout)
            self._drain(1.0)

    def _append(self, text: str) -> None:
        with self._lock:
            self.output += text

    def kill(self) -> None:
        if self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self.proc.wait()


def stop_with_ctrl_c(proc: subprocess.Popen | None, record, timeout: float = 15.0) -> None:
    """Ends a Python program still running as Ctrl-C does (SIGINT); one that does not end within
    `timeout` has its stacks `record`ed (abort_for_stacks) and is killed."""
    if proc is None or proc.poll() is not None:
        return
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        abort_for_stacks(proc, record, 5.0)
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def abort_for_stacks(proc: subprocess.Popen, record, timeout: float) -> None:
    """For a process that hangs: `record`s its signal state, then sends SIGABRT, on which a Python
    program run with PYTHONFAULTHANDLER=1 writes every thread's stack to its output, so the failure
    says where it hung. Waits `timeout` for it to end; the caller kills it if it did not."""
    record(signal_state(proc.pid))
    proc.send_signal(signal.SIGABRT)
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        pass


def signal_state(pid: int) -> str:
    """What /proc says about `pid`'s signals: ignored, caught, and each thread's blocked set
    (a process that does not react to Ctrl-C shows here whether SIGINT reaches it)."""
    lines = []
    try:
        status = Path(f"/proc/{pid}/status").read_text()
        lines += [line for line in status.splitlines() if line.startswith(("SigIgn", "SigCgt", "SigPnd", "ShdPnd"))]
        for task in sorted(Path(f"/proc/{pid}/task").iterdir()):
            fields = dict(line.split(":", 1) for line in (task / "status").read_text().splitlines() if ":" in line)
            lines.append(f"thread {task.name} {fields.get('Name', '').strip()}: SigBlk {fields.get('SigBlk', '').strip()}")
    except OSError as error:
        lines.append(f"({error})")
    joined = "\n".join(lines)
    return f"\n--- signals of pid {pid}:\n{joined}\n"
