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


def test_the_main_job_refuses_a_task_the_contract_lacks_before_any_set_up(tmp_path):
    # so101-launch takes any text as cube_to_bin's episode text: the main job must not record a
    # misspelt task as cube_to_bin, nor install gigabytes before saying so.
    done = subprocess.run(
        [str(repo_root() / "scripts" / "record_dataset.sh"), "--task", "lift_cub", "--output", str(tmp_path / "run")],
        capture_output=True,
        text=True,
        timeout=10,
        env={"HOME": str(tmp_path), "PATH": "/usr/bin:/bin"},
    )
    assert done.returncode == 2, done.stdout + done.stderr
    assert "--task 'lift_cub' is not a task: one of cube_to_bin, lift_cube," in done.stderr
    assert "setup" not in done.stderr and not (tmp_path / "run").exists()


def test_the_main_job_refuses_an_unknown_action_space(tmp_path):
    done = subprocess.run(
        [str(repo_root() / "scripts" / "record_dataset.sh"), "--action-space", "cartesian"],
        capture_output=True,
        text=True,
        timeout=10,
        env={"HOME": str(tmp_path), "PATH": "/usr/bin:/bin"},
    )
    assert done.returncode == 2 and "--action-space is joint or ee" in done.stderr, done.stderr
