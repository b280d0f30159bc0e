"""Where this checkout keeps things the Python tools start: the stack's binaries and the
network-namespace wrapper."""

from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
ISOLATED = REPO_ROOT / "scripts" / "isolated"


def bin_dir() -> Path:
    """The stack's binaries: $SO101_BIN_DIR, else the release directory of the build scripts/common.sh
    uses ($CARGO_TARGET_DIR, or one per checkout under ~/.cache/so101)."""
    if os.environ.get("SO101_BIN_DIR"):
        return Path(os.environ["SO101_BIN_DIR"])
    target = os.environ.get("CARGO_TARGET_DIR") or (
        Path.home() / ".cache" / "so101" / f"target-{hashlib.sha256(str(REPO_ROOT).encode()).hexdigest()[:12]}"
    )
    return Path(target) / "release"


def node_binary(name: str) -> Path:
    """A built binary of the stack; FileNotFoundError with what to do when it is missing."""
    path = bin_dir() / name
    if not path.is_file():
        raise FileNotFoundError(f"{path} not found: build the workspace (scripts/setup.sh) or set SO101_BIN_DIR")
    return path


def node_environment() -> dict[str, str]:
    """The environment for a Rust node started from the venv's Python: without the ROS wheels'
    LD_LIBRARY_PATH additions, which the nodes do not need; the venv's executables (the Rerun
    viewer `rerun` that so101_rerun --spawn starts) on PATH."""
    env = {k: v for k, v in os.environ.items() if k != "LD_LIBRARY_PATH"}
    venv_bin = str(Path(sys.executable).parent)
    env["PATH"] = os.pathsep.join([venv_bin, *(p for p in env.get("PATH", "").split(os.pathsep) if p and p != venv_bin)])
    return env
