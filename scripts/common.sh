# shellcheck shell=bash
# Sourced by the project's shell scripts: the checkout's root, its build directory, and helpers.
#
# Each checkout builds into its own directory under ~/.cache/so101 (outside the clone, so a CI
# run in the same place reuses its build): the binaries carry their checkout's asset path, so
# two checkouts must not share one. Set CARGO_TARGET_DIR to override.
SO101_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [ -z "${CARGO_TARGET_DIR:-}" ]; then
    CARGO_TARGET_DIR="${HOME}/.cache/so101/target-$(printf '%s' "${SO101_ROOT}" | sha256sum | cut -c1-12)"
fi
export CARGO_TARGET_DIR

# sha256 of a file (coreutils, or Python where sha256sum is missing).
sha256_of() {
    if command -v sha256sum >/dev/null 2>&1; then
        sha256sum "$1" | cut -d' ' -f1
    else
        "${PYTHON:-python3}" -c 'import hashlib,sys; print(hashlib.sha256(open(sys.argv[1],"rb").read()).hexdigest())' "$1"
    fi
}

# `--help` or `-h` as the first argument of a script: print the script's header comment (its usage)
# and exit, before any set-up runs. Called as: help_if_asked "${BASH_SOURCE[0]}" "$@"
help_if_asked() {
    case "${2:-}" in
        -h | --help) ;;
        *) return 0 ;;
    esac
    # Lines 2.. up to the first line that is not a comment, without the leading "# ".
    sed -n '2,${/^#/!q;s/^# \{0,1\}//;p}' "$1"
    exit 0
}

# A wheel from PyPI, pinned by file name and sha256, in the download cache: downloaded when missing
# (or when the cached copy has another checksum), refused unless its checksum is the pinned one.
# Prints its path. Called as:
#   fetch_pinned_wheel PYTHON CACHE FILE SHA256 REQUIREMENT [PIP_DOWNLOAD_ARGS...]
fetch_pinned_wheel() {
    local python="$1" cache="$2" file="$3" sha256="$4" requirement="$5"
    shift 5
    local wheel="${cache}/${file}"
    mkdir -p "${cache}"
    if [[ -f "${wheel}" ]] && [[ "$(sha256_of "${wheel}")" != "${sha256}" ]]; then
        printf 'cached %s has the wrong checksum; downloading it again\n' "${file}" >&2
        rm -f "${wheel}"
    fi
    if [[ ! -f "${wheel}" ]]; then
        printf 'downloading %s into %s\n' "${requirement}" "${cache}" >&2
        "${python}" -m pip download --quiet --disable-pip-version-check --no-deps --only-binary=:all: \
            --dest "${cache}" "$@" "${requirement}" >&2 || { printf 'pip download of %s failed\n' "${requirement}" >&2; return 1; }
        [[ -f "${wheel}" ]] || { printf 'pip did not produce %s\n' "${wheel}" >&2; return 1; }
    fi
    local got
    got="$(sha256_of "${wheel}")"
    if [[ "${got}" != "${sha256}" ]]; then
        printf 'checksum mismatch for %s\n  expected sha256 %s\n  got      sha256 %s\nNothing was extracted. A re-run downloads the wheel again; if the mismatch persists, the file served for %s is not the pinned one and must not be used.\n' \
            "${wheel}" "${sha256}" "${got}" "${requirement}" >&2
        return 1
    fi
    printf '%s\n' "${wheel}"
}
