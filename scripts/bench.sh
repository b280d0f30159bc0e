#!/usr/bin/env bash
# Run the benchmarks of docs/benchmarks.md (set-up first), all peers in one private network namespace.
#   scripts/bench.sh                     all of them, with their defaults (no further arguments)
#   scripts/bench.sh sim [--repeats N] [--seconds S] [--samples N] [--json FILE]
#   scripts/bench.sh sim_core [--steps N] [--repeats N] [--num-envs N] [--cameras none,64x48,320x240] [--json FILE]
#   scripts/bench.sh driver [--repeats N] [--seconds S] [--baud B] [--json FILE]
#   scripts/bench.sh recorder [--seconds S] [--sweep-seconds S] [--rates HZ,...] [--repeats N] [--workdir DIR] [--json FILE]
#   scripts/bench.sh cameras [--repeats N] [--seconds S] [--frames N] [--json FILE]
#   scripts/bench.sh camera_node [--repeats N] [--seconds S] [--warmup S] [--json FILE]
#   scripts/bench.sh expert [--episodes N] [--speed S] [--seed N] [--json FILE]
#   scripts/bench.sh convert [--episodes N] [--sizes WxH,...] [--json FILE]
#   scripts/bench.sh storage [--qualities Q,...] [--episodes N] [--long-minutes M] [--converter-src DIR] [--json FILE]
#   scripts/bench.sh servo_model [--steps N] [--repeats N] [--json FILE]
#   scripts/bench.sh sysid [--output DIR] [--joints a,b] [--json FILE]
#   scripts/bench.sh camera_align [--poses N] [--seed N] [--boards a3,a4] [--json FILE]
#   scripts/bench.sh backgrounds [--repeats N] [--frames N] [--json FILE]
#   scripts/bench.sh train_step --dataset DIR [--policy act|pose_act|diffusion] [--steps N] [--skip W] [--variant V] [--json FILE]   (not in `all`: it needs a dataset)
#   scripts/bench.sh model_step --dataset DIR [--batch-size B] [--steps N] [--variant V] [--json FILE]   (not in `all`: it needs a dataset with cameras)
#   scripts/bench.sh pose_estimate CKPT --dataset DIR [--episodes N] [--anchor-episodes N] [--seed N] [--randomize [RANGES]] [--json FILE]   (not in `all`: it needs a pose_act policy)
#   scripts/bench.sh grasps CKPT [--failures-of EVAL_INFO | --episodes N --seed N] [--randomize [RANGES]] [--json FILE]   (not in `all`: it needs a policy)
set -euo pipefail
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
help_if_asked "${BASH_SOURCE[0]}" "$@"
REPO_ROOT="${SO101_ROOT}"
"${REPO_ROOT}/scripts/setup.sh"
run() {
    "${REPO_ROOT}/scripts/isolated" "${REPO_ROOT}/.venv/bin/python" -m "so101.bench.$1" \
        --bin-dir "${CARGO_TARGET_DIR}/release" "${@:2}"
}
case "${1:-all}" in
    sim | sim_core | driver | recorder | cameras | camera_node | expert | convert | storage | servo_model | sysid | camera_align | backgrounds | train_step | model_step | pose_estimate | grasps) run "$@" ;;
    all) run sim && run sim_core && run driver && run recorder && run cameras && run camera_node && run expert && run convert && run storage && run servo_model && run sysid && run camera_align && run backgrounds ;;
    *) echo "usage: scripts/bench.sh [sim|sim_core|driver|recorder|cameras|camera_node|expert|convert|storage|servo_model|sysid|camera_align|backgrounds|train_step|model_step|pose_estimate|grasps] [ARGS...]" >&2; exit 2 ;;
esac
