#!/usr/bin/env bash
# Run the benchmarks of docs/benchmarks.md (set-up first), all peers in one private network namespace.
#   scripts/bench.sh [--repeats N] [--seconds S] [--samples N] [--json FILE]
set -euo pipefail
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
REPO_ROOT="${SO101_ROOT}"
"${REPO_ROOT}/scripts/setup.sh"
exec "${REPO_ROOT}/scripts/isolated" "${REPO_ROOT}/.venv/bin/python" "${REPO_ROOT}/scripts/bench_sim.py" \
    --bin-dir "${CARGO_TARGET_DIR}/release" "$@"
