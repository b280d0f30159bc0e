# Sourced by the project's shell scripts: the checkout's root and its build directory.
#
# Each checkout builds into its own directory under ~/.cache/so101 (outside the clone, so a CI
# run in the same place reuses its build): the binaries carry their checkout's asset path, so
# two checkouts must not share one. Set CARGO_TARGET_DIR to override.
SO101_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [ -z "${CARGO_TARGET_DIR:-}" ]; then
    CARGO_TARGET_DIR="${HOME}/.cache/so101/target-$(printf '%s' "${SO101_ROOT}" | sha256sum | cut -c1-12)"
fi
export CARGO_TARGET_DIR
