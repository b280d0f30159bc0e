"""so101.dataset.parquet reads what pandas writes, index and columns as pandas.read_parquet gives them."""

import numpy as np
import pandas as pd

from so101.dataset.parquet import read_parquet


def test_a_named_index_and_array_columns_read_back_as_pandas_reads_them(tmp_path):
    # The shapes LeRobot's files have: tasks.parquet indexed by the task's text, data files with
    # list columns.
    tasks = pd.DataFrame({"task_index": [0, 1]}, index=pd.Index(["lift the cube", "stack the cubes"], name="task"))
    tasks.to_parquet(tmp_path / "tasks.parquet")
    frames = pd.DataFrame({"index": [0, 1, 2], "observation.state": [np.arange(6, dtype=np.float32) + k for k in range(3)]})
    frames.to_parquet(tmp_path / "data.parquet")

    for path in (tmp_path / "tasks.parquet", tmp_path / "data.parquet"):
        pd.testing.assert_frame_equal(read_parquet(path), pd.read_parquet(path))
    assert list(read_parquet(tmp_path / "tasks.parquet").index) == ["lift the cube", "stack the cubes"]
    assert list(read_parquet(tmp_path / "data.parquet", columns=["index"]).columns) == ["index"]
