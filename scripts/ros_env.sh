# shellcheck shell=bash
# Source me (bash or zsh):  . scripts/ros_env.sh
#
# Environment of the project's rclpy side (.venv made by scripts/setup_python.sh).
#
# The ros-jazzy-* wheels need NO ROS environment to import and run: their dependency
# ros-wheels-bootstrapper installs a .pth hook that re-executes every Python process of the venv
# once with LD_LIBRARY_PATH extended by the venv's lib/ and site-packages/ros_*.libs (guard variable
# _ROS_WHEELS_BOOTSTRAP_COMPLETE=1). No AMENT_PREFIX_PATH, no setup.bash. So `.venv/bin/python`
# works on its own; this file only adds what the project chooses:
#   - the venv's bin/ first on PATH (python3, pytest),
#   - RMW_IMPLEMENTATION=rmw_fastrtps_cpp (the only RMW installed; also the default),
#   - FASTRTPS_DEFAULT_PROFILES_FILE = python/fastdds_profile.xml (4 MiB socket buffers, needed
#     to receive large messages such as camera images from the Rust nodes).
# Side effect of the bootstrapper to know: child processes of a venv Python inherit that
# LD_LIBRARY_PATH (the integration tests strip it for the Rust node).
#
# Anything that opens a DDS participant still runs inside scripts/isolated.

if [ -n "${BASH_SOURCE:-}" ]; then
    _so101_here="${BASH_SOURCE[0]}"
elif [ -n "${ZSH_VERSION:-}" ]; then
    # shellcheck disable=SC2296  # zsh's own expansion: the sourced file's path
    _so101_here="${(%):-%x}"
else
    _so101_here="$0"
fi
_so101_root="$(cd "$(dirname "${_so101_here}")/.." && pwd)"

if [ ! -x "${_so101_root}/.venv/bin/python" ]; then
    echo "ros_env.sh: ${_so101_root}/.venv is missing; run scripts/setup_python.sh first" >&2
else
    export VIRTUAL_ENV="${_so101_root}/.venv"
    case ":${PATH}:" in
        *":${VIRTUAL_ENV}/bin:"*) ;;
        *) export PATH="${VIRTUAL_ENV}/bin:${PATH}" ;;
    esac
fi
export RMW_IMPLEMENTATION=rmw_fastrtps_cpp
export FASTRTPS_DEFAULT_PROFILES_FILE="${_so101_root}/python/fastdds_profile.xml"
unset _so101_here _so101_root
