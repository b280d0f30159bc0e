#!/usr/bin/env bash
# The project's test command (README, CI): set up, check formatting and lints (rustfmt, clippy,
# ruff, shellcheck), run the Rust unit and integration tests, the Python unit tests, then the rclpy
# integration tests against the real nodes. Everything that
# may open a DDS participant runs inside a private network namespace (scripts/isolated).
set -euo pipefail

. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
help_if_asked "${BASH_SOURCE[0]}" "$@"
REPO_ROOT="${SO101_ROOT}"
cd "${REPO_ROOT}"

log() { printf '\033[1mtest:\033[0m %s\n' "$*" >&2; }

scripts/setup.sh

log "cargo fmt --check"
cargo fmt --all -- --check
log "ruff (python/, tests/) and shellcheck (scripts/)"
.venv/bin/ruff check python tests
.venv/bin/ruff format --check python tests
shellcheck scripts/*.sh scripts/isolated
log "cargo clippy"
cargo clippy --release --locked --workspace --all-targets -- -D warnings

log "Rust tests (in a private network namespace)"
scripts/isolated cargo test --release --locked --workspace

log "Python unit tests (python/tests: no DDS, no network namespace needed)"
.venv/bin/python -m pytest -q python/tests

log "rclpy integration tests (in a private network namespace)"
export SO101_BIN_DIR="${CARGO_TARGET_DIR}/release"
scripts/isolated .venv/bin/python -m pytest -q tests/integration "$@"
