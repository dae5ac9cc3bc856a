"""Reads a travmap cell dataset with pyarrow and prints what the Rust test checks:
the row count, the column names and types, the travmap metadata keys, and every
row of one frame (as JSON; nulls as null). DuckDB and Polars read the whole file
too; every row they give must equal pyarrow's, or the script fails.

With REWRITE_DIR, also writes the dataset back as other writers would, travmap's
metadata kept, for `train` to read: pyarrow with each of its codecs, DuckDB
(`COPY ... TO`), Polars (`write_parquet`, every column nullable), and Polars with
one x_m nulled (`polars-null-x_m.parquet`, which `train` must refuse).

    python read_parquet.py cells.parquet FRAME [REWRITE_DIR]
"""

import json
import pathlib
import sys

import duckdb
import polars
import pyarrow.compute as pc
import pyarrow.parquet as pq

path, frame = sys.argv[1], int(sys.argv[2])
table = pq.read_table(path)
metadata = pq.read_metadata(path).metadata
expected = table.to_pylist()


def agree(reader, rows, columns):
    assert columns == table.column_names, f"{reader} columns {columns}"
    assert len(rows) == len(expected), f"{reader} read {len(rows)} rows, pyarrow {len(expected)}"
    for index, (row, want) in enumerate(zip(rows, expected)):
        assert row == want, f"{reader} row {index} differs from pyarrow's"


with duckdb.connect() as connection:
    result = connection.execute("SELECT * FROM read_parquet(?)", [path])
    columns = [column[0] for column in result.description]
    agree("duckdb", [dict(zip(columns, values)) for values in result.fetchall()], columns)
    duckdb_keys = sorted(
        key.decode()
        for (key,) in connection.execute(
            "SELECT key FROM parquet_kv_metadata(?)", [path]
        ).fetchall()
    )
frame_polars = polars.read_parquet(path)
agree("polars", frame_polars.to_dicts(), frame_polars.columns)

if len(sys.argv) > 3:
    out = pathlib.Path(sys.argv[3])
    for codec in ("none", "snappy", "gzip", "brotli", "lz4"):
        pq.write_table(table, out / f"pyarrow-{codec}.parquet", compression=codec)
    travmap_keys = {key.decode(): value.decode() for key, value in metadata.items()}
    quoted = lambda text: "'" + text.replace("'", "''") + "'"
    kv = ", ".join(f"{quoted(key)}: {quoted(value)}" for key, value in travmap_keys.items())
    duckdb.execute(
        f"COPY (SELECT * FROM read_parquet({quoted(path)})) TO {quoted(str(out / 'duckdb.parquet'))} "
        f"(FORMAT parquet, KV_METADATA {{{kv}}})"
    )
    frame_polars.write_parquet(out / "polars.parquet", metadata=travmap_keys)
    nulled = frame_polars.with_columns(
        polars.when(polars.int_range(polars.len()) == 0).then(None).otherwise(polars.col("x_m")).alias("x_m")
    )
    nulled.write_parquet(out / "polars-null-x_m.parquet", metadata=travmap_keys)

rows = table.filter(pc.equal(table["frame"], frame)).to_pylist()
print(
    json.dumps(
        {
            "rows": table.num_rows,
            "columns": [[field.name, str(field.type)] for field in table.schema],
            "metadata_keys": sorted(key.decode() for key in metadata),
            "duckdb_metadata_keys": duckdb_keys,
            "polars_types": [str(dtype) for dtype in frame_polars.dtypes],
            "frame_rows": rows,
        }
    )
)
