"""so101-launch's report of the episodes it recorded (so101.stack.launch.Launch): the expert's node
ends the run right after its last stop event, and a busy recorder may close that episode only
after, on its way out. The episode is still reported once the nodes are stopped (so101-learn demos
counts these lines: a CI run's summary once said 1 demonstration of 2). Stand-in processes, no DDS."""

from __future__ import annotations

import os
import sys

from bag_writer import EpisodeBag

from so101.stack.launch import Launch
from so101.stack.launch_plan import NodeSpec

# A recorder that closes its open episode (writes metadata.yaml) when it is stopped with SIGINT.
RECORDER = """
import os, signal, sys, time
from pathlib import Path

episode, ready = Path(sys.argv[1]), Path(sys.argv[2])

def close(*_):
    os.replace(episode / "metadata.closing", episode / "metadata.yaml")
    sys.exit(0)

signal.signal(signal.SIGINT, close)
ready.touch()
while True:
    time.sleep(0.05)
"""


def test_an_episode_the_recorder_closes_after_the_run_ended_is_reported(tmp_path, capsys):
    bags = tmp_path / "bags"
    episodes = [EpisodeBag(bags / f"episode_00000{index}").close(success=index == 0) for index in (0, 1)]
    for episode in episodes:  # both open when the run starts
        (episode / "metadata.yaml").rename(episode / "metadata.closing")
    # The expert's stand-in: the first episode closes during the run, then it ends the run at once.
    expert = f"import os; os.replace({str(episodes[0] / 'metadata.closing')!r}, {str(episodes[0] / 'metadata.yaml')!r})"

    launch = Launch(tmp_path, ready_timeout=20.0, stop_timeout=20.0, namespace="")
    launch.remember_earlier_episodes(bags)  # as so101-launch does before it starts the nodes
    ready = tmp_path / "recorder.ready"
    env = dict(os.environ)
    launch.start(
        NodeSpec("recorder_node", [sys.executable, "-c", RECORDER, str(episodes[1]), str(ready)], ready=f"path {ready}", env=env)
    )
    launch.start(NodeSpec("teleop_node", [sys.executable, "-c", expert], ends_run=True, env=env))
    ended = launch.watch(bags)
    assert ended is not None and ended.spec.name == "teleop_node"
    reported_during_the_run = capsys.readouterr().out
    assert "recorded episode_000000 (success)" in reported_during_the_run
    assert "episode_000001" not in reported_during_the_run

    launch.stop_all()
    launch.report_episodes(bags)
    after = capsys.readouterr().out
    assert "recorded episode_000001 (failure)" in after, after
    assert "episode_000000" not in after, "an episode reported twice"
