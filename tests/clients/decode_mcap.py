"""Decodes every message of an MCAP written by travmap with two independent Python
clients, mcap-ros2-support and rosbags, and prints a JSON summary per topic that the
Rust tests compare with travmap's own values.

Usage: decode_mcap.py FILE.mcap
"""

import json
import math
import struct
import sys
from pathlib import Path

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore


# PointField datatypes of coordinates: FLOAT32 and FLOAT64 (travmap's annotated cloud).
COORDINATE_FORMATS = {7: "<f", 8: "<d"}


def cloud_summary(msg):
    step = msg.point_step
    data = bytes(msg.data)
    names = [f.name for f in msg.fields]
    xyz = [next(f for f in msg.fields if f.name == axis) for axis in "xyz"]

    def at(offset):
        return [struct.unpack_from(COORDINATE_FORMATS[f.datatype], data, offset + f.offset)[0] for f in xyz]

    first = at(0) if data else None
    last = at(len(data) - step) if data else None
    return {"points": int(msg.width * msg.height), "fields": names, "first": first, "last": last}


def grid_summary(msg):
    cells = [int(c) for c in msg.data]
    return {
        "width": msg.info.width,
        "height": msg.info.height,
        "resolution": float(msg.info.resolution),
        "origin": [float(msg.info.origin.position.x), float(msg.info.origin.position.y)],
        "cells": cells,
    }


def grid_map_summary(msg):
    """The GridMap's geometry, and each layer as numbers (NaN as null)."""
    layers = {}
    for name, array in zip(msg.layers, msg.data):
        dims = [[d.label, int(d.size), int(d.stride)] for d in array.layout.dim]
        values = [None if math.isnan(v) else float(v) for v in array.data]
        layers[name] = {"dims": dims, "values": values}
    pose = msg.info.pose.position
    return {
        "resolution": float(msg.info.resolution),
        "length": [float(msg.info.length_x), float(msg.info.length_y)],
        "centre": [float(pose.x), float(pose.y), float(pose.z)],
        "basic_layers": list(msg.basic_layers),
        "layers": layers,
    }


def foxglove_grid_summary(msg):
    """The foxglove Grid's geometry, and each float32 field as numbers (NaN as null)."""
    data = bytes(msg.data)
    cells = len(data) // msg.cell_stride
    layers = {}
    for field in msg.fields:
        assert field.type == 7, field
        values = [struct.unpack_from("<f", data, i * msg.cell_stride + field.offset)[0] for i in range(cells)]
        layers[field.name] = [None if math.isnan(v) else float(v) for v in values]
    return {
        "column_count": int(msg.column_count),
        "cell_size": [float(msg.cell_size.x), float(msg.cell_size.y)],
        "row_stride": int(msg.row_stride),
        "origin": [float(msg.pose.position.x), float(msg.pose.position.y)],
        "layers": layers,
    }


def summarise(topic, schema, msg, stamp_ns):
    entry = {"topic": topic, "schema": schema, "log_time": int(stamp_ns),
             "stamp": int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
             if hasattr(msg, "header") else
             int(msg.timestamp.sec) * 1_000_000_000 + int(msg.timestamp.nanosec)
             if hasattr(msg, "timestamp") else None}
    if schema == "sensor_msgs/msg/PointCloud2":
        entry.update(cloud_summary(msg))
    elif schema == "nav_msgs/msg/OccupancyGrid":
        entry.update(grid_summary(msg))
    elif schema == "grid_map_msgs/msg/GridMap":
        entry.update(grid_map_summary(msg))
    elif schema == "foxglove_msgs/msg/Grid":
        entry.update(foxglove_grid_summary(msg))
    elif schema == "tf2_msgs/msg/TFMessage":
        entry["transforms"] = [[t.header.frame_id, t.child_frame_id, float(t.transform.translation.x),
                                float(t.transform.translation.y), float(t.transform.translation.z)]
                               for t in msg.transforms]
    elif schema == "travmap_msgs/msg/FrameMetrics":
        entry["frame_index"] = int(msg.frame_index)
        accuracy = float(msg.accuracy)
        entry["accuracy"] = None if math.isnan(accuracy) else accuracy
    return entry


def with_mcap(path):
    out = []
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            out.append(summarise(channel.topic, schema.name, decoded, message.log_time))
    return out


def with_rosbags(path):
    store = get_typestore(Stores.ROS2_HUMBLE)
    out = []
    with AnyReader([Path(path)], default_typestore=store) as reader:
        # travmap's own message type and grid_map's come with their definitions in
        # the file.
        extra = {}
        for conn in reader.connections:
            if conn.msgtype.startswith(("travmap_msgs/", "grid_map_msgs/", "foxglove_msgs/")):
                extra.update(get_types_from_msg(conn.msgdef.data, conn.msgtype))
        if extra:
            store.register(extra)
        for conn, timestamp, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            out.append(summarise(conn.topic, conn.msgtype, msg, timestamp))
    return out


def main():
    path = sys.argv[1]
    print(json.dumps({"mcap": with_mcap(path), "rosbags": with_rosbags(path)}, allow_nan=False))


if __name__ == "__main__":
    main()
