"""The benchmarks of docs/benchmarks.md, one module each (`python -m so101.bench NAME ...`, or
scripts/bench.sh, which runs them inside a private network namespace)."""
