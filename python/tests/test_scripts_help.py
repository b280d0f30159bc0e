"""Every shell entry point answers --help with its usage before any set-up runs (a newcomer reads
it before deciding to install gigabytes)."""

from __future__ import annotations

import subprocess

import pytest

from so101.paths import repo_root

SCRIPTS = [
    "record_dataset.sh",
    "run_sim_demo.sh",
    "bench.sh",
    "test.sh",
    "setup.sh",
    "setup_python.sh",
    "fetch_assets.sh",
    "isolated",
]


@pytest.mark.parametrize("script", SCRIPTS)
def test_help_prints_the_usage_and_sets_nothing_up(script, tmp_path):
    # An empty HOME and PATH: a script that started its set-up would find no cargo, apt or venv.
    done = subprocess.run(
        [str(repo_root() / "scripts" / script), "--help"],
        capture_output=True,
        text=True,
        timeout=10,
        env={"HOME": str(tmp_path), "PATH": "/usr/bin:/bin"},
    )
    assert done.returncode == 0, done.stderr
    assert len(done.stdout.splitlines()) >= 2, done.stdout
    assert "setup" not in done.stderr and "ERROR" not in done.stderr, done.stderr
