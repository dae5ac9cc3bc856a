"""Reads a travmap dataset folder of part files as one table with pyarrow.dataset,
DuckDB and Polars, and checks that each gives every row of the same cells written
as one file (in the order of the parts' names, frame by frame).

    python read_parquet_parts.py cells/ cells.parquet

Prints {"rows": N, "parts": K} as JSON; fails on the first difference.
"""

import json
import pathlib
import sys

import duckdb
import polars
import pyarrow.dataset as ds
import pyarrow.parquet as pq

folder, single = pathlib.Path(sys.argv[1]), sys.argv[2]
expected = pq.read_table(single).to_pylist()
parts = sorted(folder.glob("part-*.parquet"))


def agree(reader, rows):
    assert len(rows) == len(expected), f"{reader} read {len(rows)} rows, the single file holds {len(expected)}"
    for index, (row, want) in enumerate(zip(rows, expected)):
        assert row == want, f"{reader} row {index} differs from the single file's"


# Each reader is given the folder as a user would. pyarrow.dataset and Polars read
# the parts in the order of their names; DuckDB is asked to.
agree("pyarrow.dataset", ds.dataset(folder, format="parquet").to_table().to_pylist())
with duckdb.connect() as connection:
    result = connection.execute(
        "SELECT * EXCLUDE (filename, file_row_number) FROM read_parquet(?, filename = true, file_row_number = true) ORDER BY filename, file_row_number",
        [str(folder / "*.parquet")],
    )
    columns = [column[0] for column in result.description]
    agree("duckdb", [dict(zip(columns, values)) for values in result.fetchall()])
agree("polars", polars.read_parquet(folder / "*.parquet").to_dicts())
print(json.dumps({"rows": len(expected), "parts": len(parts)}))
