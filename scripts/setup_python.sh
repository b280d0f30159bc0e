#!/usr/bin/env bash
# Create (or update) the project's Python environment .venv in the repository root:
# rclpy (ROS 2 Jazzy PyPI wheels), the standard message packages, Fast DDS, LeRobot and the test tools,
# all pinned in python/requirements.txt; then python/requirements-nodeps.txt with --no-deps (imitation,
# whose declared pins contradict LeRobot's: the file says why that is safe).
#
# Idempotent: a stamp in .venv holds the hashes of the requirements files and the interpreter version,
# so a second run with unchanged requirements returns at once. A venv made by another Python
# minor version is rebuilt from scratch.
#
# Environment:
#   PYTHON   interpreter to build the venv with (default: the first CPython 3.12 found; lerobot
#            0.6 needs 3.12, and the ros-jazzy-* wheels exist for it)
#   VENV     where to put the venv (default: <repo>/.venv)
#   VLA_VENV where to put the VLAs' environment (default: <repo>/.venv-vla): the venv plus
#            python/requirements-vla.txt (transformers, for SmolVLA and pi0), kept apart because
#            LeRobot imports transformers whenever it is installed, seconds at every LeRobot start
#
# Afterwards: `. scripts/ros_env.sh` (optional, see there), and run anything that opens a DDS
# participant inside `scripts/isolated`.
set -euo pipefail

REPO_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
. "${REPO_ROOT}/scripts/common.sh"
help_if_asked "${BASH_SOURCE[0]}" "$@"
REQUIREMENTS="${REPO_ROOT}/python/requirements.txt"
NODEPS_REQUIREMENTS="${REPO_ROOT}/python/requirements-nodeps.txt"
VLA_REQUIREMENTS="${REPO_ROOT}/python/requirements-vla.txt"
VENV="${VENV:-${REPO_ROOT}/.venv}"
VLA_VENV="${VLA_VENV:-${REPO_ROOT}/.venv-vla}"
STAMP="${VENV}/.so101-requirements.stamp"

log() { printf 'setup_python: %s\n' "$*" >&2; }
die() { printf 'setup_python: ERROR: %s\n' "$*" >&2; exit 1; }

[ -f "${REQUIREMENTS}" ] || die "missing ${REQUIREMENTS}"
[ -f "${NODEPS_REQUIREMENTS}" ] || die "missing ${NODEPS_REQUIREMENTS}"
[ -f "${VLA_REQUIREMENTS}" ] || die "missing ${VLA_REQUIREMENTS}"

# Pick the interpreter: $PYTHON if given, else the first CPython 3.12 found (on PATH, then pyenv's
# versions; Debian 12's own python3 is 3.11, which lerobot 0.6 does not support).
py_version_of() { "$1" -c 'import sys; print("%d.%d" % sys.version_info[:2])' 2>/dev/null; }
supported() { [ "$1" = "3.12" ]; }

if [ -n "${PYTHON:-}" ]; then
    command -v "${PYTHON}" >/dev/null 2>&1 || die "PYTHON=${PYTHON} not found"
    PY_VERSION="$(py_version_of "${PYTHON}")" || die "PYTHON=${PYTHON} does not run (a pyenv shim of a version that is not active?)"
    supported "${PY_VERSION}" ||
        die "PYTHON=${PYTHON} is Python ${PY_VERSION}; the venv needs CPython 3.12 (lerobot 0.6 and the ros-jazzy-* wheels)"
else
    PYTHON=""
    for candidate in python3.12 python3 /usr/local/bin/python3.12 /usr/bin/python3.12 "${HOME}"/.pyenv/versions/3.12*/bin/python3.12; do
        command -v "${candidate}" >/dev/null 2>&1 || continue
        version="$(py_version_of "${candidate}")" || continue
        if supported "${version}"; then PYTHON="${candidate}"; PY_VERSION="${version}"; break; fi
    done
    [ -n "${PYTHON}" ] ||
        die "no CPython 3.12 found (tried python3.12, python3, ~/.pyenv/versions/3.12*); install one (e.g. pyenv install 3.12) or set PYTHON=/path/to/python3.12"
fi

# The .pth hook written below is part of what a venv must have: bump its version when it changes.
PTH_VERSION=3
PACKAGE="${REPO_ROOT}/python/pyproject.toml"
PLUGINS="$(cat "${REPO_ROOT}"/python/plugins/*/pyproject.toml | sha256sum | cut -d" " -f1)"
WANT="requirements=$(sha256_of "${REQUIREMENTS}") nodeps=$(sha256_of "${NODEPS_REQUIREMENTS}") vla=$(sha256_of "${VLA_REQUIREMENTS}") vla_venv=${VLA_VENV} package=$(sha256_of "${PACKAGE}") plugins=${PLUGINS} python=${PY_VERSION} pth=${PTH_VERSION}"

# Fast path: nothing changed since the last successful run.
up_to_date() { [ -x "${VENV}/bin/python" ] && [ -x "${VLA_VENV}/bin/python" ] && [ -f "${STAMP}" ] && [ "$(cat "${STAMP}")" = "${WANT}" ]; }
if up_to_date; then
    log "${VENV} and ${VLA_VENV} are up to date (Python ${PY_VERSION})"
    exit 0
fi

# Serialize concurrent runs (two shells, CI steps) on one venv.
mkdir -p "$(dirname "${VENV}")"
if command -v flock >/dev/null 2>&1; then
    exec 9>"${VENV}.lock"
    flock 9
    # Another run may have finished the work while we waited.
    if up_to_date; then
        log "${VENV} and ${VLA_VENV} are up to date (Python ${PY_VERSION})"
        exit 0
    fi
fi

# A venv of another Python version (or a broken one) cannot be upgraded in place: rebuild it.
if [ -e "${VENV}" ]; then
    have="$(py_version_of "${VENV}/bin/python" || true)"
    if [ "${have}" != "${PY_VERSION}" ]; then
        log "removing ${VENV} (Python ${have:-unknown}, want ${PY_VERSION})"
        rm -rf "${VENV}"
    fi
fi

if [ ! -x "${VENV}/bin/python" ]; then
    log "creating ${VENV} with $(command -v "${PYTHON}") (Python ${PY_VERSION})"
    "${PYTHON}" -m venv "${VENV}"
fi

rm -f "${STAMP}"
log "installing ${REQUIREMENTS#"${REPO_ROOT}"/}"
"${VENV}/bin/python" -m pip install --quiet --disable-pip-version-check -r "${REQUIREMENTS}"
# Without their declared dependencies (whatever they import is pinned in requirements.txt).
log "installing ${NODEPS_REQUIREMENTS#"${REPO_ROOT}"/} (--no-deps)"
"${VENV}/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps -r "${NODEPS_REQUIREMENTS}"

# The project's own Python package `so101` (python/: converter, policy runner, Gymnasium envs,
# launcher, benchmarks), editable so the checkout is what runs; its dependencies are pinned above.
# (Its name before the move to python/ was so101-lerobot: a venv made then loses that one first.)
if "${VENV}/bin/python" -m pip show --quiet so101-lerobot >/dev/null 2>&1; then
    "${VENV}/bin/python" -m pip uninstall --quiet --yes so101-lerobot
fi
# A venv made when the VLAs' packages were part of it loses them (they live in the VLAs' environment).
if "${VENV}/bin/python" -m pip show --quiet transformers >/dev/null 2>&1; then
    log "removing the VLAs' packages from ${VENV} (they live in ${VLA_VENV})"
    # shellcheck disable=SC2046  # one argument per package name
    "${VENV}/bin/python" -m pip uninstall --quiet --yes $(sed -n 's/^\([A-Za-z0-9_.-]*\)==.*/\1/p' "${VLA_REQUIREMENTS}")
fi
# With it, LeRobot's plugins (python/plugins: robot type so101_ros, env type so101_sim, policy type
# pose_act), each a distribution of its own because LeRobot finds plugins by distribution name.
"${VENV}/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation \
    --editable "${REPO_ROOT}/python" \
    --editable "${REPO_ROOT}/python/plugins/lerobot_robot_so101_ros" \
    --editable "${REPO_ROOT}/python/plugins/lerobot_env_so101_sim" \
    --editable "${REPO_ROOT}/python/plugins/lerobot_policy_so101_pose_act"

# Every Python process of the venv gets the project's Fast DDS profile (4 MiB socket buffers, so
# rclpy receives camera images from the Rust nodes), RMW and checkout (SO101_ROOT: where the `so101`
# package finds scripts/isolated, the assets and the build) unless its environment names others:
# scripts, tests and one-off `python -c` alike, with no environment to source.
SITE_PACKAGES="$("${VENV}/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
cat >"${SITE_PACKAGES}/so101_ros_defaults.pth" <<EOF
import os; os.environ.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", "${REPO_ROOT}/python/fastdds_profile.xml"); os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp"); os.environ.setdefault("SO101_ROOT", "${REPO_ROOT}")
EOF

# Smoke test: the wheels import and the Fast DDS RMW library loads. No DDS participant is opened
# here (rclpy.init alone creates none), so this is safe outside a network namespace.
"${VENV}/bin/python" - <<'EOF'
import rclpy
from rclpy.utilities import get_rmw_implementation_identifier
from sensor_msgs.msg import JointState  # noqa: F401
from std_msgs.msg import Float64MultiArray  # noqa: F401
from std_srvs.srv import Trigger  # noqa: F401
from rosgraph_msgs.msg import Clock  # noqa: F401
from diagnostic_msgs.msg import DiagnosticArray  # noqa: F401
from geometry_msgs.msg import PoseStamped  # noqa: F401
import pytest  # noqa: F401
from lerobot.datasets.lerobot_dataset import LeRobotDataset  # noqa: F401
import so101.dataset.convert  # noqa: F401
import imitation.algorithms.bc  # noqa: F401  (installed --no-deps: its import chain must be complete)
import stable_baselines3  # noqa: F401
from so101.paths import repo_root
assert repo_root().is_dir()
rmw = get_rmw_implementation_identifier()
assert rmw == "rmw_fastrtps_cpp", rmw
import os
assert os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"].endswith("python/fastdds_profile.xml"), os.environ
EOF

# The VLAs' environment: a venv of the same interpreter that sees everything of the main one (its
# site-packages added as a site directory, so its .pth hooks and editable installs work there too)
# and adds python/requirements-vla.txt, plus its own copies of the console scripts (lerobot-*,
# so101-*) so that they run with its interpreter.
log "making ${VLA_VENV} (${VENV#"${REPO_ROOT}"/} + ${VLA_REQUIREMENTS#"${REPO_ROOT}"/})"
rm -rf "${VLA_VENV}"
"${VENV}/bin/python" -m venv --without-pip "${VLA_VENV}"
VLA_SITE_PACKAGES="$("${VLA_VENV}/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
# ros_wheels_bootstrapper (rclpy's wheels) finds the ROS libraries under sys.prefix, which here is
# the VLAs' environment: it is given the main one's before it re-executes the interpreter with them.
ROS_LIBRARY_PATH="$(printf '%s:' "${VENV}/lib" "${SITE_PACKAGES}"/ros_*.libs)"
printf 'import os, site; "_ROS_WHEELS_BOOTSTRAP_COMPLETE" in os.environ or os.environ.update(LD_LIBRARY_PATH="%s" + os.environ.get("LD_LIBRARY_PATH", "")); site.addsitedir("%s")\n' \
    "${ROS_LIBRARY_PATH}" "${SITE_PACKAGES}" >"${VLA_SITE_PACKAGES}/so101_main_venv.pth"
# lerobot and accelerate again (--no-deps, the main one's pins) for their console scripts.
LEROBOT_REQUIREMENT="$(grep -o '^lerobot\[[^]]*\]==[0-9.]*' "${REQUIREMENTS}" | sed 's/\[.*\]//')"
ACCELERATE_REQUIREMENT="$(grep '^accelerate==' "${REQUIREMENTS}")"
"${VENV}/bin/python" -m pip --python "${VLA_VENV}/bin/python" install --quiet --disable-pip-version-check \
    --no-deps --ignore-installed -r "${VLA_REQUIREMENTS}" "${LEROBOT_REQUIREMENT}" "${ACCELERATE_REQUIREMENT}"
"${VENV}/bin/python" -m pip --python "${VLA_VENV}/bin/python" install --quiet --disable-pip-version-check \
    --no-deps --no-build-isolation --ignore-installed --editable "${REPO_ROOT}/python"
"${VLA_VENV}/bin/python" - <<'EOF'
import sys
from lerobot.policies.smolvla.modeling_smolvla import SmolVLAPolicy  # noqa: F401
import rclpy  # noqa: F401
import so101.learn.vla  # noqa: F401
assert sys.prefix != sys.base_prefix
EOF

printf '%s\n' "${WANT}" >"${STAMP}"
log "done: ${VENV} (Python ${PY_VERSION}); run rclpy code as: scripts/isolated ${VENV#"${REPO_ROOT}"/}/bin/python ..."
