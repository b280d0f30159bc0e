"""The results of one VM run: SO101_VIVID_RESULTS names their directory (scripts/camera_vm_test.sh
sets it after the VM has run)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from vivid_results import Results


@pytest.fixture(scope="session")
def results() -> Results:
    directory = os.environ.get("SO101_VIVID_RESULTS")
    if not directory or not (Path(directory) / "events.txt").is_file():
        pytest.fail("no VM results: run scripts/camera_vm_test.sh (it sets SO101_VIVID_RESULTS)")
    return Results(Path(directory))
