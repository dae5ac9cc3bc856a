"""Writes one ROS 2 MCAP drive (as `travmap convert` makes it) again in every other
recorded-log format travmap reads, with real writers and no travmap code:

  ros1-none.bag, ros1-bz2.bag, ros1-lz4.bag  rosbags' ROS 1 bag writer (chunk compression)
  ros1.mcap                                  Python mcap's writer, ros1msg schemas, ros1 messages
  rosbag2-sqlite3/, rosbag2-mcap/            rosbags' rosbag2 writer (storage plugins)
  rosbag2-sqlite3-zstd/, rosbag2-mcap-zstd/  the same, each message zstd-compressed (message mode)
  rosbag2-sqlite3-zstd-file/, rosbag2-mcap-zstd-file/
                                             the same, each storage file zstd-compressed (file mode)
  rosbag2-from-bag/                          rosbags-convert of ros1-none.bag (ROS 1 -> ROS 2)
  rosbag2-mcap-livox/                        rosbags' rosbag2 writer, every cloud as a Livox
                                             livox_ros_driver2/msg/CustomMsg (reflectivity = the
                                             intensity x 255, rounded)
  rosbag2-mcap-uint8/                        the same points as PointCloud2s with that reflectivity
                                             as a uint8 intensity (what the Livox route must read as)
  ros1-livox.bag                             rosbags' ROS 1 bag writer, the Livox route's clouds as
                                             ROS 1's livox_ros_driver/CustomMsg (FAST-LIO's bags)
  rosbag2-mcap-jpeg/                         rosbags' rosbag2 writer, every camera image made
                                             a JPEG (Pillow, quality 90) named as image_transport
                                             names it, `rgb8; jpeg compressed bgr8`
  rosbag2-mcap-pose/                         rosbags' rosbag2 writer, the drive as a localisation
                                             records it: no moving /tf, the pose of the vehicle's
                                             base_link (the LiDAR mounted on it on /tf_static) as
                                             a PoseStamped on /pose, naming no child frame
  ros1-pose.bag                              rosbags' ROS 1 bag writer, the same poses as
                                             PoseWithCovarianceStamped (as amcl_pose is)
  rosbag2-mcap-two-poses/                    rosbag2-mcap-pose/ with a second PoseStamped topic,
                                             /vision_pose (the poses 5 m off, in `odom`)
  rosbag2-mcap-poses-and-tf/                 the drive as recorded (its moving /tf), and both
                                             pose topics
  foxglove.mcap                              the Foxglove SDK's MCAP writer, every message of a
                                             type Foxglove has a schema for as that schema in
                                             protobuf (PointCloud, FrameTransforms, CompressedImage,
                                             CameraCalibration), as nuScenes' MCAPs are written
  foxglove-pose.mcap                         the Foxglove SDK's writer, rosbag2-mcap-pose/'s messages:
                                             the vehicle's pose as a foxglove.PoseInFrame on /pose
  foxglove-nuscenes.mcap                     the Foxglove SDK's writer, laid out as nuScenes' MCAPs
                                             are: the LiDAR in `lidar_top` on a vehicle `base_link`,
                                             each mount on /tf (not /tf_static) at a few key frames
                                             only, and a radar's small clouds beside it
  foxglove-json.mcap                         Python mcap's writer, the same schemas in JSON (json
                                             messages, jsonschema schemas, bytes in base64), as the
                                             MCAP examples write them

Messages become ROS 1 with rosbags' CDR -> ROS 1 conversion (which adds the Header's
seq); ROS 1 message definitions and md5sums come from rosbags' Noetic type store.
Every route also carries a `/chatter` std_msgs String per cloud, a type travmap does
not read, to check that it is copied as recorded.

usage: python ros_routes.py DRIVE.mcap OUT_DIR [ROSBAGS_CONVERT]
"""
import io
import subprocess
import sys
from pathlib import Path

from PIL import Image

import numpy as np
from mcap.reader import make_reader
from mcap.writer import Writer as McapWriter
from rosbags.rosbag1 import Writer as Bag1Writer
from rosbags.rosbag2 import Writer as Bag2Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode, StoragePlugin
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

ROS2 = get_typestore(Stores.ROS2_HUMBLE)
ROS1 = get_typestore(Stores.ROS1_NOETIC)
# Noetic's store lacks tf2_msgs; its TFMessage is one field over the Noetic types.
ROS1.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
CHATTER = "std_msgs/msg/String"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"


def recorded(path):
    """(topic, ROS 2 type, log time, CDR bytes) of every message, plus a /chatter
    String after every PointCloud2."""
    out = []
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            out.append((channel.topic, schema.name, message.log_time, bytes(message.data)))
            if schema.name == "sensor_msgs/msg/PointCloud2":
                text = ROS2.types[CHATTER](data=f"cloud at {message.log_time}")
                out.append(("/chatter", CHATTER, message.log_time, bytes(ROS2.serialize_cdr(text, CHATTER))))
    return out


def ros1_bag(messages, path, compression):
    writer = Bag1Writer(path)
    if compression:
        writer.set_compression(compression)
    with writer:
        connections = {}
        for topic, msgtype, stamp, cdr in messages:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=ROS1)
            writer.write(connections[topic], stamp, bytes(ROS2.cdr_to_ros1(cdr, msgtype)))


def ros1_mcap(messages, path):
    with open(path, "wb") as f:
        writer = McapWriter(f)
        writer.start(profile="ros1", library="ros_routes.py")
        channels = {}
        for topic, msgtype, stamp, cdr in messages:
            if topic not in channels:
                definition, md5sum = ROS1.generate_msgdef(msgtype)
                schema = writer.register_schema(
                    name=msgtype.replace("/msg/", "/"), encoding="ros1msg", data=definition.encode()
                )
                channels[topic] = writer.register_channel(
                    topic=topic, message_encoding="ros1", schema_id=schema, metadata={"md5sum": md5sum}
                )
            data = bytes(ROS2.cdr_to_ros1(cdr, msgtype))
            writer.add_message(channel_id=channels[topic], log_time=stamp, publish_time=stamp, data=data)
        writer.finish()


def rosbag2(messages, path, storage, compression=None):
    writer = Bag2Writer(path, version=9, storage_plugin=storage)
    if compression:
        writer.set_compression(compression, CompressionFormat.ZSTD)
    with writer:
        connections = {}
        for topic, msgtype, stamp, cdr in messages:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=ROS2)
            writer.write(connections[topic], stamp, cdr)


LIVOX = "livox_ros_driver2/msg/CustomMsg"
# ROS 1's driver (livox_ros_driver, FAST-LIO's bags) has the same fields.
LIVOX1 = "livox_ros_driver/msg/CustomMsg"
for store in (ROS2, ROS1):
    for package in ("livox_ros_driver2", "livox_ros_driver"):
        store.register(
            get_types_from_msg(
                "uint32 offset_time\nfloat32 x\nfloat32 y\nfloat32 z\nuint8 reflectivity\nuint8 tag\nuint8 line",
                f"{package}/msg/CustomPoint",
            )
        )
        store.register(
            get_types_from_msg(
                "std_msgs/Header header\nuint64 timebase\nuint32 point_num\nuint8 lidar_id\nuint8[3] rsvd\n"
                f"{package}/CustomPoint[] points",
                f"{package}/msg/CustomMsg",
            )
        )


def cloud_rows(cloud):
    """(x, y, z, reflectivity) of a PointCloud2 as travmap convert writes it (x, y, z,
    intensity float32)."""
    rows = np.frombuffer(bytes(cloud.data), dtype="<f4").reshape(-1, cloud.point_step // 4)
    reflectivity = np.clip(np.rint(rows[:, 3] * 255.0), 0, 255).astype(np.uint8)
    return rows[:, :3], reflectivity


def as_livox(messages, livox):
    """`messages` with every PointCloud2 a Livox CustomMsg (`livox`), or a PointCloud2 of
    the same points with a uint8 intensity."""
    out = []
    point = ROS2.types["livox_ros_driver2/msg/CustomPoint"]
    for topic, msgtype, stamp, cdr in messages:
        if msgtype == "sensor_msgs/msg/PointCloud2":
            cloud = ROS2.deserialize_cdr(cdr, msgtype)
            xyz, reflectivity = cloud_rows(cloud)
            if livox:
                points = [
                    point(offset_time=0, x=float(p[0]), y=float(p[1]), z=float(p[2]), reflectivity=int(r), tag=0, line=0)
                    for p, r in zip(xyz, reflectivity)
                ]
                stamp_ns = cloud.header.stamp.sec * 1_000_000_000 + cloud.header.stamp.nanosec
                message = ROS2.types[LIVOX](
                    header=cloud.header, timebase=stamp_ns, point_num=len(points), lidar_id=0,
                    rsvd=np.zeros(3, dtype=np.uint8), points=points,
                )
                out.append((topic, LIVOX, stamp, bytes(ROS2.serialize_cdr(message, LIVOX))))
                continue
            rows = np.zeros(len(xyz), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "u1")])
            rows["x"], rows["y"], rows["z"], rows["intensity"] = xyz[:, 0], xyz[:, 1], xyz[:, 2], reflectivity
            field = ROS2.types["sensor_msgs/msg/PointField"]
            cloud.fields = [
                field(name="x", offset=0, datatype=7, count=1), field(name="y", offset=4, datatype=7, count=1),
                field(name="z", offset=8, datatype=7, count=1), field(name="intensity", offset=12, datatype=2, count=1),
            ]
            cloud.point_step, cloud.row_step = 13, 13 * len(rows) // max(cloud.height, 1)
            cloud.data = np.frombuffer(rows.tobytes(), dtype=np.uint8)
            cdr = bytes(ROS2.serialize_cdr(cloud, msgtype))
        out.append((topic, msgtype, stamp, cdr))
    return out


def as_jpeg(messages):
    """`messages` with every CompressedImage's PNG re-encoded as a JPEG."""
    out = []
    for topic, msgtype, stamp, cdr in messages:
        if msgtype == COMPRESSED_IMAGE:
            image = ROS2.deserialize_cdr(cdr, msgtype)
            jpeg = io.BytesIO()
            Image.open(io.BytesIO(bytes(image.data))).convert("RGB").save(jpeg, "JPEG", quality=90)
            image.format = "rgb8; jpeg compressed bgr8"
            image.data = np.frombuffer(jpeg.getvalue(), dtype=np.uint8)
            cdr = bytes(ROS2.serialize_cdr(image, msgtype))
        out.append((topic, msgtype, stamp, cdr))
    return out


def foxglove_types():
    """ROS datatype -> the Foxglove SDK's numeric type (numbered differently)."""
    from foxglove.messages import PackedElementFieldNumericType as T

    return {1: T.Int8, 2: T.Uint8, 3: T.Int16, 4: T.Uint16, 5: T.Int32, 6: T.Uint32, 7: T.Float32, 8: T.Float64}


def as_foxglove(messages, path):
    """`messages` written by the Foxglove SDK as Foxglove's schemas, on the same topics
    and log times; types without a Foxglove schema (/chatter) are left out."""
    import foxglove
    from foxglove import messages as fg

    types = foxglove_types()

    def stamp(header):
        return fg.Timestamp(sec=header.stamp.sec, nsec=header.stamp.nanosec)

    def transform(t):
        v, q = t.transform.translation, t.transform.rotation
        return fg.FrameTransform(
            timestamp=stamp(t.header), parent_frame_id=t.header.frame_id, child_frame_id=t.child_frame_id,
            translation=fg.Vector3(x=v.x, y=v.y, z=v.z), rotation=fg.Quaternion(x=q.x, y=q.y, z=q.z, w=q.w),
        )

    # foxglove.log makes each topic's channel typed by its first message's schema.
    with foxglove.open_mcap(str(path), allow_overwrite=True):
        for topic, msgtype, log_time, cdr in messages:
            if msgtype == CHATTER:
                continue
            m = ROS2.deserialize_cdr(cdr, msgtype)
            if msgtype == "sensor_msgs/msg/PointCloud2":
                message = fg.PointCloud(
                    timestamp=stamp(m.header), frame_id=m.header.frame_id, point_stride=m.point_step,
                    fields=[fg.PackedElementField(name=f.name, offset=f.offset, type=types[f.datatype]) for f in m.fields],
                    data=bytes(m.data),
                )
            elif msgtype == "tf2_msgs/msg/TFMessage":
                message = fg.FrameTransforms(transforms=[transform(t) for t in m.transforms])
            elif msgtype == COMPRESSED_IMAGE:
                message = fg.CompressedImage(
                    timestamp=stamp(m.header), frame_id=m.header.frame_id, data=bytes(m.data), format=m.format,
                )
            elif msgtype == "sensor_msgs/msg/CameraInfo":
                message = fg.CameraCalibration(
                    timestamp=stamp(m.header), frame_id=m.header.frame_id, width=m.width, height=m.height,
                    distortion_model=m.distortion_model, D=list(m.d), K=list(m.k), R=list(m.r), P=list(m.p),
                )
            elif msgtype == POSE_STAMPED:
                p, q = m.pose.position, m.pose.orientation
                message = fg.PoseInFrame(
                    timestamp=stamp(m.header), frame_id=m.header.frame_id,
                    pose=fg.Pose(position=fg.Vector3(x=p.x, y=p.y, z=p.z), orientation=fg.Quaternion(x=q.x, y=q.y, z=q.z, w=q.w)),
                )
            else:
                raise SystemExit(f"{topic}: no Foxglove schema for {msgtype}")
            foxglove.log(topic, message, log_time=log_time)


def as_nuscenes_like(messages, path):
    """`messages`' clouds and poses as nuScenes' MCAPs hold theirs: map -> base_link
    per cloud, base_link -> lidar_top and -> radar_front (identity mounts) on /tf at
    the second and fourth clouds only, /lidar_top and a 4-point /radar_front cloud."""
    import foxglove
    from foxglove import messages as fg

    types = foxglove_types()

    def stamp(header):
        return fg.Timestamp(sec=header.stamp.sec, nsec=header.stamp.nanosec)

    def transform(timestamp, parent, child, v=None, q=None):
        return fg.FrameTransform(
            timestamp=timestamp, parent_frame_id=parent, child_frame_id=child,
            translation=fg.Vector3(x=v.x, y=v.y, z=v.z) if v else fg.Vector3(x=0, y=0, z=0),
            rotation=fg.Quaternion(x=q.x, y=q.y, z=q.z, w=q.w) if q else fg.Quaternion(x=0, y=0, z=0, w=1),
        )

    def cloud(header, frame, m):
        return fg.PointCloud(
            timestamp=stamp(header), frame_id=frame, point_stride=m.point_step,
            fields=[fg.PackedElementField(name=f.name, offset=f.offset, type=types[f.datatype]) for f in m.fields],
            data=bytes(m.data),
        )

    # A context of its own: /tf carries single FrameTransforms here, as in nuScenes.
    from foxglove.channels import FrameTransformChannel, PointCloudChannel

    context = foxglove.Context()
    tf = FrameTransformChannel("/tf", context=context)
    lidar = PointCloudChannel("/lidar_top", context=context)
    radar = PointCloudChannel("/radar_front", context=context)
    clouds = 0
    with foxglove.open_mcap(str(path), allow_overwrite=True, context=context):
        for topic, msgtype, log_time, cdr in messages:
            if topic == "/tf":
                for t in ROS2.deserialize_cdr(cdr, msgtype).transforms:
                    v, q = t.transform.translation, t.transform.rotation
                    tf.log(transform(stamp(t.header), "map", "base_link", v, q), log_time=log_time)
            elif msgtype == "sensor_msgs/msg/PointCloud2":
                m = ROS2.deserialize_cdr(cdr, msgtype)
                if clouds in (1, 3):
                    for mount in ("lidar_top", "radar_front"):
                        tf.log(transform(stamp(m.header), "base_link", mount), log_time=log_time)
                lidar.log(cloud(m.header, "lidar_top", m), log_time=log_time)
                few = ROS2.deserialize_cdr(cdr, msgtype)
                few.data = few.data[: 4 * few.point_step]
                radar.log(cloud(m.header, "radar_front", few), log_time=log_time)
                clouds += 1


def as_foxglove_json(messages, path):
    """`messages` as Foxglove's schemas in JSON, written by Python mcap; types without
    a Foxglove schema (/chatter) are left out."""
    import base64
    import json

    # Foxglove numbers a point field's type differently from ROS.
    numeric = {1: 2, 2: 1, 3: 4, 4: 3, 5: 6, 6: 5, 7: 7, 8: 8}

    def stamp(header):
        return {"sec": header.stamp.sec, "nsec": header.stamp.nanosec}

    def transform(t):
        v, q = t.transform.translation, t.transform.rotation
        return {
            "timestamp": stamp(t.header), "parent_frame_id": t.header.frame_id, "child_frame_id": t.child_frame_id,
            "translation": {"x": v.x, "y": v.y, "z": v.z}, "rotation": {"x": q.x, "y": q.y, "z": q.z, "w": q.w},
        }

    with open(path, "wb") as f:
        writer = McapWriter(f)
        writer.start()
        channels = {}
        for topic, msgtype, log_time, cdr in messages:
            if msgtype == CHATTER:
                continue
            m = ROS2.deserialize_cdr(cdr, msgtype)
            if msgtype == "sensor_msgs/msg/PointCloud2":
                schema, message = "foxglove.PointCloud", {
                    "timestamp": stamp(m.header), "frame_id": m.header.frame_id, "point_stride": m.point_step,
                    "fields": [{"name": f.name, "offset": f.offset, "type": numeric[f.datatype]} for f in m.fields],
                    "data": base64.b64encode(bytes(m.data)).decode(),
                }
            elif msgtype == "tf2_msgs/msg/TFMessage":
                schema, message = "foxglove.FrameTransforms", {"transforms": [transform(t) for t in m.transforms]}
            elif msgtype == COMPRESSED_IMAGE:
                schema, message = "foxglove.CompressedImage", {
                    "timestamp": stamp(m.header), "frame_id": m.header.frame_id, "format": m.format,
                    "data": base64.b64encode(bytes(m.data)).decode(),
                }
            elif msgtype == "sensor_msgs/msg/CameraInfo":
                schema, message = "foxglove.CameraCalibration", {
                    "timestamp": stamp(m.header), "frame_id": m.header.frame_id, "width": m.width,
                    "height": m.height, "distortion_model": m.distortion_model,
                    "D": list(m.d), "K": list(m.k), "R": list(m.r), "P": list(m.p),
                }
            else:
                raise SystemExit(f"{topic}: no Foxglove schema for {msgtype}")
            if topic not in channels:
                text = json.dumps({"title": schema, "type": "object"}).encode()
                schema_id = writer.register_schema(name=schema, encoding="jsonschema", data=text)
                channels[topic] = writer.register_channel(topic=topic, message_encoding="json", schema_id=schema_id)
            writer.add_message(channels[topic], log_time=log_time, data=json.dumps(message).encode(), publish_time=log_time)
        writer.finish()


POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
POSE_WITH_COVARIANCE = "geometry_msgs/msg/PoseWithCovarianceStamped"
# The vehicle's base_link carries the LiDAR 1.5 m up and 0.8 m forward, level.
MOUNT = np.array([0.8, 0.0, 1.5])


def as_pose_topic(messages, msgtype):
    """The drive as a localisation or a motion-capture system records it: no moving
    /tf, the vehicle's pose on /pose (`msgtype`, in the map frame, naming no child
    frame), and the LiDAR's mount on base_link added to /tf_static."""
    T = ROS2.types
    out = []
    for topic, t, stamp, cdr in messages:
        if topic == "/tf_static":
            tf = ROS2.deserialize_cdr(cdr, t)
            mount = T["geometry_msgs/msg/TransformStamped"](
                header=T["std_msgs/msg/Header"](stamp=tf.transforms[0].header.stamp, frame_id="base_link"),
                child_frame_id="velodyne",
                transform=T["geometry_msgs/msg/Transform"](
                    translation=T["geometry_msgs/msg/Vector3"](x=MOUNT[0], y=MOUNT[1], z=MOUNT[2]),
                    rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                ),
            )
            tf = T[t](transforms=[mount, *tf.transforms])
            out.append((topic, t, stamp, bytes(ROS2.serialize_cdr(tf, t))))
            continue
        if topic != "/tf":
            out.append((topic, t, stamp, cdr))
            continue
        for transform in ROS2.deserialize_cdr(cdr, t).transforms:
            q, v = transform.transform.rotation, transform.transform.translation
            # map_from_base_link = map_from_velodyne x velodyne_from_base_link
            w, x, y, z = q.w, q.x, q.y, q.z
            rotation = np.array([
                [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
            ])
            p = np.array([v.x, v.y, v.z]) - rotation @ MOUNT
            pose = T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]), orientation=q
            )
            if msgtype == POSE_STAMPED:
                message = T[msgtype](header=transform.header, pose=pose)
            else:
                covariance = T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36))
                message = T[msgtype](header=transform.header, pose=covariance)
            out.append(("/pose", msgtype, stamp, bytes(ROS2.serialize_cdr(message, msgtype))))
    return out


def with_second_pose_topic(messages):
    """`messages` with a second PoseStamped topic beside /pose, /vision_pose: the same
    poses 5 m off in x, in `odom` (as PX4's logs carry the vision input beside
    mavros/local_position/pose)."""
    T = ROS2.types
    out = list(messages)
    for topic, t, stamp, cdr in messages:
        if topic != "/pose":
            continue
        message = ROS2.deserialize_cdr(cdr, t)
        pose = message.pose.pose if t == POSE_WITH_COVARIANCE else message.pose
        pose.position.x += 5.0
        header = T["std_msgs/msg/Header"](stamp=message.header.stamp, frame_id="odom")
        vision = T[POSE_STAMPED](header=header, pose=pose)
        out.append(("/vision_pose", POSE_STAMPED, stamp, bytes(ROS2.serialize_cdr(vision, POSE_STAMPED))))
    return out


def main():
    drive, out = Path(sys.argv[1]), Path(sys.argv[2])
    out.mkdir(parents=True, exist_ok=True)
    messages = recorded(drive)
    ros1_bag(messages, out / "ros1-none.bag", None)
    ros1_bag(messages, out / "ros1-bz2.bag", Bag1Writer.CompressionFormat.BZ2)
    ros1_bag(messages, out / "ros1-lz4.bag", Bag1Writer.CompressionFormat.LZ4)
    ros1_mcap(messages, out / "ros1.mcap")
    rosbag2(messages, out / "rosbag2-sqlite3", StoragePlugin.SQLITE3)
    rosbag2(messages, out / "rosbag2-mcap", StoragePlugin.MCAP)
    for mode, suffix in [(CompressionMode.MESSAGE, ""), (CompressionMode.FILE, "-file")]:
        for storage, name in [(StoragePlugin.SQLITE3, "sqlite3"), (StoragePlugin.MCAP, "mcap")]:
            rosbag2(messages, out / f"rosbag2-{name}-zstd{suffix}", storage, mode)
    rosbag2(as_jpeg(messages), out / "rosbag2-mcap-jpeg", StoragePlugin.MCAP)
    livox = as_livox(messages, True)
    rosbag2(livox, out / "rosbag2-mcap-livox", StoragePlugin.MCAP)
    # The same bytes under ROS 1's package name (the layout does not depend on it).
    ros1_bag([(t, LIVOX1 if m == LIVOX else m, s, c) for t, m, s, c in livox], out / "ros1-livox.bag", None)
    rosbag2(as_livox(messages, False), out / "rosbag2-mcap-uint8", StoragePlugin.MCAP)
    rosbag2(as_pose_topic(messages, POSE_STAMPED), out / "rosbag2-mcap-pose", StoragePlugin.MCAP)
    ros1_bag(as_pose_topic(messages, POSE_WITH_COVARIANCE), out / "ros1-pose.bag", None)
    two_poses = with_second_pose_topic(as_pose_topic(messages, POSE_STAMPED))
    rosbag2(two_poses, out / "rosbag2-mcap-two-poses", StoragePlugin.MCAP)
    poses_and_tf = messages + [m for m in two_poses if m[0] in ("/pose", "/vision_pose")]
    rosbag2(sorted(poses_and_tf, key=lambda m: m[2]), out / "rosbag2-mcap-poses-and-tf", StoragePlugin.MCAP)
    as_foxglove(messages, out / "foxglove.mcap")
    as_foxglove(as_pose_topic(messages, POSE_STAMPED), out / "foxglove-pose.mcap")
    as_nuscenes_like(messages, out / "foxglove-nuscenes.mcap")
    as_foxglove_json(messages, out / "foxglove-json.mcap")
    if len(sys.argv) > 3:
        subprocess.run(
            [sys.argv[3], "--src", str(out / "ros1-none.bag"), "--dst", str(out / "rosbag2-from-bag")],
            check=True,
        )


if __name__ == "__main__":
    main()
