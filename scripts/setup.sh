#!/usr/bin/env bash
# One-time (and idempotent) set-up of everything the stack needs on a Debian 12 machine:
#   1. Debian packages: MuJoCo 2.2.2 (libmujoco-dev; libmujoco-samples for the mujoco-testspeed
#      benchmark anchor), libclang for the bindings, a C toolchain, unshare/ip for the private
#      network namespaces the tests and nodes run in, libudev (gamepads), Mesa's EGL and OSMesa
#      (headless rendering of the cameras), FFmpeg's libraries (LeRobot decodes videos with them).
#   2. The Python venv .venv (CPython 3.12: Jazzy rclpy wheels, Fast DDS, LeRobot, pytest, the
#      project's `so101` package in python/): scripts/setup_python.sh.
#   3. The third-party SO-101 meshes (pinned + checksum): scripts/fetch_assets.sh.
#   4. A release build of the Rust workspace into $CARGO_TARGET_DIR.
# Each step skips what is already in place, so a second run takes seconds.
set -euo pipefail

. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
help_if_asked "${BASH_SOURCE[0]}" "$@"
REPO_ROOT="${SO101_ROOT}"
APT_PACKAGES=(libmujoco-dev libmujoco-samples libclang-dev gcc libc6-dev iproute2 util-linux python3-venv
              libudev-dev pkg-config shellcheck
              libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6
              libavutil57 libavcodec59 libavformat59 libavdevice59 libavfilter8 libswscale6 libswresample4)
MIN_RUST=1.95.0

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
rust_version="$(rustc --version | cut -d' ' -f2)"
[ "$(printf '%s\n%s\n' "${MIN_RUST}" "${rust_version}" | sort -V | head -n1)" = "${MIN_RUST}" ] ||
    die "rustc ${rust_version} is older than ${MIN_RUST}: run 'rustup update' (Debian's own rustc is too old)"
if ! cargo fmt --version >/dev/null 2>&1 || ! cargo clippy --version >/dev/null 2>&1; then
    command -v rustup >/dev/null 2>&1 || die "cargo fmt and cargo clippy are needed: install rustfmt and clippy"
    log "adding the rustfmt and clippy components"
    rustup component add rustfmt clippy
fi

"${REPO_ROOT}/scripts/setup_python.sh"
PYTHON="${REPO_ROOT}/.venv/bin/python" "${REPO_ROOT}/scripts/fetch_assets.sh"

# Every crate, dev-dependencies included: the tests later run in a namespace without network.
cargo fetch --locked --manifest-path "${REPO_ROOT}/Cargo.toml"
log "building the workspace (release) into ${CARGO_TARGET_DIR}"
cargo build --release --locked --workspace --manifest-path "${REPO_ROOT}/Cargo.toml"
log "ready: binaries in ${CARGO_TARGET_DIR}/release"
