#!/usr/bin/env python3
"""Writes the seed corpus in fuzz/seeds/ from the shared data: small, real inputs
for every target of travmap::fuzzing. Run from the repository root after
`cargo build --release`; needs `../shared/data` and the Python `mcap`, `pyarrow` and
`rosbags` packages (the CI client venv has them).

    python3 fuzz/make_seeds.py [--travmap target/release/travmap] [--data ../shared/data]
"""

import argparse
import json
import pathlib
import shutil
import struct
import subprocess
import tempfile
import zlib

import sys

import pyarrow.parquet as pq
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_typestore

POINTS = 64  # points per scan in the seeds: real layout, cheap to mutate


def png(width: int, height: int) -> bytes:
    """A small RGB gradient PNG (filter 0 on every row)."""
    rows = b"".join(
        b"\0" + bytes(v for x in range(width) for v in (8 * x, 16 * y, 128))
        for y in range(height)
    )

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b"")


def tiny_sequence(source: pathlib.Path, out: pathlib.Path) -> None:
    """Frames 0..2 of `source`, each scan cut to its first POINTS points, with a small image."""
    for sub in ("velodyne", "labels", "image_2"):
        (out / sub).mkdir(parents=True)
    shutil.copy(source / "calib.txt", out / "calib.txt")
    for name in ("poses.txt", "times.txt"):
        lines = (source / name).read_text().splitlines()[:3]
        (out / name).write_text("\n".join(lines) + "\n")
    for frame in range(3):
        stem = f"{frame:06}"
        scan = (source / "velodyne" / f"{stem}.bin").read_bytes()[: 16 * POINTS]
        (out / "velodyne" / f"{stem}.bin").write_bytes(scan)
        labels = (source / "labels" / f"{stem}.label").read_bytes()[: 4 * POINTS]
        (out / "labels" / f"{stem}.label").write_bytes(labels)
        (out / "image_2" / f"{stem}.png").write_bytes(png(32, 16))


def pcd_files(scan: bytes) -> dict:
    """A KITTI scan as PCD with each kind of DATA; binary_compressed as LZF literal runs."""
    points = [struct.unpack("<4f", scan[i : i + 16]) for i in range(0, len(scan), 16)]
    header = (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z intensity\n"
        "SIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n"
        f"WIDTH {len(points)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(points)}\n"
    )
    ascii_rows = "".join(" ".join(repr(v) for v in p) + "\n" for p in points)
    columns = b"".join(struct.pack("<f", p[c]) for c in range(4) for p in points)
    lzf = b"".join(bytes([len(columns[i : i + 32]) - 1]) + columns[i : i + 32] for i in range(0, len(columns), 32))
    return {
        "binary.pcd": (header + "DATA binary\n").encode() + scan,
        "ascii.pcd": (header + "DATA ascii\n" + ascii_rows).encode(),
        "binary_compressed.pcd": (header + "DATA binary_compressed\n").encode()
        + struct.pack("<II", len(lzf), len(columns))
        + lzf,
    }


def ply_files(scan: bytes) -> dict:
    """A KITTI scan as PLY in each encoding, with a face element after the vertices."""
    points = [struct.unpack("<4f", scan[i : i + 16]) for i in range(0, len(scan), 16)]

    def header(encoding: str) -> str:
        return (
            f"ply\nformat {encoding} 1.0\ncomment a KITTI scan\nelement vertex {len(points)}\n"
            "property float x\nproperty float y\nproperty float z\nproperty float intensity\n"
            "element face 0\nproperty list uchar int vertex_indices\nend_header\n"
        )

    return {
        "ascii.ply": (header("ascii") + "".join(" ".join(repr(v) for v in p) + "\n" for p in points)).encode(),
        "binary_little_endian.ply": header("binary_little_endian").encode() + scan,
        "binary_big_endian.ply": header("binary_big_endian").encode()
        + b"".join(struct.pack(">4f", *p) for p in points),
    }


def las_files(scan: bytes, out: pathlib.Path) -> dict:
    """A KITTI scan as LAS and LAZ, written by laspy (LAZ through lazrs)."""
    import laspy
    import numpy as np

    points = np.frombuffer(scan, dtype="<f4").reshape(-1, 4)
    files = {}
    for name in ["scan.las", "scan.laz"]:
        header = laspy.LasHeader(point_format=3, version="1.2")
        header.scales = np.array([0.001, 0.001, 0.001])
        las = laspy.LasData(header)
        las.x, las.y, las.z = (points[:, k].astype(np.float64) for k in range(3))
        las.intensity = (points[:, 3] * 65535).astype(np.uint16)
        las.write(out / name)
        files[name] = (out / name).read_bytes()
    return files


def first_message_per_topic(path: pathlib.Path) -> dict:
    with path.open("rb") as f:
        found = {}
        for _, channel, message in make_reader(f).iter_messages():
            found.setdefault(channel.topic, message.data)
        return found


def packet_scans(
    db: pathlib.Path, data_bytes: int = 1206, sized: bool = False, packets: int = 3, flagged: bool = False, message: int = 0, first: int = 0
) -> dict:
    """A packet message (VelodyneScan: `uint8[1206] data`; PandarScan:
    `uint8[1500] data` and `uint32 size`; RobosenseScan: `uint8 is_difop` first) of a
    rosbag2 .db3, the `message`-th, cut to `packets` from its `first`, as CDR and as ROS 1, and
    the same packets as nebula's NebulaPackets (CDR, `uint8[] data`)."""
    import sqlite3
    import struct

    rows = sqlite3.connect(db).execute("select data from messages order by timestamp").fetchall()
    buf = rows[message][0]
    at = 4 + 8
    name_len = struct.unpack_from("<I", buf, at)[0]
    at = (at + 4 + name_len + 3) & ~3
    header, frame = buf[:at], buf[16 : 16 + name_len - 1]
    at += 4
    cut = []
    for index in range(first + packets):
        at = (at + 3) & ~3
        sec, nsec = struct.unpack_from("<iI", buf, at)
        flag = buf[at + 8 : at + 8 + flagged]
        at += flagged
        data = buf[at + 8 : at + 8 + data_bytes]
        at += 8 + data_bytes
        size = b""
        if sized:
            at = (at + 3) & ~3
            size = buf[at : at + 4]
            at += 4
        if index >= first:
            cut.append((sec, nsec, flag + data, size))
    cdr = bytearray(header) + struct.pack("<I", len(cut))
    for sec, nsec, data, size in cut:
        cdr += b"\0" * ((4 - (len(cdr) - 4) % 4) % 4) + struct.pack("<iI", sec, nsec) + data
        if sized:
            cdr += b"\0" * ((4 - (len(cdr) - 4) % 4) % 4) + size
    sec, nsec = struct.unpack_from("<iI", header, 4)
    ros1 = struct.pack("<III", 0, sec, nsec) + struct.pack("<I", len(frame)) + frame + struct.pack("<I", len(cut))
    for sec, nsec, data, size in cut:
        ros1 += struct.pack("<II", sec, nsec) + data + size
    nebula = bytearray(header) + struct.pack("<I", len(cut))
    for sec, nsec, data, size in cut:
        packet = data[len(data) - data_bytes :][: struct.unpack("<I", size)[0]] if sized else data
        nebula += b"\0" * ((4 - (len(nebula) - 4) % 4) % 4) + struct.pack("<iII", sec, nsec, len(packet)) + packet
    return {"cdr": bytes(cdr), "ros1": ros1, "nebula": bytes(nebula)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--travmap", default="target/release/travmap")
    parser.add_argument("--data", default="../shared/data")
    args = parser.parse_args()
    data = pathlib.Path(args.data)
    seq = data / "semantickitti-00" / "sequences" / "00"
    seeds = pathlib.Path(__file__).parent / "seeds"
    shutil.rmtree(seeds, ignore_errors=True)

    def seed(target: str, name: str, body: bytes) -> None:
        (seeds / target).mkdir(parents=True, exist_ok=True)
        (seeds / target / name).write_bytes(body)

    seed("kitti_calib", "odometry-calib.txt", (seq / "calib.txt").read_bytes())
    seed("kitti_calib", "object-calib.txt", (data / "kitti-object-000008" / "training" / "calib" / "000008.txt").read_bytes())
    seed("kitti_poses", "poses.txt", b"\n".join((seq / "poses.txt").read_bytes().splitlines()[:3]) + b"\n")
    seed("kitti_poses", "times.txt", b"\n".join((seq / "times.txt").read_bytes().splitlines()[:5]) + b"\n")
    seed("kitti_scan", "000000.bin", (seq / "velodyne" / "000000.bin").read_bytes()[: 16 * POINTS])
    seed("kitti_labels", "000000.label", (seq / "labels" / "000000.label").read_bytes()[: 4 * POINTS])
    scan = (seq / "velodyne" / "000000.bin").read_bytes()[: 16 * POINTS]
    for name, body in pcd_files(scan).items():
        seed("pcd_file", name, body)
    for name, body in ply_files(scan).items():
        seed("ply_file", name, body)
    with tempfile.TemporaryDirectory() as tmp:
        for name, body in las_files(scan, pathlib.Path(tmp)).items():
            seed("las_file", name, body)
    nebula = pathlib.Path("fixtures/nebula")
    for name, db in [
        ("vlp32c", nebula / "vlp32/1713492677464078412/1713492677464078412_0.db3"),
        ("vlp16_dual", nebula / "vlp16/1673400471837873222/1673400471837873222_0.db3"),
    ]:
        scans = packet_scans(db)
        seed("nebula_packets", f"{name}.cdr", scans.pop("nebula"))
        for encoding, body in scans.items():
            seed("velodyne_scan", f"{name}.{encoding}", body)
    for name, db in [
        ("xt32_dual", nebula / "xt32/1673400677802009732/1673400677802009732_0.db3"),
        ("xt16_dual", nebula / "xt16/1732848127890747768/1732848127890747768_0.db3"),
        ("p40_dual", nebula / "40p/1673400149412331409/1673400149412331409_0.db3"),
        ("p64_dual", nebula / "64/1673403880599376836/1673403880599376836_0.db3"),
        ("qt64_dual", nebula / "qt64/1673401195788312575/1673401195788312575_0.db3"),
        ("xt32m_dual", nebula / "xt32m/1660893203042895158/1660893203042895158_0.db3"),
        ("qt128_dual", nebula / "qt128/1730273789074637152/1730273789074637152_0.db3"),
    ]:
        scans = packet_scans(db, 1500, sized=True)
        seed("nebula_packets", f"{name}.cdr", scans.pop("nebula"))
        for encoding, body in scans.items():
            seed("pandar_scan", f"{name}.{encoding}", body)
    # The Helios 16P's fourth message holds its DIFOP: the seed is cut around it.
    helios = nebula / "helios16p/rosbag2_2023_08_03-11_02_46/rosbag2_2023_08_03-11_02_46_0.db3"
    scans = packet_scans(helios, 1500, sized=True, packets=3, flagged=True, message=3, first=92)
    seed("nebula_packets", "helios16p.cdr", scans.pop("nebula"))
    for encoding, body in scans.items():
        seed("robosense_scan", f"helios16p.{encoding}", body)

    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        tiny_sequence(seq, tmp / "seq")
        for compression in ("none", "zstd", "lz4"):
            drive = tmp / f"drive-{compression}.mcap"
            subprocess.run(
                [args.travmap, "convert", str(tmp / "seq"), "-o", str(drive), "--compression", compression, "-q"],
                check=True,
            )
            seed("mcap_file", drive.name, drive.read_bytes())
        # Damaged files: a recorder killed before the summary, or inside a chunk, and
        # a chunk whose bytes were flipped.
        whole = (tmp / "drive-zstd.mcap").read_bytes()
        summary_start = int.from_bytes(whole[-8 - 29 + 9 : -8 - 29 + 17], "little")
        seed("mcap_file", "cut-before-summary.mcap", whole[:summary_start])
        seed("mcap_file", "cut-inside-chunk.mcap", whole[: len(whole) * 2 // 3])
        flipped = bytearray(whole)
        flipped[len(whole) // 2] ^= 0xFF
        seed("mcap_file", "corrupt-chunk.mcap", bytes(flipped))
        messages = first_message_per_topic(tmp / "drive-none.mcap")
        # The tiny drive in every other log format, by real writers (rosbags, mcap).
        routes = tmp / "routes"
        subprocess.run(
            [sys.executable, "tests/clients/ros_routes.py", str(tmp / "drive-none.mcap"), str(routes)],
            check=True,
        )
        for name in ("ros1-none.bag", "ros1-bz2.bag", "ros1-lz4.bag"):
            seed("bag_file", name, (routes / name).read_bytes())
        seed("mcap_file", "ros1.mcap", (routes / "ros1.mcap").read_bytes())
        # Foxglove's schemas in protobuf, as the Foxglove SDK writes them.
        foxglove = first_message_per_topic(routes / "foxglove.mcap")
        for topic, name in (
            ("/velodyne_points", "point_cloud"),
            ("/tf", "frame_transforms"),
            ("/camera_2/image/compressed", "compressed_image"),
            ("/camera_2/camera_info", "camera_calibration"),
        ):
            seed("foxglove_message", f"{name}.pb", foxglove[topic])
        seed("foxglove_message", "pose_in_frame.pb", first_message_per_topic(routes / "foxglove-pose.mcap")["/pose"])
        foxglove_json = first_message_per_topic(routes / "foxglove-json.mcap")
        for topic, name in (("/velodyne_points", "point_cloud"), ("/camera_2/camera_info", "camera_calibration")):
            seed("foxglove_message", f"{name}.json", foxglove_json[topic])
        for storage in ("sqlite3", "mcap"):
            metadata = (routes / f"rosbag2-{storage}" / "metadata.yaml").read_text()
            # The fuzz target's directory holds one (empty) storage file, drive_0.mcap.
            metadata = metadata.replace(f"rosbag2-{storage}.{'db3' if storage == 'sqlite3' else 'mcap'}", "drive_0.mcap")
            seed("rosbag2_metadata", f"{storage}-metadata.yaml", metadata.encode())
        # Frame 0's cells on a 6 m grid (9 rows, every column), as travmap writes them
        # (zstd) and as pyarrow rewrites them (uncompressed, dictionary-encoded).
        cells = tmp / "cells.parquet"
        subprocess.run(
            [args.travmap, "dataset", str(seq), "-o", str(cells), "--frames", "0..1",
             "--set", "training.grid_size_m=6", "--set", "features.groups=[]", "-q"],
            check=True,
        )
        seed("dataset_file", "travmap-zstd.parquet", cells.read_bytes())
        pyarrow_cells = tmp / "pyarrow.parquet"
        pq.write_table(pq.read_table(cells), pyarrow_cells, compression="none")
        seed("dataset_file", "pyarrow-uncompressed.parquet", pyarrow_cells.read_bytes())
    seed("ros_point_cloud", "velodyne_points.cdr", messages["/velodyne_points"])
    seed("ros_tf", "tf.cdr", messages["/tf"])
    seed("ros_tf", "tf_static.cdr", messages["/tf_static"])
    seed("ros_camera_info", "camera_info.cdr", messages["/camera_2/camera_info"])
    seed("ros_image", "compressed_png.cdr", messages["/camera_2/image/compressed"])
    ros2 = get_typestore(Stores.ROS2_HUMBLE)
    for topic, msgtype, name in (
        ("/velodyne_points", "sensor_msgs/msg/PointCloud2", "point_cloud2"),
        ("/tf", "tf2_msgs/msg/TFMessage", "tf"),
        ("/camera_2/camera_info", "sensor_msgs/msg/CameraInfo", "camera_info"),
    ):
        seed("ros1_message", f"{name}.ros1", bytes(ros2.cdr_to_ros1(messages[topic], msgtype)))

    # Messages of other writers (rosbags-rs), in layouts travmap does not write itself.
    others = first_message_per_topic(data / "mcap" / "rosbags_rs_all_std_types.mcap")
    seed("ros_point_cloud", "rosbags_point_cloud2.cdr", others["/test/sensor_msgs/point_cloud2"])
    seed("ros_image", "rosbags_image.cdr", others["/test/sensor_msgs/image"])
    seed("ros_image", "rosbags_compressed_image.cdr", others["/test/sensor_msgs/compressed_image"])
    seed("ros_camera_info", "rosbags_camera_info.cdr", others["/test/sensor_msgs/camera_info"])
    seed("ros_tf", "rosbags_tf.cdr", others["/test/tf2_msgs/tf_message"])
    seed("ros_tf", "rosbags_odometry.cdr", others["/test/nav_msgs/odometry"])
    seed("ros_tf", "rosbags_pose_stamped.cdr", others["/test/geometry_msgs/pose_stamped"])
    seed(
        "ros_tf",
        "rosbags_pose_with_covariance_stamped.cdr",
        others["/test/geometry_msgs/pose_with_covariance_stamped"],
    )

    # The embedded model cut to three support vectors and three reduced-set centres:
    # the whole structure, small enough to mutate quickly.
    model = json.loads(pathlib.Path("crates/method/src/classifier/default_model.json").read_text())

    def cut(m: dict) -> None:
        m["dual_coefficients"] = m["dual_coefficients"][:3]
        m["support_vectors"] = m["support_vectors"][:3]
        m["training"]["search"] = m["training"]["search"][:1]
        m["reduced_set"]["centres"] = m["reduced_set"]["centres"][:3]
        m["reduced_set"]["weights"] = m["reduced_set"]["weights"][:3]

    cut(model)
    if model.get("fallback"):
        cut(model["fallback"])
    seed("model", "small_model.json", json.dumps(model, indent=1).encode())

    for target in sorted(p.name for p in seeds.iterdir()):
        files = list((seeds / target).iterdir())
        print(f"{target}: {len(files)} seeds, {sum(f.stat().st_size for f in files)} bytes")


if __name__ == "__main__":
    main()
