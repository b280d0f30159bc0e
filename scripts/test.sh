#!/usr/bin/env bash
# The project's test command (README, CI): set up, check formatting and lints (rustfmt, clippy,
# ruff, shellcheck), run the Rust unit and integration tests, the Python unit tests, then the rclpy
# integration tests against the real nodes. Everything that
# may open a DDS participant runs inside a private network namespace (scripts/isolated).
#
# The Python tests run in pytest-xdist workers, one test file per worker at a time (`--dist
# loadfile`, so a file's module fixtures are made once): most integration tests wait on nodes that
# run in real time, so two workers halve the suite's time on two cores (19.6 -> 9.0 min), and a
# third took another fifth off the integration tests. Workers: SO101_TEST_WORKERS for both phases
# (default: the CPU count for the unit tests, one more for the integration tests; at least 2 and 3,
# at most 4: each worker may train a LeRobot policy); extra arguments go to the integration tests'
# pytest (`-n 0` runs them serially).
# Tests marked `alone` (peers that time each answer on their own clock in a busy loop, which a
# preemption beside a training worker breaks) run after that, in one process.
set -euo pipefail

. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
help_if_asked "${BASH_SOURCE[0]}" "$@"
REPO_ROOT="${SO101_ROOT}"
cd "${REPO_ROOT}"

# Each step with the time since the start (min:s), so a log shows where the suite's time goes.
started=${SECONDS}
log() { printf '\033[1mtest:\033[0m [%d:%02d] %s\n' $(((SECONDS - started) / 60)) $(((SECONDS - started) % 60)) "$*" >&2; }

scripts/setup.sh

log "cargo fmt --check"
cargo fmt --all -- --check
log "ruff (python/, tests/) and shellcheck (scripts/)"
.venv/bin/ruff check python tests
.venv/bin/ruff format --check python tests
shellcheck scripts/*.sh scripts/vm/*.sh scripts/isolated .ci/run
log "cargo clippy"
cargo clippy --release --locked --workspace --all-targets -- -D warnings

log "Rust tests (in a private network namespace)"
scripts/isolated cargo test --release --locked --workspace

workers="${SO101_TEST_WORKERS:-$(nproc)}"
[ "${workers}" -ge 2 ] || workers=2
[ "${workers}" -le 4 ] || [ -n "${SO101_TEST_WORKERS:-}" ] || workers=4
parallel=(-n "${workers}" --dist loadfile)
# The integration tests wait on nodes running in real time more than they compute: one worker more
# than the cores (at least 3, at most 4) kept 1.6 of 2 cores busy and took the phase from 14.5 to
# 11.6 min on a 2-core host (2026-12-06); the unit tests compute, and keep one per core.
integration_workers="${SO101_TEST_WORKERS:-$(($(nproc) + 1))}"
[ "${integration_workers}" -ge 3 ] || [ -n "${SO101_TEST_WORKERS:-}" ] || integration_workers=3
[ "${integration_workers}" -le 4 ] || [ -n "${SO101_TEST_WORKERS:-}" ] || integration_workers=4
integration_parallel=(-n "${integration_workers}" --dist loadfile)

log "Python unit tests (python/tests: no DDS, no network namespace needed; ${workers} workers)"
.venv/bin/python -m pytest -q "${parallel[@]}" python/tests

log "rclpy integration tests (in a private network namespace; ${integration_workers} workers, a DDS domain each)"
export SO101_BIN_DIR="${CARGO_TARGET_DIR}/release"
scripts/isolated .venv/bin/python -m pytest -q "${integration_parallel[@]}" -m "not alone" --durations=15 tests/integration "$@"
log "rclpy integration tests that time their peer's answers on their own clock (alone, after the rest)"
# Exit status 5: arguments that select none of them.
scripts/isolated .venv/bin/python -m pytest -q -m alone tests/integration "$@" || [ $? -eq 5 ]
log "done"
