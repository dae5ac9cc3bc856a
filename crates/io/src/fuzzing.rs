//! Entry points of the cargo fuzz targets in `fuzz/` for the readers of this crate
//! (`travmap_fuzzing` gathers them with the other crates'), also run by the corpus
//! replay and mutation tests in `tests/`: each feeds arbitrary bytes to one parser
//! of untrusted input. Any result is fine, an error or a value; a panic,
//! an abort or an allocation out of proportion to the input is a bug.

use std::path::Path;

use crate::Source;
use crate::SourceOptions;
use crate::kitti::text::{parse_calibration, parse_poses, parse_times};
use crate::kitti::{drop_non_returns, parse_labels, parse_scan};
use crate::log_drive::transforms::isometry;
use crate::payloads::cloud::cloud_points;
use crate::payloads::image::{image_pixels, jpeg_pixels};
use crate::payloads::livox::{LIVOX_CUSTOM_MESSAGES, decode_cloud};
use travmap_formats::foxglove;
use travmap_formats::log_message::Part;
use travmap_formats::mcap::writer::Compression;
use travmap_formats::mcap::writer::{FinishedChunk, McapWriter};
use travmap_formats::ros::MessageEncoding;
use travmap_formats::ros::ros1;
use travmap_formats::ros::{CameraInfo, Odometry, PointCloud2, TfMessage, Transform, decode};

/// A fuzz target: arbitrary bytes in, nothing out.
pub type Target = fn(&[u8]);

/// Every target by name: the fuzz target `NAME` calls `TARGETS[NAME]`, and its seed
/// corpus is `fuzz/seeds/NAME/`.
pub const TARGETS: [(&str, Target); 22] = [
    ("kitti_calib", kitti_calib),
    ("kitti_poses", kitti_poses),
    ("kitti_scan", kitti_scan),
    ("kitti_labels", kitti_labels),
    ("ros_point_cloud", ros_point_cloud),
    ("ros_image", ros_image),
    ("ros_camera_info", ros_camera_info),
    ("ros_tf", ros_tf),
    ("mcap_file", mcap_file),
    ("bag_file", bag_file),
    ("pcap_file", pcap_file),
    ("ros1_message", ros1_message),
    ("rosbag2_metadata", rosbag2_metadata),
    ("pcd_file", pcd_file),
    ("ply_file", ply_file),
    ("las_file", las_file),
    ("velodyne_scan", velodyne_scan),
    ("pandar_scan", pandar_scan),
    ("robosense_scan", robosense_scan),
    ("nebula_packets", nebula_packets),
    ("ouster_packets", ouster_packets),
    ("foxglove_message", foxglove_message),
];

const NAMED: &str = "fuzzed";

/// `calib.txt`, and the cameras it gives.
pub fn kitti_calib(data: &[u8]) {
    if let Ok(text) = std::str::from_utf8(data)
        && let Ok(calibration) = parse_calibration(text, Path::new(NAMED))
    {
        let _ = calibration.camera_2();
        let _ = calibration.velodyne_from_camera_0();
    }
}

/// `poses.txt` and `times.txt`, which share the line-of-numbers format.
pub fn kitti_poses(data: &[u8]) {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = parse_poses(text, Path::new(NAMED));
        let _ = parse_times(text, Path::new(NAMED));
    }
}

/// A `.bin` scan, then the dropping of its points that are no return beside labels.
pub fn kitti_scan(data: &[u8]) {
    if let Ok(mut points) = parse_scan(data, Path::new(NAMED)) {
        let mut labels: Vec<u32> = (0..points.len() as u32).collect();
        drop_non_returns(&mut points, Some(&mut labels));
        assert_eq!(points.len(), labels.len());
    }
}

/// A `.label` file, against the right point count and a wrong one.
pub fn kitti_labels(data: &[u8]) {
    for points in [data.len() / 4, data.len() / 4 + 1] {
        let _ = parse_labels(data, Path::new(NAMED), Path::new(NAMED), points);
    }
}

/// A `sensor_msgs/msg/PointCloud2` message (or a Livox CustomMsg), decoded and read
/// into points.
pub fn ros_point_cloud(data: &[u8]) {
    if let Ok(cloud) = decode::<PointCloud2>(data) {
        let _ = cloud_points(&cloud);
    }
    // And as a Livox CustomMsg, read as a PointCloud2.
    for encoding in [MessageEncoding::Cdr, MessageEncoding::Ros1] {
        if let Ok(cloud) = decode_cloud(LIVOX_CUSTOM_MESSAGES[0], encoding, data) {
            let _ = cloud_points(&cloud);
        }
    }
}

/// A protobuf and a JSON message as each Foxglove schema travmap reads, whole and
/// its header alone; a point cloud read into points.
pub fn foxglove_message(data: &[u8]) {
    for (schema, encoding) in foxglove::SCHEMAS
        .iter()
        .flat_map(|schema| [(schema, foxglove::PROTOBUF), (schema, foxglove::JSON)])
    {
        for part in [Part::Whole, Part::Header] {
            if let Ok(cdr) = foxglove::to_cdr(schema, encoding, data, part)
                && let Ok(cloud) = decode::<PointCloud2>(&cdr)
            {
                let _ = cloud_points(&cloud);
            }
        }
    }
}

/// A `CompressedImage` (PNG or JPEG) and a raw `Image` message, decoded to pixels;
/// and the bytes as a JPEG file themselves.
pub fn ros_image(data: &[u8]) {
    let _ = jpeg_pixels(data);
    for encoding in [MessageEncoding::Cdr, MessageEncoding::Ros1] {
        let _ = image_pixels(data, true, encoding);
        let _ = image_pixels(data, false, encoding);
    }
}

/// A `sensor_msgs/msg/CameraInfo` message and the projection it gives.
pub fn ros_camera_info(data: &[u8]) {
    if let Ok(info) = decode::<CameraInfo>(data) {
        let k = nalgebra::Matrix3::from_row_slice(&info.k);
        let _ = k.try_inverse();
    }
}

/// A `tf2_msgs/msg/TFMessage` and a `nav_msgs/msg/Odometry`, made into poses.
pub fn ros_tf(data: &[u8]) {
    if let Ok(tf) = decode::<TfMessage>(data) {
        for t in &tf.transforms {
            let _ = isometry(&t.transform);
        }
    }
    if let Ok(odometry) = decode::<Odometry>(data) {
        let pose = odometry.pose.pose;
        let _ = isometry(&Transform {
            translation: pose.position,
            rotation: pose.orientation,
        });
    }
    for type_name in crate::log_drive::pose_topics::POSE_MESSAGES {
        let mut topic = crate::log_drive::pose_topics::PoseTopic::default();
        let _ = topic.add(type_name, data, travmap_formats::ros::MessageEncoding::Cdr);
    }
}

/// A whole MCAP file: opened as a drive, then every frame read, images included;
/// and its chunks as stored, copied into a new file as passthrough copies them.
pub fn mcap_file(data: &[u8]) {
    with_file(data, "mcap", read_drive);
    let Some(mut stored) =
        travmap_formats::mcap::stored::stored_log(&bytes::Bytes::copy_from_slice(data))
    else {
        return;
    };
    let mut copy = || -> std::io::Result<Vec<u8>> {
        let mut writer =
            McapWriter::new(Vec::new(), "ros2", "fuzz", Compression::Zstd, 1 << 20, 1)?;
        for (header, data) in &stored.schemas {
            writer.add_schema(header.id, &header.name, &header.encoding, data);
        }
        for channel in &stored.channels {
            writer.add_channel(channel, false);
        }
        for chunk in &mut stored.chunks {
            writer.copy_chunk(FinishedChunk::copied(chunk))?;
        }
        writer.finish()
    };
    // Every channel a chunk uses is declared (stored_log checks), so copying works.
    copy().expect("a stored log copies");
}

/// A whole ROS 1 bag, read as [`mcap_file`] reads an MCAP file.
pub fn bag_file(data: &[u8]) {
    with_file(data, "bag", read_drive);
}

/// A whole packet capture opened as a drive, every frame read.
pub fn pcap_file(data: &[u8]) {
    with_file(data, "pcap", read_drive);
}

/// The ROS 1 message types travmap reads, in ROS 1's format.
pub fn ros1_message(data: &[u8]) {
    if let Ok(cloud) = ros1::decode::<PointCloud2>(data) {
        let _ = cloud_points(&cloud);
    }
    let _ = ros1::decode::<TfMessage>(data);
    let _ = ros1::decode::<Odometry>(data);
    let _ = ros1::decode::<CameraInfo>(data);
    for type_name in [
        "velodyne_msgs/msg/VelodyneScan",
        "pandar_msgs/msg/PandarScan",
    ] {
        let _ = travmap_formats::ros::ros1_to_cdr(type_name, data);
    }
}

/// A `velodyne_msgs/msg/VelodyneScan` message, CDR and then ROS 1: its packets
/// decoded and cut into scans as the model they name (a flat table of its laser
/// count, read as YAML, for the models without a built-in one).
pub fn velodyne_scan(data: &[u8]) {
    use crate::packets::velodyne::{
        Decoder, DecoderSettings, ScanAssembler, VelodyneCalibration, VelodyneModel, scan_message,
    };
    use travmap_formats::ros::MessageEncoding;
    for encoding in [MessageEncoding::Cdr, MessageEncoding::Ros1] {
        let Ok(message) = scan_message(data, encoding) else {
            continue;
        };
        let Some(Ok(model)) = message
            .packets
            .first()
            .map(|(_, p)| VelodyneModel::of_packet(p))
        else {
            continue;
        };
        let calibration = VelodyneCalibration::builtin(model).or_else(|| {
            let lasers: String = (0..model.lasers())
                .map(|i| {
                    let elevation = (i as f64 - 64.0) * 0.005;
                    format!(
                        "- {{laser_id: {i}, rot_correction: 0.01, vert_correction: {elevation}}}\n"
                    )
                })
                .collect();
            VelodyneCalibration::from_yaml(&format!("lasers:\n{lasers}")).ok()
        });
        let Some(Ok(decoder)) =
            calibration.map(|c| Decoder::new(model, c, DecoderSettings::default()))
        else {
            continue;
        };
        let mut assembler = ScanAssembler::new(decoder);
        for (stamp_ns, packet) in message.packets {
            let _ = assembler.push(packet, stamp_ns);
        }
    }
}

/// A PCD file, read into points.
pub fn pcd_file(data: &[u8]) {
    if let Ok(cloud) = crate::cloud_files::pcd::parse_pcd(data, NAMED) {
        let _ = cloud_points(&cloud);
    }
}

/// A PLY file, read into points.
pub fn ply_file(data: &[u8]) {
    if let Ok(cloud) = crate::cloud_files::ply::parse_ply(data, NAMED) {
        let _ = cloud_points(&cloud);
    }
}

/// A LAS or LAZ file, read into points.
pub fn las_file(data: &[u8]) {
    let bytes = data.len() as u64;
    let _ = crate::cloud_files::las::las_points(
        std::io::Cursor::new(data.to_vec()),
        bytes,
        &mut |_| Ok(()),
    );
}

/// A rosbag2 `metadata.yaml`, in a directory holding one empty storage file.
pub fn rosbag2_metadata(data: &[u8]) {
    let directory = std::env::temp_dir().join(format!(
        "travmap-fuzz-{}-{:?}.rosbag2",
        std::process::id(),
        std::thread::current().id()
    ));
    if std::fs::create_dir_all(&directory).is_ok()
        && std::fs::write(directory.join("metadata.yaml"), data).is_ok()
        && std::fs::write(directory.join("drive_0.mcap"), b"").is_ok()
    {
        read_drive(&directory);
    }
    let _ = std::fs::remove_dir_all(&directory);
}

/// Opens `path` as a drive, of whatever format it is, and reads every frame.
fn read_drive(path: &Path) {
    if let Ok(source) = Source::open(path, &SourceOptions::default(), &|_| {}) {
        source.read(&(0..usize::MAX)).for_each(drop);
    }
}

/// Runs `read` on `data` written to a file, for the readers that take a path. One
/// file per thread, because the tests run targets in parallel.
pub fn with_file(data: &[u8], extension: &str, read: impl FnOnce(&Path)) {
    let path = std::env::temp_dir().join(format!(
        "travmap-fuzz-{}-{:?}.{extension}",
        std::process::id(),
        std::thread::current().id()
    ));
    if std::fs::write(&path, data).is_ok() {
        read(&path);
    }
    let _ = std::fs::remove_file(&path);
}

/// A `pandar_msgs/msg/PandarScan` message, CDR and then ROS 1: its packets decoded
/// and cut into scans as the Hesai model they name; and the bytes as a Hesai
/// angle-correction CSV.
pub fn pandar_scan(data: &[u8]) {
    use crate::packets::hesai::{
        HesaiAssembler, HesaiCalibration, HesaiModel, pandar_scan_message,
    };
    use travmap_formats::ros::MessageEncoding;
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = HesaiCalibration::from_csv(text);
    }
    for encoding in [MessageEncoding::Cdr, MessageEncoding::Ros1] {
        let Ok(message) = pandar_scan_message(data, encoding) else {
            continue;
        };
        let Some(Ok(model)) = message
            .packets
            .first()
            .map(|(_, p)| HesaiModel::of_packet(p))
        else {
            continue;
        };
        let mut assembler = HesaiAssembler::new(model, &HesaiCalibration::builtin(model))
            .expect("the factory table fits its model");
        for (stamp_ns, packet) in message.packets {
            if let Ok(Some(scan)) = assembler.push(packet, stamp_ns) {
                assert!(
                    scan.points
                        .iter()
                        .all(|p| p.xyz_m.iter().all(|v| v.is_finite()))
                );
            }
        }
    }
}

/// A `robosense_msgs/msg/RobosenseScan` message, CDR and then ROS 1: its packets
/// decoded (the DIFOPs among them read) and cut into scans as a Helios 16P; and the
/// bytes as a RoboSense angle CSV.
pub fn robosense_scan(data: &[u8]) {
    use crate::packets::robosense::{
        RobosenseAssembler, RobosenseCalibration, RobosenseModel, robosense_scan_message,
    };
    use travmap_formats::ros::MessageEncoding;
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = RobosenseCalibration::from_csv(text);
    }
    for encoding in [MessageEncoding::Cdr, MessageEncoding::Ros1] {
        let Ok(message) = robosense_scan_message(data, encoding) else {
            continue;
        };
        let model = RobosenseModel::Helios16p;
        let mut assembler = RobosenseAssembler::new(model, &RobosenseCalibration::builtin(model))
            .expect("the generic table fits its model");
        for (stamp_ns, packet) in message.packets {
            if let Ok(Some(scan)) = assembler.push(packet, stamp_ns) {
                let points = scan.points.iter().flat_map(|p| p.xyz_m);
                assert!(points.clone().all(f32::is_finite));
            }
        }
    }
}

/// A `nebula_msgs/msg/NebulaPackets` message (CDR): read in place and as its serde
/// type (the same packet bytes when both read it); each packet's vendor and model
/// told from its bytes, and the packets cut into scans with the model's built-in
/// table.
pub fn nebula_packets(data: &[u8]) {
    use crate::packets::{
        NEBULA_PACKETS, PacketAssembler, PacketCalibration, PacketModel, packet_message,
    };
    use travmap_formats::ros::{MessageEncoding, NebulaPackets, decode};
    let Ok(message) = packet_message(NEBULA_PACKETS, data, MessageEncoding::Cdr, 0) else {
        return;
    };
    if let Ok(typed) = decode::<NebulaPackets>(data) {
        let typed = typed.packets.iter().map(|p| p.data.as_slice());
        assert!(typed.eq(message.packets.iter().map(|(_, p)| *p)));
    }
    let Some(Ok(model)) =
        (message.packets.first()).map(|(_, packet)| PacketModel::of_packet(NEBULA_PACKETS, packet))
    else {
        return;
    };
    let Ok(calibration) = PacketCalibration::for_model(model, None) else {
        return;
    };
    let mut assembler =
        PacketAssembler::new(model, &calibration).expect("a built-in table fits its model");
    if let Ok(scans) = assembler.push_message(NEBULA_PACKETS, data, MessageEncoding::Cdr, 0) {
        let points = scans.iter().flat_map(|scan| &scan.points);
        assert!(points.flat_map(|p| p.xyz_m).all(f32::is_finite));
    }
}

/// Ouster packets: the sensor's metadata JSON (its length in the first two bytes,
/// little-endian), then packets of the metadata's packet size; the metadata read
/// and the packets cut into scans, every point finite.
pub fn ouster_packets(data: &[u8]) {
    use crate::packets::ouster::{OusterAssembler, OusterMetadata};
    let Some((length, rest)) = data.split_first_chunk::<2>() else {
        return;
    };
    let Some((json, packets)) = rest.split_at_checked(usize::from(u16::from_le_bytes(*length)))
    else {
        return;
    };
    let Ok(metadata) = OusterMetadata::from_json(&String::from_utf8_lossy(json)) else {
        return;
    };
    let mut assembler = OusterAssembler::new(&metadata);
    let packet_bytes = metadata.model.packet_bytes();
    for (k, packet) in packets.chunks(packet_bytes).enumerate() {
        if let Ok(scans) = assembler.push(packet, k as u64 * 1_000_000) {
            let points = scans.iter().flat_map(|scan| &scan.points);
            assert!(points.flat_map(|p| p.xyz_m).all(f32::is_finite));
        }
    }
}
