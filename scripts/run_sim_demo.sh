#!/usr/bin/env bash
# The sim demo: set up, then run the simulated SO-101 headless with its built-in pick-and-place demo,
# and watch it from an rclpy peer that prints the arm, the cube and the task once a second.
# Both run in one private network namespace (DDS stays on this machine). Ctrl-C stops both.
#
#   scripts/run_sim_demo.sh [--duration SECONDS] [extra so101_sim_node flags, e.g. --lite]
set -euo pipefail

. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
help_if_asked "${BASH_SOURCE[0]}" "$@"
REPO_ROOT="${SO101_ROOT}"

"${REPO_ROOT}/scripts/setup.sh"
exec "${REPO_ROOT}/scripts/isolated" "${REPO_ROOT}/.venv/bin/python" -m so101.tools.watch_sim \
    --node "${CARGO_TARGET_DIR}/release/so101_sim_node" "$@"
