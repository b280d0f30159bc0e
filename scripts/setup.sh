#!/usr/bin/env bash
# One-time (and idempotent) set-up of everything the stack needs on Debian 12 or 13 (Ubuntu 24.04
# by the package names; docs/platforms.md):
#   1. Debian packages, as scripts/apt_packages.sh names them on this distribution: MuJoCo 2.2.2
#      (libmujoco-dev; libmujoco-samples for the mujoco-testspeed benchmark anchor), libclang for
#      the bindings, a C toolchain, unshare/ip for the private network namespaces the tests and
#      nodes run in, libudev (gamepads), Mesa's EGL and OSMesa (headless rendering of the
#      cameras), FFmpeg's libraries (LeRobot decodes videos with them).
#   2. The Python venv .venv (CPython 3.12: Jazzy rclpy wheels, Fast DDS, LeRobot, pytest, the
#      project's `so101` package in python/): scripts/setup_python.sh.
#   3. The third-party SO-101 meshes (pinned + checksum): scripts/fetch_assets.sh, and the pictures
#      of the held-out shift set (scikit-image's samples, pinned + checksum): scripts/fetch_backgrounds.sh.
#   4. A release build of the Rust workspace into $CARGO_TARGET_DIR.
# Each step skips what is already in place, so a second run takes seconds.
set -euo pipefail

. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
help_if_asked "${BASH_SOURCE[0]}" "$@"
REPO_ROOT="${SO101_ROOT}"
MIN_RUST=1.95.0

log() { printf '\033[1msetup:\033[0m %s\n' "$*" >&2; }
die() { printf 'setup: ERROR: %s\n' "$*" >&2; exit 1; }

sudo_cmd=()
[ "$(id -u)" = 0 ] || sudo_cmd=(sudo)
apt_get() { "${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get "$@"; }

# The package names differ between releases (FFmpeg's carry their soname): apt's cache says which
# this one has. Without package lists yet (a fresh container), download them first.
lists_updated=0
if ! packages="$("${REPO_ROOT}/scripts/apt_packages.sh" 2>/dev/null)"; then
    log "downloading apt's package lists"
    apt_get update -q
    lists_updated=1
    packages="$("${REPO_ROOT}/scripts/apt_packages.sh")" ||
        die "apt offers not every package the stack needs (docs/platforms.md lists the supported releases)"
fi
mapfile -t APT_PACKAGES <<<"${packages}"

# Installed packages, and the names they provide (libavcodec-extra61 stands in for libavcodec61).
installed="$(dpkg-query -W -f='${db:Status-Abbrev}|${Package}|${Provides}\n' |
    awk -F'|' '$1 ~ /^[hi]i/ { print $2; n = split($3, p, ", *"); for (i = 1; i <= n; i++) { sub(/ .*/, "", p[i]); print p[i] } }')"
missing=()
for package in "${APT_PACKAGES[@]}"; do
    grep -qxF -- "${package}" <<<"${installed}" || missing+=("${package}")
done
if [ ${#missing[@]} -gt 0 ]; then
    log "installing Debian packages: ${missing[*]}"
    [ "${lists_updated}" = 1 ] || apt_get update -q
    apt_get install -y -q --no-install-recommends "${missing[@]}"
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
PYTHON="${REPO_ROOT}/.venv/bin/python" "${REPO_ROOT}/scripts/fetch_backgrounds.sh"

# Every crate, dev-dependencies included: the tests later run in a namespace without network.
cargo fetch --locked --manifest-path "${REPO_ROOT}/Cargo.toml"
log "building the workspace (release) into ${CARGO_TARGET_DIR}"
cargo build --release --locked --workspace --manifest-path "${REPO_ROOT}/Cargo.toml"
# The simulation core's Python extension (the in-process Gymnasium environments), installed into
# the venv. Built in a target directory of its own: maturin gives PyO3's build script an
# environment cargo alone does not (PYO3_ENVIRONMENT_SIGNATURE), so in a shared one every later
# cargo build, clippy and test rebuilt PyO3 and everything above it, and maturin rebuilt them again.
log "installing the so101_native Python extension into ${REPO_ROOT}/.venv"
rm -f "${CARGO_TARGET_DIR}"/wheels/so101_native-*.whl
"${REPO_ROOT}/.venv/bin/maturin" build --release --locked --quiet --compatibility linux --auditwheel skip \
    --manifest-path "${REPO_ROOT}/crates/so101_native/Cargo.toml" --target-dir "${CARGO_TARGET_DIR}/python_extension" \
    --interpreter "${REPO_ROOT}/.venv/bin/python" --out "${CARGO_TARGET_DIR}/wheels"
"${REPO_ROOT}/.venv/bin/python" -m pip install --quiet --disable-pip-version-check --force-reinstall --no-deps \
    "${CARGO_TARGET_DIR}"/wheels/so101_native-*.whl
log "ready: binaries in ${CARGO_TARGET_DIR}/release"
