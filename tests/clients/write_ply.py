"""Writes points (float32 x y z intensity, uint32 label records) as a PLY file with
Python's plyfile: the writer Open3D-free pipelines use. Usage:
write_ply.py RECORDS.bin OUT.ply ascii|binary_little_endian|binary_big_endian"""
import sys

import numpy as np
from plyfile import PlyData, PlyElement

records, out, encoding = sys.argv[1], sys.argv[2], sys.argv[3]
raw = np.fromfile(records, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("label", "<u4")])
order = ">" if encoding == "binary_big_endian" else "<"
vertex = np.empty(len(raw), dtype=[(name, order + kind) for name, kind in
                                   [("x", "f4"), ("y", "f4"), ("z", "f4"), ("intensity", "f4"), ("label", "u4")]])
for name in vertex.dtype.names:
    vertex[name] = raw[name]
element = PlyElement.describe(vertex, "vertex", comments=["the shipped drive's scans in the world frame"])
PlyData([element], text=(encoding == "ascii"), byte_order=order).write(out)
