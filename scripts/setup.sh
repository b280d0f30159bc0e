#!/usr/bin/env bash
# One-time (and idempotent) set-up of everything the stack needs on a Debian 12 machine:
#   1. Debian packages: MuJoCo 2.2.2 (libmujoco-dev, mujoco-testspeed), libclang for the bindings,
#      unshare/ip for the private network namespaces the tests and nodes run in.
#   2. The Python venv .venv (Jazzy rclpy wheels, Fast DDS, pytest): scripts/setup_python.sh.
#   3. The third-party SO-101 meshes (pinned + checksum): scripts/fetch_assets.sh.
#   4. A release build of the Rust workspace into $CARGO_TARGET_DIR.
# Each step skips what is already in place, so a second run takes seconds.
set -euo pipefail

REPO_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-${HOME}/.cache/so101/target}"
APT_PACKAGES=(libmujoco-dev libmujoco-samples libclang-dev iproute2 util-linux python3-venv)

log() { printf '\033[1msetup:\033[0m %s\n' "$*" >&2; }
die() { printf 'setup: ERROR: %s\n' "$*" >&2; exit 1; }

missing=()
for package in "${APT_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "${package}" 2>/dev/null | grep -q "install ok installed" || missing+=("${package}")
done
if [ ${#missing[@]} -gt 0 ]; then
    log "installing Debian packages: ${missing[*]}"
    sudo_cmd=()
    [ "$(id -u)" = 0 ] || sudo_cmd=(sudo)
    "${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -q
    "${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
else
    log "Debian packages present"
fi

command -v cargo >/dev/null 2>&1 || die "cargo not found: install the Rust toolchain (https://rustup.rs), then rerun"

"${REPO_ROOT}/scripts/setup_python.sh"
PYTHON="${REPO_ROOT}/.venv/bin/python" "${REPO_ROOT}/scripts/fetch_assets.sh"

log "building the workspace (release) into ${CARGO_TARGET_DIR}"
cargo build --release --locked --workspace --manifest-path "${REPO_ROOT}/Cargo.toml"
log "ready: binaries in ${CARGO_TARGET_DIR}/release"
