"""Writes Ouster lidar packets with Ouster's own SDK (ouster-sdk, `frame_to_packets`),
recorded as ouster_ros records them, and the points the SDK makes of them (its
`XYZLut`), for tests/ouster.rs to decode and compare.

The scene is RELLIS-3D's real OS1-64 scan (../shared/data/rellis3d-000104: 2,048
columns of 64 beams, column by column, as the sensor sent them, in the lidar frame):
each return's range from its beam's origin, in an OS1-64 at 2048x10 with the SDK's
default beam angles (a beam's default direction is within 0.32 degrees of the
scan's return, median). Reflectivity is the .bin's intensity (0..1, as travmap
reads it; RELLIS-3D stored uint16 counts / 65536, so nearly all 0) times 255. Three frames of the
same scan (frame ids 100-102), the sensor's clock since boot (5 s at the first
column), each packet recorded when its last column was measured, 100 ms apart, on
a vehicle moving 0.5 m along x per frame (/tf: map -> os_sensor at each scan's
first column).

  ouster-PROFILE/        rosbags' rosbag2 writer (sqlite3), for PROFILE in LEGACY,
                         RNG19_RFL8_SIG16_NIR16, RNG19_RFL8_SIG16_NIR16_DUAL (the
                         second return 0.5 m behind the first on every fourth beam),
                         RNG15_RFL8_NIR8: /ouster/lidar_packets and /ouster/imu_packets
                         (ouster_sensor_msgs/msg/PacketMsg, `uint8[] buf`; 48-byte IMU
                         packets every 10 ms), /ouster/metadata (std_msgs/msg/String,
                         the SDK's sensor_info JSON, first), /tf
  ouster-legacy.bag      rosbags' ROS 1 bag writer, the LEGACY route as ouster_ros 1
                         records it (ouster_ros/PacketMsg)
  ouster-late-metadata/  the RNG19 route with its metadata recorded after the first
                         frame's packets
  ouster-no-metadata/    the RNG19 route without its metadata topic
  ouster-points/         the RNG19 route's frames as ouster_ros publishes them: organised
                         PointCloud2s on /ouster/points (64 x 2048, destaggered, a beam
                         without a return at the origin) of its point layout (x, y, z,
                         intensity float32 = a photon count, t uint32, reflectivity,
                         ring, ambient uint16, range uint32; 48-byte points), the SDK's
                         points, stamped with each frame's first column, and /tf
  ouster-mid-turn/       the RNG19 route recorded from its first frame's 81st packet on
                         (the recording began mid-turn: frame 100 is 48 of its 128 packets)
  RNG19_RFL8_SIG16_NIR16.pcap
                         the RNG19 route's lidar packets as the SDK's pcap writer records
                         them (`ouster.sdk.pcap.record`: Ethernet, IPv4 fragments, UDP port
                         7502), each stamped with its log time
  ouster-two/            two sensors' packets, the RNG19 route's, in namespaces /front and
                         /rear (each with its metadata), their frames front/os_sensor
                         and rear/os_sensor mounted on /tf_static on a base_link (1 m
                         forward; 1 m back, turned half a turn) that /tf moves
  ouster-two-points/     the same two sensors as ouster_ros clouds (/front/points,
                         /rear/points)
  PROFILE.json           the metadata alone (for --lidar-calibration)
  PROFILE.seed           the fuzz target ouster_packets' input (fuzz/seeds/ouster_packets/):
                         the metadata's length (u16), the metadata, a frame's first two packets
  fixture/               with --fixture, only fixtures/ouster/ (see fixtures/README.md): the
                         RNG19 route at 1024x10 (RELLIS-3D's every other column) and its
                         points, as above
  PROFILE.points         the SDK's points of one frame, float32 x, y, z (metres, sensor
                         frame) and reflectivity, column by column (in the order the
                         packets carry them), beam by beam, each pixel's first return
                         then a second one 0.1 m or more from it, returns of range 0 left out

usage: python ouster_packets.py RELLIS_BIN OUT_DIR [--fixture]
"""
import json
import sys
from pathlib import Path

import numpy as np
import ouster.sdk.core as core
import ouster.sdk.pcap as pcap
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag2 import Writer as Ros2Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

FRAMES = 3
FIRST_FRAME_ID = 100
PERIOD_NS = 100_000_000
SENSOR_START_NS = 5_000_000_000
LOG_START_NS = 1_700_000_000_000_000_000
PROFILES = [
    "LEGACY",
    "RNG19_RFL8_SIG16_NIR16",
    "RNG19_RFL8_SIG16_NIR16_DUAL",
    "RNG15_RFL8_NIR8",
    "RNG15_RFL8_NIR8_DUAL",
    "FUSA_RNG15_RFL8_NIR8_DUAL",
]


def scene(bin_path, info, lut):
    """RELLIS-3D's scan as staggered range (mm) and reflectivity images (at 1024
    columns a turn, every other column: the same encoder angles)."""
    points = np.fromfile(bin_path, dtype=np.float32).reshape(2048, 64, 4)
    points = points[:: 2048 // info.format.columns_per_frame]
    xyz = np.ascontiguousarray(points[:, :, :3].transpose(1, 0, 2)).astype(np.float64)
    returned = np.abs(xyz).sum(axis=2) > 0
    # RELLIS-3D's clouds are in the lidar frame (measurement id 0 along +x); the
    # SDK's points in the sensor frame, half a turn about z from it.
    lidar_to_sensor = np.asarray(info.lidar_to_sensor_transform)
    xyz = xyz @ lidar_to_sensor[:3, :3].T + lidar_to_sensor[:3, 3] / 1000
    staggered = xyz
    h, w = info.format.pixels_per_column, info.format.columns_per_frame
    origin = lut.offset.reshape(h, w, 3)
    direction = lut.direction.reshape(h, w, 3) * 1000  # per millimetre of range
    ray = staggered - origin
    range_m = np.linalg.norm(ray, axis=2)
    cos = (ray * direction).sum(axis=2) / np.maximum(range_m, 1e-9)
    # The default beam angles are not this sensor's calibration, but a beam's ray
    # points within a fraction of a degree of where the scan saw its return.
    off_deg = np.degrees(np.arccos(np.clip(cos[returned], -1, 1)))
    assert np.median(off_deg) < 1.5, f"not the sensor's columns: median {np.median(off_deg):.2f} degrees off"
    range_mm = np.where(returned, np.round(range_m * 1000), 0).astype(np.uint32)
    # The .bin's intensity on the 0..1 scale, as a byte: the remission travmap reads
    # from these packets is what it reads from the .bin, to the byte.
    reflectivity = np.clip(np.round(points[:, :, 3].T * 255), 0, 255).astype(np.uint8)
    return range_mm, reflectivity


def frames(info, range_mm, reflectivity, profile):
    """Each frame's packets, with the times they were recorded at."""
    fmt = core.PacketFormat.from_info(info)
    h, w = info.format.pixels_per_column, info.format.columns_per_frame
    out = []
    for k in range(FRAMES):
        frame = core.LidarFrame(info)
        frame.field("RANGE")[:] = range_mm & fmt.field_value_mask("RANGE")
        frame.field("REFLECTIVITY")[:] = reflectivity
        if "RANGE2" in [str(f) for f in frame.fields]:
            second = np.where(np.arange(h)[:, None] % 4 == 0, range_mm + 500, 0) * (range_mm > 0)
            frame.field("RANGE2")[:] = second & fmt.field_value_mask("RANGE2")
            frame.field("REFLECTIVITY2")[:] = reflectivity // 2
        frame.timestamp[:] = SENSOR_START_NS + k * PERIOD_NS + np.arange(w) * PERIOD_NS // w
        frame.measurement_id[:] = np.arange(w)
        frame.status[:] = 0xFFFFFFFF if profile == "LEGACY" else 1
        frame.frame_id = FIRST_FRAME_ID + k
        packets = [p for p in core.frame_to_packets(frame, fmt, 0, 0) if isinstance(p, core.LidarPacket)]
        columns = info.format.columns_per_packet
        for n, packet in enumerate(packets):
            last_column_ns = SENSOR_START_NS + k * PERIOD_NS + ((n + 1) * columns - 1) * PERIOD_NS // w
            out.append((LOG_START_NS - SENSOR_START_NS + last_column_ns, bytes(packet.buf)))
        if k == 0:
            points = oracle(info, frame, fmt)
    return out, points


def oracle(info, frame, fmt):
    """The SDK's points of a frame, in the order the packets carry them."""
    lut = core.XYZLut(info)
    first = frame.field("RANGE").astype(np.int64)
    xyz = lut(frame.field("RANGE"))
    reflectivity = frame.field("REFLECTIVITY").astype(np.float32)
    has_second = "RANGE2" in [str(f) for f in frame.fields]
    if has_second:
        second = frame.field("RANGE2").astype(np.int64)
        xyz2 = lut(frame.field("RANGE2"))
        reflectivity2 = frame.field("REFLECTIVITY2").astype(np.float32)
    rows = []
    h, w = first.shape
    for j in range(w):
        for i in range(h):
            if first[i, j] != 0:
                rows.append([*xyz[i, j], reflectivity[i, j]])
            if has_second and second[i, j] != 0 and abs(second[i, j] - first[i, j]) >= 100:
                rows.append([*xyz2[i, j], reflectivity2[i, j]])
    return np.asarray(rows, dtype=np.float32)


ONE_SENSOR = [("/ouster", "os_sensor", None)]
# Two sensors on a vehicle's base_link: one 1 m forward, one 1 m back turned half a turn.
TWO_SENSORS = [("/front", "front/os_sensor", (1.0, 0.0)), ("/rear", "rear/os_sensor", (-1.0, np.pi))]


def messages(info, packets, with_metadata=True, metadata_after=0, sensors=ONE_SENSOR):
    """(topic, log time, kind, payload) in time order."""
    out = []
    for namespace, frame, mount in sensors:
        out += [(f"{namespace}/lidar_packets", t, "packet", p) for t, p in packets]
        end = packets[-1][0]
        out += [(f"{namespace}/imu_packets", t, "packet", bytes(48)) for t in range(LOG_START_NS, end, 10_000_000)]
        if with_metadata:
            out.append((f"{namespace}/metadata", LOG_START_NS - 1 + metadata_after, "metadata", info.to_json_string()))
        if mount is not None:
            out.append(("/tf_static", LOG_START_NS - 1, "mount", (frame, mount)))
    moving = "os_sensor" if sensors == ONE_SENSOR else "base_link"
    for k in range(FRAMES):
        out.append(("/tf", LOG_START_NS + k * PERIOD_NS, "tf", (moving, k)))
    return sorted(out, key=lambda m: (m[1], m[0]))


def write_pcap(path, info, packets):
    """The packets as the SDK records a sensor's stream."""
    fmt = core.PacketFormat.from_info(info)
    recorded = []
    for t, data in packets:
        packet = core.LidarPacket(fmt)
        packet.buf[:] = np.frombuffer(data, dtype=np.uint8)
        packet.host_timestamp = t
        recorded.append(packet)
    pcap.record(recorded, str(path))


def write_points(path, info, range_mm, reflectivity, sensors=ONE_SENSOR):
    """The frames as ouster_ros's organised clouds of the SDK's points."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    h, w = info.format.pixels_per_column, info.format.columns_per_frame
    xyz = core.XYZLut(info)(range_mm)
    layout = np.dtype(
        {
            "names": ["x", "y", "z", "intensity", "t", "reflectivity", "ring", "ambient", "range"],
            "formats": ["<f4", "<f4", "<f4", "<f4", "<u4", "<u2", "<u2", "<u2", "<u4"],
            "offsets": [0, 4, 8, 16, 20, 24, 26, 28, 32],
            "itemsize": 48,
        }
    )
    points = np.zeros((h, w), dtype=layout)
    for k, name in enumerate("xyz"):
        points[name] = xyz[:, :, k]
    points["intensity"] = 1000.0 + 10.0 * reflectivity  # photons: never the 0..255 scale
    points["t"] = np.arange(w)[None, :] * PERIOD_NS // w
    points["reflectivity"] = reflectivity
    points["ring"] = np.arange(h)[:, None]
    points["range"] = range_mm
    points = np.ascontiguousarray(core.destagger(info, points.view(np.uint8).reshape(h, w, 48)))
    datatypes = {"<f4": 7, "<u4": 6, "<u2": 4}
    PointField = store.types["sensor_msgs/msg/PointField"]
    fields = [
        PointField(name=n, offset=layout.fields[n][1], datatype=datatypes[layout.fields[n][0].str], count=1)
        for n in layout.names
    ]
    PointCloud2 = store.types["sensor_msgs/msg/PointCloud2"]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    with Ros2Writer(path) as writer:
        tf = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=store)
        if sensors != ONE_SENSOR:
            tf_static = writer.add_connection("/tf_static", "tf2_msgs/msg/TFMessage", typestore=store)
            for _, frame, (x, yaw) in sensors:
                mount = transform(store, 0, frame, "base_link", x, yaw)
                writer.write(tf_static, LOG_START_NS - 1, store.serialize_cdr(mount, "tf2_msgs/msg/TFMessage"))
        clouds = {
            frame: writer.add_connection(f"{namespace}/points", "sensor_msgs/msg/PointCloud2", typestore=store)
            for namespace, frame, _ in sensors
        }
        moving = "os_sensor" if sensors == ONE_SENSOR else "base_link"
        for k in range(FRAMES):
            ns = LOG_START_NS + k * PERIOD_NS
            writer.write(tf, ns, store.serialize_cdr(transform(store, k, moving), "tf2_msgs/msg/TFMessage"))
            stamp = Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
            for frame, connection in clouds.items():
                cloud = PointCloud2(
                    header=Header(stamp=stamp, frame_id=frame),
                    height=h,
                    width=w,
                    fields=fields,
                    is_bigendian=False,
                    point_step=48,
                    row_step=48 * w,
                    data=points.reshape(-1),
                    is_dense=False,
                )
                writer.write(connection, ns + PERIOD_NS, store.serialize_cdr(cloud, "sensor_msgs/msg/PointCloud2"))


def transform(store, k, child="os_sensor", parent="map", x=None, yaw=0.0):
    """A transform at frame k's time: by default the vehicle 0.5 m further along x."""
    ns = LOG_START_NS + k * PERIOD_NS
    types = store.types
    stamp = types["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
    header = types["std_msgs/msg/Header"]
    header = header(stamp=stamp, frame_id=parent) if "seq" not in header.__dataclass_fields__ else header(seq=0, stamp=stamp, frame_id=parent)
    t = types["geometry_msgs/msg/Transform"](
        translation=types["geometry_msgs/msg/Vector3"](x=0.5 * k if x is None else x, y=0.0, z=0.0),
        rotation=types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=np.sin(yaw / 2), w=np.cos(yaw / 2)),
    )
    stamped = types["geometry_msgs/msg/TransformStamped"](header=header, child_frame_id=child, transform=t)
    return types["tf2_msgs/msg/TFMessage"](transforms=[stamped])


def write(writer_kind, path, info, packets, **kwargs):
    if writer_kind == "ros2":
        store = get_typestore(Stores.ROS2_HUMBLE)
        packet_type = "ouster_sensor_msgs/msg/PacketMsg"
    else:
        store = get_typestore(Stores.ROS1_NOETIC)
        packet_type = "ouster_ros/msg/PacketMsg"
    store.register(get_types_from_msg("uint8[] buf", packet_type))
    if "tf2_msgs/msg/TFMessage" not in store.types:
        store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    PacketMsg = store.types[packet_type]
    String = store.types["std_msgs/msg/String"]
    tf = "tf2_msgs/msg/TFMessage"
    types = {"packet": packet_type, "metadata": "std_msgs/msg/String", "tf": tf, "mount": tf}

    def message(kind, payload):
        if kind == "packet":
            return PacketMsg(buf=np.frombuffer(payload, dtype=np.uint8))
        if kind == "metadata":
            return String(data=payload)
        if kind == "mount":
            frame, (x, yaw) = payload
            return transform(store, 0, frame, "base_link", x, yaw)
        child, k = payload
        return transform(store, k, child)

    serialize = store.serialize_cdr if writer_kind == "ros2" else store.serialize_ros1
    Writer = Ros2Writer if writer_kind == "ros2" else Ros1Writer
    connections = {}
    with Writer(path) as writer:
        for topic, t, kind, payload in messages(info, packets, **kwargs):
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, types[kind], typestore=store)
            writer.write(connections[topic], t, serialize(message(kind, payload), types[kind]))


def fixture(bin_path, out):
    info = core.SensorInfo.from_default(core.LidarMode._1024x10)
    info.format.udp_profile_lidar = core.UDPProfileLidar.RNG19_RFL8_SIG16_NIR16
    range_mm, reflectivity = scene(bin_path, info, core.XYZLut(info))
    packets, points = frames(info, range_mm, reflectivity, "RNG19_RFL8_SIG16_NIR16")
    points.tofile(out / "os1-64-1024x10.points")
    write("ros2", out / "os1-64-1024x10", info, packets)
    print(len(packets), "packets of", len(packets[0][1]), "bytes;", len(points), "points in a frame")


def main():
    bin_path, out = Path(sys.argv[1]), Path(sys.argv[2])
    out.mkdir(parents=True, exist_ok=True)
    if sys.argv[3:] == ["--fixture"]:
        return fixture(bin_path, out)
    for profile in PROFILES:
        info = core.SensorInfo.from_default(core.LidarMode._2048x10)
        info.format.udp_profile_lidar = getattr(core.UDPProfileLidar, profile)
        if profile.startswith("FUSA"):
            # The functional-safety packets: a header with a 32-bit frame id.
            info.format.header_type = core.HeaderType.FUSA
        range_mm, reflectivity = scene(bin_path, info, core.XYZLut(info))
        packets, points = frames(info, range_mm, reflectivity, profile)
        metadata = info.to_json_string().encode()
        (out / f"{profile}.json").write_bytes(metadata)
        seed = len(metadata).to_bytes(2, "little") + metadata + packets[0][1] + packets[1][1]
        (out / f"{profile}.seed").write_bytes(seed)
        points.tofile(out / f"{profile}.points")
        write("ros2", out / f"ouster-{profile}", info, packets)
        if profile == "LEGACY":
            write("ros1", out / "ouster-legacy.bag", info, packets)
        if profile == "RNG19_RFL8_SIG16_NIR16":
            write("ros2", out / "ouster-late-metadata", info, packets, metadata_after=PERIOD_NS + 1)
            write("ros2", out / "ouster-no-metadata", info, packets, with_metadata=False)
            write_points(out / "ouster-points", info, range_mm, reflectivity)
            write_pcap(out / f"{profile}.pcap", info, packets)
            write("ros2", out / "ouster-mid-turn", info, packets[80:])
            write("ros2", out / "ouster-two", info, packets, sensors=TWO_SENSORS)
            write_points(out / "ouster-two-points", info, range_mm, reflectivity, sensors=TWO_SENSORS)
        print(profile, len(packets), "packets of", len(packets[0][1]), "bytes;", len(points), "points in a frame")


if __name__ == "__main__":
    main()
