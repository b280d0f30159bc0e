"""`so101-bench NAME [ARGS...]`: runs one benchmark module of so101.bench (its --help for its
arguments). DDS peers: run it inside scripts/isolated, as scripts/bench.sh does."""

from __future__ import annotations

import importlib
import sys

BENCHMARKS = (
    "sim",
    "sim_core",
    "driver",
    "recorder",
    "cameras",
    "camera_node",
    "expert",
    "convert",
    "storage",
    "latency",
    "servo_model",
    "sysid",
)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help") or argv[0] not in BENCHMARKS:
        print(f"usage: so101-bench {{{','.join(BENCHMARKS)}}} [ARGS...]   (NAME --help for its arguments)", file=sys.stderr)
        return 0 if argv and argv[0] in ("-h", "--help") else 2
    module = importlib.import_module(f"so101.bench.{argv[0]}")
    sys.argv = [f"so101-bench {argv[0]}", *argv[1:]]
    return module.main()


if __name__ == "__main__":
    sys.exit(main())
