"""Parquet files read into pandas without Arrow's thread pools.

pandas.read_parquet reads through Arrow's thread pools, and a process that exits while their
threads wind down can abort at interpreter exit ("terminate called without an active exception",
SIGABRT after all its work was done: apache/arrow#34314) or hang there (apache/arrow#50482, where
use_threads=False avoids it). In a CI run so101-learn finished its training, printed its summary
and lost its exit code that way. The files read here are a dataset's metadata and per-episode
tables: small enough that one thread reads them as fast.
"""

from __future__ import annotations

from pathlib import Path


def read_parquet(path: Path | str, columns: list[str] | None = None):
    """The file as a pandas DataFrame, its index restored as pandas.read_parquet restores it."""
    import pyarrow.parquet as pq

    table = pq.read_table(path, columns=columns, use_threads=False, pre_buffer=False)
    return table.to_pandas(use_threads=False)
