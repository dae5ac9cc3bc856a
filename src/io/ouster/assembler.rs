//! Ouster packets into scans: a scan is a frame id's columns, handed on at the
//! column window's last column, or when the frame id changes (its last packet
//! lost).

use super::metadata::OusterMetadata;
use super::packet::OusterModel;
use crate::io::velodyne::{PacketScan, VelodynePoint};

/// A second return closer than this to the first is the same surface.
const DUAL_RETURN_THRESHOLD_MM: u32 = 100;

pub struct OusterAssembler {
    model: OusterModel,
    last_column: u16,
    /// Per measurement id and beam: the beam's direction and origin in the sensor
    /// frame (metres).
    directions: Vec<[f32; 3]>,
    origins: Vec<[f32; 3]>,
    /// The frame id being gathered, and the last one handed on.
    frame_id: Option<u16>,
    handed_on: Option<u16>,
    points: Vec<VelodynePoint>,
    /// The scan's first column's time, and the shift from the sensor's clock to
    /// the log's at the packet that held it.
    stamp_ns: Option<u64>,
    to_log_clock_ns: i64,
    decode_points: bool,
}

impl OusterAssembler {
    pub fn new(metadata: &OusterMetadata) -> Self {
        let (directions, origins) = metadata.beams();
        Self {
            model: metadata.model,
            last_column: metadata.column_window.1,
            directions,
            origins,
            frame_id: None,
            handed_on: None,
            points: Vec::new(),
            stamp_ns: None,
            to_log_clock_ns: 0,
            decode_points: true,
        }
    }

    /// This assembler cutting and stamping scans without decoding their points.
    pub fn stamps_only(self) -> Self {
        Self {
            decode_points: false,
            directions: Vec::new(),
            origins: Vec::new(),
            ..self
        }
    }

    /// Adds a packet recorded at `stamp_ns` (the log's time: ouster_ros's packet
    /// message has no stamp); the scans it completes. Times are the columns' own,
    /// moved to the log's clock by the packet that began the scan (its last column
    /// was measured as it was sent), so a sensor without time synchronisation still
    /// finds its poses.
    pub fn push(&mut self, packet: &[u8], stamp_ns: u64) -> Result<Vec<PacketScan>, String> {
        let frame_id = self.model.frame_id(packet)?;
        let mut completed = Vec::new();
        if self.frame_id.is_some_and(|f| f != frame_id) {
            completed.extend(self.hand_on());
        }
        // The rest of a frame already handed on (packets out of order) is dropped.
        if self.handed_on == Some(frame_id) && self.frame_id.is_none() {
            return Ok(completed);
        }
        self.frame_id = Some(frame_id);
        let model = self.model;
        let columns = || model.columns(packet).filter(|c| c.valid);
        let Some(last) = columns().last() else {
            return Ok(completed);
        };
        let w = self.model.columns_per_frame;
        if let Some(column) = columns().find(|c| c.measurement_id >= w) {
            return Err(format!(
                "measurement id {} in a frame of {w} columns",
                column.measurement_id
            ));
        }
        if self.stamp_ns.is_none() {
            let first = columns().next().expect("a valid column");
            self.to_log_clock_ns = (i128::from(stamp_ns) - i128::from(last.timestamp_ns)) as i64;
            self.stamp_ns = Some(first.timestamp_ns);
        }
        if self.decode_points {
            self.decode(packet);
        }
        if columns().any(|c| c.measurement_id == self.last_column) {
            completed.extend(self.hand_on());
        }
        Ok(completed)
    }

    fn decode(&mut self, packet: &[u8]) {
        let (h, pixel_bytes) = (
            usize::from(self.model.pixels_per_column),
            self.model.pixel_bytes(),
        );
        let profile = self.model.profile;
        for column in self.model.columns(packet).filter(|c| c.valid) {
            let beams = usize::from(column.measurement_id) * h;
            let time_ns = column
                .timestamp_ns
                .saturating_add_signed(self.to_log_clock_ns);
            for (beam, pixel) in column.pixels.chunks_exact(pixel_bytes).enumerate() {
                let [(first, first_reflectivity), (second, second_reflectivity)] =
                    profile.returns(pixel);
                let second_apart =
                    second != 0 && second.abs_diff(first) >= DUAL_RETURN_THRESHOLD_MM;
                let returns = [(first, first_reflectivity)]
                    .into_iter()
                    .chain(second_apart.then_some((second, second_reflectivity)));
                for (range_mm, reflectivity) in returns.filter(|(r, _)| *r != 0) {
                    let (direction, origin) =
                        (self.directions[beams + beam], self.origins[beams + beam]);
                    let range_m = range_mm as f32 / 1000.0;
                    self.points.push(VelodynePoint {
                        xyz_m: std::array::from_fn(|k| origin[k] + range_m * direction[k]),
                        intensity: reflectivity,
                        ring: beam as u16,
                        azimuth_centideg: azimuth_centideg(
                            column.measurement_id,
                            self.model.columns_per_frame,
                        ),
                        time_ns,
                    });
                }
            }
        }
    }

    /// The scan gathered so far, if it has any column.
    fn hand_on(&mut self) -> Option<PacketScan> {
        self.handed_on = self.frame_id.take();
        let stamp_ns = self.stamp_ns.take()?;
        Some(PacketScan {
            stamp_ns: stamp_ns.saturating_add_signed(self.to_log_clock_ns),
            points: std::mem::take(&mut self.points),
        })
    }
}

/// The encoder's angle at a measurement id, 0.01 degree clockwise from the sensor
/// frame's +x (the lidar frame's -x: measurement id 0 looks backwards).
fn azimuth_centideg(measurement_id: u16, columns_per_frame: u16) -> u16 {
    let turned = u32::from(measurement_id) * 36_000 / u32::from(columns_per_frame);
    ((turned + 18_000) % 36_000) as u16
}
