#!/usr/bin/env bash
# Fuzz the parsers of outside input with cargo-fuzz (libFuzzer; issue 40), one target at a time on one core.
#   scripts/fuzz.sh                      every target for 600 s
#   scripts/fuzz.sh TARGET [SECONDS]     one target (fuzz/fuzz_targets/TARGET.rs) for SECONDS (600)
#   scripts/fuzz.sh all [SECONDS]        every target for SECONDS each
#   scripts/fuzz.sh list                 the targets
# Needs a nightly toolchain and cargo-fuzz (`rustup toolchain install nightly`, `cargo install cargo-fuzz
# --locked`). Builds into fuzz/target (release, debug assertions, AddressSanitizer), runs from and adds
# to fuzz/corpus/TARGET, then minimizes that corpus (cmin) so what is committed stays small. A finding's
# reproducer, once fixed, goes to fuzz/regressions/TARGET/ under a name that says what it found. A crash,
# panic, hang (-timeout=5 s), allocation over 512 MB or RSS over 2 GB stops the run with its input
# in fuzz/artifacts/TARGET/. Logs: $FUZZ_LOG_DIR (logs/fuzz). The last line per target:
#   TARGET executions=N seconds=S corpus_files=F corpus_bytes=B status=ok|FINDING
# The corpora also run as ordinary tests (tests/fuzz_corpus.rs of each owning crate).
set -euo pipefail
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
help_if_asked "${BASH_SOURCE[0]}" "$@"
FUZZ_DIR="${SO101_ROOT}/fuzz"
LOG_DIR="${FUZZ_LOG_DIR:-${SO101_ROOT}/logs/fuzz}"
# cargo-fuzz's own target directory: another toolchain and other flags than the workspace's build.
unset CARGO_TARGET_DIR
targets() { sed -n 's/^name = "\(.*\)"$/\1/p' "${FUZZ_DIR}/Cargo.toml" | grep -v '^so101-fuzz$'; }

fuzz_one() {
    local target="$1" seconds="$2" log="${LOG_DIR}/$1.log" corpus="${FUZZ_DIR}/corpus/$1" status=ok
    local seeds=()
    mkdir -p "${corpus}"
    # Findings' reproducers (fuzz/regressions/TARGET/) seed the run but stay out of cmin's reach.
    [ -d "${FUZZ_DIR}/regressions/$1" ] && seeds+=("${FUZZ_DIR}/regressions/$1")
    echo "fuzz: ${target} for ${seconds} s (log ${log})"
    (cd "${FUZZ_DIR}" && cargo +nightly fuzz run "${target}" "${corpus}" "${seeds[@]}" -- \
        -max_total_time="${seconds}" -timeout=5 -rss_limit_mb=2048 -malloc_limit_mb=512 \
        -print_final_stats=1) >"${log}" 2>&1 || status=FINDING
    local executions
    executions="$(sed -n 's/^stat::number_of_executed_units: *\([0-9]*\)/\1/p' "${log}" | tail -n1)"
    if [ "${status}" = ok ]; then
        (cd "${FUZZ_DIR}" && cargo +nightly fuzz cmin "${target}" "${corpus}") >>"${log}" 2>&1
    fi
    echo "${target} executions=${executions:-?} seconds=${seconds} corpus_files=$(find "${corpus}" -type f | wc -l)" \
        "corpus_bytes=$(find "${corpus}" -type f -printf '%s\n' | awk '{s += $1} END {print s + 0}') status=${status}" |
        tee -a "${LOG_DIR}/summary.txt"
    [ "${status}" = ok ] || tail -n 40 "${log}" >&2
}

mkdir -p "${LOG_DIR}"
case "${1:-all}" in
    list) targets ;;
    all)
        (cd "${FUZZ_DIR}" && cargo +nightly fuzz build)
        for target in $(targets); do fuzz_one "${target}" "${2:-600}"; done
        ;;
    *)
        targets | grep -qx "$1" || { echo "fuzz: no target $1 (scripts/fuzz.sh list)" >&2; exit 2; }
        (cd "${FUZZ_DIR}" && cargo +nightly fuzz build "$1")
        fuzz_one "$1" "${2:-600}"
        ;;
esac
