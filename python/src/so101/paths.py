"""Where the checkout keeps what the Python tools start: the stack's binaries, the network-namespace
wrapper, the project's assets.

The checkout's root comes from the environment (`SO101_ROOT`), which the set-up's venv sets for
every process it runs (scripts/setup_python.sh writes it into a .pth file beside this package); the
binaries from `SO101_BIN_DIR`, else from the build directory scripts/common.sh uses."""

from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path


class CheckoutNotFound(RuntimeError):
    pass


def repo_root() -> Path:
    """The checkout this package was set up from ($SO101_ROOT)."""
    root = os.environ.get("SO101_ROOT")
    if not root:
        raise CheckoutNotFound(
            "SO101_ROOT is not set: run the tools with the project's venv (scripts/setup.sh makes .venv and "
            "sets it there), or export SO101_ROOT=/path/to/the/checkout"
        )
    path = Path(root)
    if not (path / "scripts" / "isolated").is_file():
        raise CheckoutNotFound(f"SO101_ROOT={root} is not a checkout of the SO-101 stack (no scripts/isolated)")
    return path


def isolated_wrapper() -> Path:
    """scripts/isolated: runs a command inside a private network namespace with only loopback."""
    return repo_root() / "scripts" / "isolated"


def asset(relative: str) -> Path:
    """A file under the checkout's assets/ directory."""
    return repo_root() / "assets" / relative


def bin_dir() -> Path:
    """The stack's binaries: $SO101_BIN_DIR, else the release directory of the build scripts/common.sh
    uses ($CARGO_TARGET_DIR, or one per checkout under ~/.cache/so101)."""
    if os.environ.get("SO101_BIN_DIR"):
        return Path(os.environ["SO101_BIN_DIR"])
    target = os.environ.get("CARGO_TARGET_DIR") or (
        Path.home() / ".cache" / "so101" / f"target-{hashlib.sha256(str(repo_root()).encode()).hexdigest()[:12]}"
    )
    return Path(target) / "release"


def node_binary(name: str) -> Path:
    """A built binary of the stack; FileNotFoundError with what to do when it is missing."""
    path = bin_dir() / name
    if not path.is_file():
        raise FileNotFoundError(f"{path} not found: build the workspace (scripts/setup.sh) or set SO101_BIN_DIR")
    return path


def node_environment(rust_log: str | None = None) -> dict[str, str]:
    """The environment for a Rust node started from the venv's Python: without the ROS wheels'
    LD_LIBRARY_PATH additions, which the nodes do not need; the venv's executables (the Rerun
    viewer `rerun` that so101_rerun --spawn starts) on PATH; RUST_LOG when given."""
    env = {k: v for k, v in os.environ.items() if k not in ("LD_LIBRARY_PATH", "_ROS_WHEELS_BOOTSTRAP_COMPLETE")}
    venv_bin = str(Path(sys.executable).parent)
    env["PATH"] = os.pathsep.join([venv_bin, *(p for p in env.get("PATH", "").split(os.pathsep) if p and p != venv_bin)])
    if rust_log is not None:
        env["RUST_LOG"] = rust_log
    return env
