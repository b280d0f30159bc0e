"""so101.paths: the checkout and the binaries come from the environment, with an error that says
what to do when they cannot be found."""

from __future__ import annotations

from pathlib import Path

import pytest

from so101 import paths


def test_the_venv_names_a_checkout_with_the_namespace_wrapper():
    # scripts/setup_python.sh sets SO101_ROOT for every process of the venv.
    root = paths.repo_root()
    assert (root / "scripts" / "isolated").is_file()
    assert paths.isolated_wrapper() == root / "scripts" / "isolated"
    assert paths.asset("so101_cube_to_bin.xml").is_file()


def test_without_so101_root_the_error_says_how_to_set_it(monkeypatch):
    monkeypatch.delenv("SO101_ROOT")
    with pytest.raises(paths.CheckoutNotFound, match="SO101_ROOT"):
        paths.repo_root()


def test_a_directory_that_is_not_a_checkout_is_refused(monkeypatch, tmp_path):
    monkeypatch.setenv("SO101_ROOT", str(tmp_path))
    with pytest.raises(paths.CheckoutNotFound, match="not a checkout"):
        paths.repo_root()


def test_bin_dir_follows_so101_bin_dir_then_cargo_target_dir(monkeypatch, tmp_path):
    monkeypatch.setenv("SO101_BIN_DIR", str(tmp_path))
    assert paths.bin_dir() == tmp_path
    with pytest.raises(FileNotFoundError, match="scripts/setup.sh"):
        paths.node_binary("no_such_node")
    monkeypatch.delenv("SO101_BIN_DIR")
    monkeypatch.setenv("CARGO_TARGET_DIR", str(tmp_path))
    assert paths.bin_dir() == Path(tmp_path) / "release"


def test_node_environment_drops_the_ros_wheels_library_path(monkeypatch):
    monkeypatch.setenv("LD_LIBRARY_PATH", "/somewhere/ros")
    env = paths.node_environment(rust_log="debug")
    assert "LD_LIBRARY_PATH" not in env and env["RUST_LOG"] == "debug"
