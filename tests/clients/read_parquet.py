"""Reads a travmap cell dataset with pyarrow and prints what the Rust test checks:
the row count, the column names and types, the travmap metadata keys, and every
row of one frame (as JSON; nulls as null).

    python read_parquet.py cells.parquet FRAME
"""

import json
import sys

import pyarrow.compute as pc
import pyarrow.parquet as pq

path, frame = sys.argv[1], int(sys.argv[2])
table = pq.read_table(path)
metadata = pq.read_metadata(path).metadata
rows = table.filter(pc.equal(table["frame"], frame)).to_pylist()
print(
    json.dumps(
        {
            "rows": table.num_rows,
            "columns": [[field.name, str(field.type)] for field in table.schema],
            "metadata_keys": sorted(key.decode() for key in metadata),
            "frame_rows": rows,
        }
    )
)
