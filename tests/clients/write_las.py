"""Writes points (float32 x y z intensity, uint32 label records) as LAS or LAZ with
laspy (LAZ through lazrs), moved into UTM-like coordinates (+512000 m east, +4100000
m north) with a 1 mm scale, as survey software writes them. Usage:
write_las.py RECORDS.bin OUT.las|OUT.laz"""
import sys

import laspy
import numpy as np

records, out = sys.argv[1], sys.argv[2]
raw = np.fromfile(records, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("label", "<u4")])
header = laspy.LasHeader(point_format=3, version="1.2")
header.offsets = np.array([512000.0, 4100000.0, 0.0])
header.scales = np.array([0.001, 0.001, 0.001])
las = laspy.LasData(header)
las.x = raw["x"].astype(np.float64) + 512000.0
las.y = raw["y"].astype(np.float64) + 4100000.0
las.z = raw["z"].astype(np.float64)
las.intensity = np.clip(raw["intensity"] * 65535.0, 0, 65535).astype(np.uint16)
las.write(out)
