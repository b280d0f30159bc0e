"""Timed recording sessions, as lerobot-record runs them, for `so101-launch --record --episode-time`:
N episodes of a fixed length, each followed by a reset period (not recorded, none after the last),
every episode carrying the task text. Keys in the launcher's terminal, as lerobot-record's:

  right arrow  end the episode (or the reset period) now
  left arrow   re-record: during an episode, drop it; during the reset period after one, drop
               the episode just recorded; either way it is recorded again after the reset
  Esc          stop: the running episode is kept, no more are recorded

An episode with a time limit needs no key, so both hands can stay on the leader arm. The session
drives the recorder through its services (/recorder/start, stop, discard, discard_last: each call
is answered, so an episode's time counts from when its recording began; the task text is the
recorder's --task) and, on the simulated arm, calls /sim/reset before each episode. The first
episode begins once /recorder/ready says the recorder receives every publisher of what it records
(at most READY_TIMEOUT later, with a warning naming the topics it still waits for), so that it
holds every stream from its start.

`Session` is the schedule (pure, clocked by its caller); `decode_keys` reads a terminal's bytes;
`TerminalKeys` and `SessionRunner` are the I/O."""

from __future__ import annotations

import os
import select
import sys
from dataclasses import dataclass
from enum import Enum


class Key(Enum):
    NEXT = "right arrow"
    RERECORD = "left arrow"
    STOP = "Esc"


# What a terminal sends for each key (normal and application cursor modes).
_SEQUENCES = {b"\x1b[C": Key.NEXT, b"\x1bOC": Key.NEXT, b"\x1b[D": Key.RERECORD, b"\x1bOD": Key.RERECORD}


def decode_keys(data: bytes) -> list[Key]:
    """The session keys in one read of a terminal in raw mode. A lone ESC (nothing after it in
    the read) is the Esc key; other escape sequences and other bytes are ignored."""
    keys: list[Key] = []
    i = 0
    while i < len(data):
        if data[i] != 0x1B:
            i += 1
            continue
        sequence = data[i : i + 3]
        if sequence in _SEQUENCES:
            keys.append(_SEQUENCES[sequence])
            i += 3
        elif i + 1 == len(data) or data[i + 1] == 0x1B:
            keys.append(Key.STOP)
            i += 1
        else:
            # Another sequence (up arrow, F-keys): skip to its final byte.
            i += 2
            while i < len(data) and not (0x40 <= data[i] <= 0x7E):
                i += 1
            i += 1
    return keys


class Phase(Enum):
    RECORDING = "recording"
    RESETTING = "resetting"
    DONE = "done"


@dataclass(frozen=True)
class Action:
    """What the session asks of its runner: a recorder service (start, stop, discard, discard_last),
    a sim reset, or a line to say."""

    recorder: str = ""
    reset_sim: bool = False
    say: str = ""


@dataclass
class Session:
    episodes: int  # 0: until Esc
    episode_time: float
    reset_time: float
    phase: Phase = Phase.DONE
    deadline: float = 0.0
    recorded: int = 0  # episodes kept so far
    # Whether the episode closed last may still be dropped (during the reset period after it).
    last_droppable: bool = False

    def begin(self, now: float) -> list[Action]:
        return self._start(now)

    @property
    def done(self) -> bool:
        return self.phase is Phase.DONE

    def _start(self, now: float) -> list[Action]:
        self.phase, self.deadline, self.last_droppable = Phase.RECORDING, now + self.episode_time, False
        return [
            Action(reset_sim=True),
            Action(recorder="start"),
            Action(
                say=f"recording episode {self.recorded + 1}{f' of {self.episodes}' if self.episodes else ''} ({self.episode_time:g} s)"
            ),
        ]

    def _reset(self, now: float, why: str) -> list[Action]:
        self.phase, self.deadline = Phase.RESETTING, now + self.reset_time
        return [Action(say=f"{why}; reset the scene ({self.reset_time:g} s, right arrow to go on)")]

    def _end_episode(self, now: float) -> list[Action]:
        self.recorded += 1
        actions = [Action(recorder="stop")]
        if self.episodes and self.recorded >= self.episodes:
            self.phase = Phase.DONE
            return [*actions, Action(say=f"recorded {self.recorded} episodes")]
        self.last_droppable = True
        return actions + self._reset(now, f"episode {self.recorded} kept")

    def started_at(self, now: float) -> None:
        """The recording of the running episode began at `now` (its start was answered): its time
        counts from there."""
        if self.phase is Phase.RECORDING:
            self.deadline = now + self.episode_time

    def tick(self, now: float) -> list[Action]:
        if self.phase is Phase.RECORDING and now >= self.deadline:
            return self._end_episode(now)
        if self.phase is Phase.RESETTING and now >= self.deadline:
            return self._start(now)
        return []

    def key(self, key: Key, now: float) -> list[Action]:
        if self.phase is Phase.DONE:
            return []
        if key is Key.STOP:
            actions = [Action(recorder="stop")] if self.phase is Phase.RECORDING else []
            self.recorded += self.phase is Phase.RECORDING
            self.phase = Phase.DONE
            return [*actions, Action(say=f"stopped: {self.recorded} episodes recorded")]
        if key is Key.NEXT:
            return self._end_episode(now) if self.phase is Phase.RECORDING else self._start(now)
        # Re-record.
        if self.phase is Phase.RECORDING:
            return [Action(recorder="discard"), *self._reset(now, f"episode {self.recorded + 1} dropped")]
        if self.last_droppable:
            self.recorded -= 1
            self.last_droppable = False
            return [
                Action(recorder="discard_last"),
                Action(say=f"episode {self.recorded + 1} dropped, it is recorded again next"),
            ]
        return []


class TerminalKeys:
    """The session keys typed in this process's terminal (raw mode while open; restored on close).
    Without a terminal it reads nothing: the episodes run on their time limits."""

    def __init__(self) -> None:
        self.fd = sys.stdin.fileno() if sys.stdin is not None and sys.stdin.isatty() else None
        self._saved = None
        if self.fd is not None:
            import termios
            import tty

            self._saved = termios.tcgetattr(self.fd)
            # cbreak, not raw: Ctrl-C still interrupts the launcher.
            tty.setcbreak(self.fd)

    def read(self) -> list[Key]:
        if self.fd is None or not select.select([self.fd], [], [], 0)[0]:
            return []
        return decode_keys(os.read(self.fd, 64))

    def close(self) -> None:
        if self.fd is not None and self._saved is not None:
            import termios

            termios.tcsetattr(self.fd, termios.TCSADRAIN, self._saved)
            self._saved = None


class SessionRunner:
    """Carries a session's actions out over ROS through the launcher's rclpy node: the recorder's
    services, and /sim/reset."""

    def __init__(self, node, prefix: str, session: Session, sim: bool, keys: TerminalKeys, clock=None):
        import time

        from std_srvs.srv import Trigger

        from .. import contract

        self.node, self.session, self.keys = node, session, keys
        self.clock = clock or time.monotonic
        services = {
            "start": contract.RECORDER_START,
            "stop": contract.RECORDER_STOP,
            "discard": contract.RECORDER_DISCARD,
            "discard_last": contract.RECORDER_DISCARD_LAST,
        }
        self.recorder = {name: node.create_client(Trigger, f"{prefix}/{service}") for name, service in services.items()}
        self.ready = node.create_client(Trigger, f"{prefix}/{contract.RECORDER_READY}")
        self.reset = node.create_client(Trigger, f"{prefix}/{contract.SIM_RESET}") if sim else None
        self.started = False
        self.ready_deadline: float | None = None

    def poll(self) -> bool:
        """One look: starts the session once the recorder serves and receives its streams, applies
        keys and time. Returns whether the session is over."""
        if not self.started:
            if not all(client.service_is_ready() for client in (*self.recorder.values(), self.ready)):
                return False
            if not self._recorder_receives_everything():
                return False
            self.started = True
            self._carry_out(self.session.begin(self.clock()))
            return self.session.done
        for key in self.keys.read():
            self._carry_out(self.session.key(key, self.clock()))
        self._carry_out(self.session.tick(self.clock()))
        return self.session.done

    def _recorder_receives_everything(self) -> bool:
        """Whether the first episode may begin: /recorder/ready says yes, or READY_TIMEOUT has
        passed since the first ask (then what it still waits for is printed)."""
        now = self.clock()
        if self.ready_deadline is None:
            self.ready_deadline = now + READY_TIMEOUT
        answer = self._ask(self.ready)
        if answer is not None and answer.success:
            return True
        if now < self.ready_deadline:
            return False
        why = answer.message if answer is not None else "no answer"
        print(f"so101-launch: the recorder after {READY_TIMEOUT:g} s: {why}; recording anyway", flush=True)
        return True

    def _ask(self, client):
        """One Trigger call, waited for: its answer, or None (then that is printed)."""
        import rclpy
        from std_srvs.srv import Trigger

        future = client.call_async(Trigger.Request())
        rclpy.spin_until_future_complete(self.node, future, timeout_sec=CALL_TIMEOUT)
        if not future.done():
            print(f"so101-launch: no answer from {client.srv_name} within {CALL_TIMEOUT:g} s", flush=True)
            return None
        return future.result()

    def _call(self, client, what: str) -> bool:
        """One Trigger call, waited for; whether it succeeded (what went wrong is printed)."""
        answer = self._ask(client)
        if answer is None:
            print(f"so101-launch: ({what}) not done", flush=True)
            return False
        if not answer.success:
            print(f"so101-launch: {client.srv_name}: {answer.message}", flush=True)
        return answer.success

    def _carry_out(self, actions: list[Action]) -> None:
        for action in actions:
            if action.say:
                print(f"so101-launch: {action.say}", flush=True)
            if action.reset_sim and self.reset is not None:
                if self.reset.wait_for_service(timeout_sec=CALL_TIMEOUT):
                    self._call(self.reset, "a new scene")
                else:
                    print("so101-launch: /sim/reset not available; the scene is not reset", flush=True)
            if action.recorder:
                done = self._call(self.recorder[action.recorder], action.recorder)
                if done and action.recorder == "start":
                    self.session.started_at(self.clock())


# How long a service call may take before it is given up (a request is answered once the recorder
# has matched this client, which the first call may wait for).
CALL_TIMEOUT = 10.0
# How long the first episode waits for the recorder to receive every stream (it takes well under a
# second, a few on a loaded machine; a publisher whose samples can never reach it must not hold
# the session for good).
READY_TIMEOUT = 10.0
