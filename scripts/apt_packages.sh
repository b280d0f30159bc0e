#!/usr/bin/env bash
# Prints the Debian packages the stack needs, one per line, under the names this machine's apt
# knows (scripts/setup.sh installs the ones that are missing). Debian 12, Debian 13 and Ubuntu
# 24.04 name most of them alike; FFmpeg's libraries carry their soname in the package name
# (libavcodec59 on Debian 12, libavcodec60 on Ubuntu 24.04, libavcodec61 on Debian 13), so for
# each of those the newest libNAME<N> apt knows is taken. docs/platforms.md has what was tried.
#
# Reads apt's cache only (one apt-cache call, no network, no root). Exits 1, naming what is
# missing on stderr, when apt does not know a package (package lists not downloaded yet: run
# apt-get update; or a distribution that does not ship it).
set -euo pipefail

# Same name everywhere: MuJoCo 2.2.2 (libmujoco-samples: the mujoco-testspeed benchmark anchor),
# libclang for the bindings, a C toolchain, unshare/ip for the private network namespaces,
# python3-venv, libudev (gamepads), Mesa's EGL (headless rendering of the cameras), shellcheck
# (the test command lints scripts/ with it).
FIXED=(libmujoco-dev libmujoco-samples libclang-dev gcc libc6-dev iproute2 util-linux python3-venv
       libudev-dev pkg-config shellcheck
       libegl1 libegl-mesa0 libgl1-mesa-dri)
# Taken where apt has them: OSMesa, the sim's fallback where EGL is missing (newer Mesa releases
# no longer build it; Ubuntu 24.04 ships it from a separate source package, mesa-compat).
OPTIONAL=(libosmesa6)
# FFmpeg's runtime libraries (LeRobot decodes videos with them): name without the soname number.
VERSIONED=(libavutil libavcodec libavformat libavdevice libavfilter libswscale libswresample)

command -v apt-cache >/dev/null 2>&1 || { echo 'apt_packages: apt-cache not found (the stack is set up on Debian or Ubuntu)' >&2; exit 1; }

# The names apt knows (from the package lists and dpkg's status) that are of interest, at once.
pattern="$(IFS='|'; printf '%s' "${FIXED[*]}|${OPTIONAL[*]}|(${VERSIONED[*]})[0-9]+")"
known="$(apt-cache pkgnames | grep -xE -- "${pattern}" || true)"

chosen=()
missing=()
for package in "${FIXED[@]}"; do
    if grep -qxF -- "${package}" <<<"${known}"; then chosen+=("${package}"); else missing+=("${package}"); fi
done
for package in "${OPTIONAL[@]}"; do
    if grep -qxF -- "${package}" <<<"${known}"; then chosen+=("${package}"); fi
done
for stem in "${VERSIONED[@]}"; do
    newest="$(grep -xE -- "${stem}[0-9]+" <<<"${known}" | sort -V | tail -n1 || true)"
    if [ -n "${newest}" ]; then chosen+=("${newest}"); else missing+=("${stem}<N>"); fi
done

if [ ${#missing[@]} -gt 0 ]; then
    printf 'apt_packages: apt knows none of: %s (run apt-get update; see docs/platforms.md)\n' "${missing[*]}" >&2
    exit 1
fi
printf '%s\n' "${chosen[@]}"
