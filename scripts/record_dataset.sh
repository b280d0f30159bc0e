#!/usr/bin/env bash
# The main job: set up, then record episodes of the scripted expert in the simulation (sim node,
# expert and recorder started together by so101-launch), turn the episode bags into a LeRobot
# dataset, and print a summary (episodes, successes, frames, where the dataset is).
#
#   scripts/record_dataset.sh [--episodes N] [--output DIR] [--seed S] [--lite] [--cameras SPEC]
#                             [--raw-images | --jpeg-quality Q] [--task TASK] [--action-space joint|ee]
#
# Defaults: 5 episodes of cube_to_bin, the three cameras at 640x480 and 30 Hz, meshes on, output
# runs/dataset-<time>/ (bags/, dataset/, logs/). --task records another of the contract's tasks
# (a wrong name lists them): the sim scores it, the expert plays it, the episodes carry its text,
# the dataset is local/so101_TASK. --action-space ee writes end-effector actions and state beside the joints
# (docs/lerobot.md). The bags keep the cameras' JPEG frames
# (image_raw/compressed, so101-launch's default quality); --raw-images keeps the raw frames instead
# (10x the disk). Everything with DDS runs in scripts/isolated.
set -euo pipefail

. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
REPO_ROOT="${SO101_ROOT}"

episodes=5
seed=0
task=cube_to_bin
action_space=joint
output="${REPO_ROOT}/runs/dataset-$(date +%Y%m%d-%H%M%S)"
sim_args=()
launch_args=()
usage() { help_if_asked "${BASH_SOURCE[0]}" --help; }
while [ $# -gt 0 ]; do
    case "$1" in
        --episodes) episodes="$2"; shift 2 ;;
        --output) output="$2"; shift 2 ;;
        --seed) seed="$2"; shift 2 ;;
        --lite) launch_args+=(--lite); shift ;;
        --cameras) sim_args+=(--cameras "$2"); shift 2 ;;
        --raw-images) launch_args+=(--raw-images); shift ;;
        --jpeg-quality) launch_args+=(--jpeg-quality "$2"); shift 2 ;;
        --task) task="$2"; shift 2 ;;
        --action-space) action_space="$2"; shift 2 ;;
        -h|--help) usage; exit 0 ;;
        *) echo "record_dataset.sh: unknown argument $1 (--help)" >&2; exit 2 ;;
    esac
done
case "${episodes}" in ''|*[!0-9]*|0) echo "record_dataset.sh: --episodes needs a positive number" >&2; exit 2 ;; esac
case "${action_space}" in joint|ee) ;; *) echo "record_dataset.sh: --action-space is joint or ee" >&2; exit 2 ;; esac
[ ! -e "${output}/dataset" ] || { echo "record_dataset.sh: ${output}/dataset exists already" >&2; exit 2; }

# The task's name as the contract spells it (its tasks are listed there once), or exit 2 naming
# them: any other text would record cube_to_bin under it (so101-launch --task takes free text).
contract_task() {
    "$1" - "${task}" "${REPO_ROOT}/python/src/so101" <<'PY'
import sys

sys.path.insert(0, sys.argv[2])
import contract  # the generated facts alone (no package import, so no venv needed)

name = sys.argv[1].replace("-", "_")
if name not in contract.TASKS:
    print(f"record_dataset.sh: --task {sys.argv[1]!r} is not a task: one of {', '.join(contract.TASKS)}", file=sys.stderr)
    sys.exit(2)
print(name)
PY
}
# Checked before the set-up where a python3 is on PATH already (a typo costs no install), else once
# the set-up has made the venv.
task_checked=0
if command -v python3 >/dev/null 2>&1; then
    task="$(contract_task python3)" || exit 2
    task_checked=1
fi

"${REPO_ROOT}/scripts/setup.sh"

VENV_BIN="${REPO_ROOT}/.venv/bin"
if [ "${task_checked}" = 0 ]; then
    task="$(contract_task "${VENV_BIN}/python")" || exit 2
fi
repo_id="local/so101_${task}"
mkdir -p "${output}"
echo "==> recording ${episodes} expert episode(s) of ${task} into ${output}/bags"
"${REPO_ROOT}/scripts/isolated" "${VENV_BIN}/so101-launch" --robot sim --control expert --episodes "${episodes}" \
    --seed "${seed}" --task "${task}" --record --bags "${output}/bags" --log-dir "${output}/logs" \
    ${launch_args[@]+"${launch_args[@]}"} --sim-args "${sim_args[*]+${sim_args[*]}}"

echo "==> converting to a LeRobot dataset"
"${VENV_BIN}/so101-bag-to-lerobot" "${output}/bags" --output "${output}/dataset" --repo-id "${repo_id}" \
    --action-space "${action_space}" | tee "${output}/convert.txt"

dataset="$(cd "${output}/dataset" && pwd)"
cat <<SUMMARY

Summary: $(grep -m1 'episode(s)' "${output}/convert.txt")
  dataset:  ${dataset} (repo id ${repo_id}, ${action_space} actions, LeRobot v3.0)
  bags:     ${output}/bags ($(du -sh "${output}/bags" | cut -f1))     logs: ${output}/logs
Next: a policy trained on this CPU (docs/learning.md): 50 demonstrations without
cameras, a state-based ACT with lerobot-train, evaluated through so101-run-policy:
  cd ${REPO_ROOT}
  .venv/bin/so101-learn demos --task ${task} --episodes 50 --output runs/demos50
  .venv/bin/so101-learn act --dataset runs/demos50/dataset --eval 100
A camera policy (joints + three 96x72 cameras, no cube pose) trains on this CPU too, in 1-2
hours (83 of 100 cube_to_bin episodes; this dataset's 640x480 frames take ~28 s a step here):
  .venv/bin/so101-learn demos --task ${task} --episodes 100 --lite --cameras top:96x72,front:96x72,wrist:96x72 \\
      --no-environment-state --output runs/camdemos
  .venv/bin/so101-learn act --dataset runs/camdemos/dataset --eval 100
SUMMARY
