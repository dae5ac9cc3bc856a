//! Several LiDARs in one scan: the clouds of the other sensors' topics (PointCloud2
//! messages, or scans cut from their packets), held until the scan they belong to
//! (the nearest in time, within half a period) is read, and moved into the scan's
//! frame through the transform tree.

use nalgebra::{Isometry3, Point3};

use crate::packets::{PacketCalibration, PacketModel};
use crate::payloads::cloud::{CloudPoints, cloud_points};
use crate::payloads::livox::decode_cloud;
use travmap_core::error::{Error, Result};
use travmap_formats::log_message::LogMessage;

/// Another sensor's topic merged into the frames' scans.
pub(crate) struct MergedSensor {
    pub(crate) topic: String,
    /// The frame its clouds are in.
    pub(crate) frame: String,
    /// When it carries LiDAR packets: their model and calibration.
    pub(crate) packets: Option<(PacketModel, PacketCalibration)>,
}

/// A cloud of a merged topic waiting for its scan: its stamp, the topic's place in
/// [`crate::log_drive::LogDrive`]'s `merged`, and the cloud.
pub(crate) struct MergedCloud {
    pub(crate) stamp_ns: u64,
    pub(crate) topic: usize,
    pub(crate) cloud: MergedContent,
}

/// A merged cloud as it came: a PointCloud2 message is decoded only if a scan takes it.
pub(crate) enum MergedContent {
    Message(LogMessage),
    Scan(CloudPoints),
}

/// The median time between clouds (100 ms with fewer than two).
pub fn median_period_ns(stamps_ns: &[u64]) -> u64 {
    let mut periods: Vec<u64> = stamps_ns
        .windows(2)
        .map(|w| w[1].saturating_sub(w[0]))
        .collect();
    periods.sort_unstable();
    periods
        .get(periods.len() / 2)
        .copied()
        .unwrap_or(100_000_000)
}

/// `points` with every merged topic's nearest cloud (within half a period of
/// `stamp_ns`) moved into the clouds' frame by `cloud_from_frame(frame, its
/// stamp)`, and the merged topics the scan holds; a topic with no cloud near is left
/// out of this scan only. Labels stay only when every cloud has them.
pub(crate) fn merge(
    mut points: CloudPoints,
    stamp_ns: u64,
    period_ns: u64,
    topics: &[MergedSensor],
    clouds: &[MergedCloud],
    cloud_error: &dyn Fn(&str, String) -> Error,
    cloud_from_frame: &dyn Fn(&str, u64) -> Result<Isometry3<f64>>,
) -> Result<(CloudPoints, Vec<String>)> {
    let mut merged = Vec::new();
    for (at, sensor) in topics.iter().enumerate() {
        let nearest = clouds
            .iter()
            .filter(|c| c.topic == at && c.stamp_ns.abs_diff(stamp_ns) <= period_ns / 2)
            .min_by_key(|c| c.stamp_ns.abs_diff(stamp_ns));
        let Some(other) = nearest else { continue };
        let fail = |problem: String| cloud_error(&sensor.topic, problem);
        let decoded;
        let other_points = match &other.cloud {
            MergedContent::Scan(points) => points,
            MergedContent::Message(message) => {
                let encoding = (message.connection.encoding())
                    .ok_or_else(|| fail("an encoding travmap does not read".into()))?;
                let type_name = message.connection.type_name();
                let cloud = decode_cloud(&type_name, encoding, &message.data).map_err(fail)?;
                decoded = cloud_points(&cloud).map_err(fail)?;
                &decoded
            }
        };
        let pose = cloud_from_frame(&sensor.frame, other.stamp_ns)?;
        points.points.extend(other_points.points.iter().map(|p| {
            let q = pose * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            [q.x as f32, q.y as f32, q.z as f32, p[3]]
        }));
        points.labels = match (points.labels.take(), &other_points.labels) {
            (Some(mut labels), Some(more)) => {
                labels.extend(more);
                Some(labels)
            }
            _ => None,
        };
        points.dropped += other_points.dropped;
        merged.push(sensor.topic.clone());
    }
    Ok((points, merged))
}
