//! Ouster packets into scans: a scan is a frame id's columns, handed on at the
//! column window's last column, or when the frame id changes (its last packet
//! lost).

use super::metadata::OusterMetadata;
use super::packet::OusterModel;
use crate::packets::scan::{PacketPoint, PacketScan};

/// A second return closer than this to the first is the same surface.
const DUAL_RETURN_THRESHOLD_MM: u32 = 100;

pub struct OusterAssembler {
    model: OusterModel,
    last_column: u16,
    /// Per measurement id and beam: the beam's direction and origin in the sensor
    /// frame (metres).
    directions: Vec<[f32; 3]>,
    origins: Vec<[f32; 3]>,
    /// Per beam: its ring, 0 the lowest (Ouster numbers its beams from the top).
    rings: Vec<u16>,
    /// The frame id being gathered, and the last one handed on.
    frame_id: Option<u32>,
    handed_on: Option<u32>,
    points: Vec<PacketPoint>,
    /// The scan's first column's time, and the shift from the sensor's clock to
    /// the log's at the packet that held it.
    stamp_ns: Option<u64>,
    to_log_clock_ns: i64,
    decode_points: bool,
    /// Valid columns of the scan being gathered.
    columns: u32,
}

impl OusterAssembler {
    pub fn new(metadata: &OusterMetadata) -> Self {
        let (directions, origins) = metadata.beams();
        let altitudes = &metadata.beam_altitude_deg;
        let rings = (altitudes.iter())
            .map(|a| altitudes.iter().filter(|b| b < &a).count() as u16)
            .collect();
        // A window through 0 (ouster-sdk's windowed_frame2: [370, 85] of 512): the
        // frame's columns 0..=85 are measured first, and its last is the frame's.
        let (first_column, last_column) = metadata.column_window;
        let last_column = match first_column > last_column {
            true => metadata.model.columns_per_frame - 1,
            false => last_column,
        };
        Self {
            model: metadata.model,
            last_column,
            directions,
            origins,
            rings,
            frame_id: None,
            handed_on: None,
            points: Vec::new(),
            stamp_ns: None,
            to_log_clock_ns: 0,
            decode_points: true,
            columns: 0,
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
        self.columns += columns().count() as u32;
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
                    self.points.push(PacketPoint {
                        xyz_m: std::array::from_fn(|k| origin[k] + range_m * direction[k]),
                        intensity: reflectivity,
                        ring: self.rings[beam],
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

    /// The scan gathered since the last one handed on, however little of the turn
    /// it holds (a capture of part of one turn): the scan, and its valid columns of
    /// the turn's.
    pub fn finish(&mut self) -> Option<(PacketScan, u32, u16)> {
        let columns = self.columns;
        let scan = self.hand_on()?;
        Some((scan, columns, self.model.columns_per_frame))
    }

    /// The scan gathered so far, if it has any column.
    fn hand_on(&mut self) -> Option<PacketScan> {
        self.columns = 0;
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

#[cfg(test)]
mod tests {
    use nalgebra::Matrix4;

    use super::*;
    use crate::packets::ouster::packet::Profile;

    /// Four beams, 16 columns a turn, four columns a packet, LEGACY.
    fn metadata() -> OusterMetadata {
        OusterMetadata {
            model: OusterModel {
                profile: Profile::Legacy,
                pixels_per_column: 4,
                columns_per_packet: 4,
                columns_per_frame: 16,
            },
            product: "OS-1-64".into(),
            column_window: (0, 15),
            beam_altitude_deg: vec![10.0, 3.0, -3.0, -10.0],
            beam_azimuth_deg: vec![2.0, 1.0, -1.0, -2.0],
            beam_to_lidar_mm: Matrix4::identity(),
            lidar_to_sensor_mm: Matrix4::identity(),
        }
    }

    /// A LEGACY packet of frame `frame_id` holding columns `first..first + 4`, each
    /// measured 1 ms after the last from `first_ns`, every pixel at `range_mm` (beam
    /// 3 without a return), column `invalid` not valid.
    fn packet(
        frame_id: u16,
        first: u16,
        first_ns: u64,
        range_mm: u32,
        invalid: Option<u16>,
    ) -> Vec<u8> {
        let mut out = Vec::new();
        for id in first..first + 4 {
            out.extend((first_ns + u64::from(id - first) * 1_000_000).to_le_bytes());
            out.extend(id.to_le_bytes());
            out.extend(frame_id.to_le_bytes());
            out.extend(0u32.to_le_bytes());
            for beam in 0..4 {
                let range = if beam == 3 { 0 } else { range_mm | 0xF00_00000 };
                out.extend(range.to_le_bytes());
                out.extend([beam as u8 * 10, 0, 0, 0, 0, 0, 0, 0]);
            }
            let status = if invalid == Some(id) { 0 } else { u32::MAX };
            out.extend(status.to_le_bytes());
        }
        out
    }

    #[test]
    fn a_frames_packets_are_one_scan_on_the_logs_clock() {
        let metadata = metadata();
        let mut assembler = OusterAssembler::new(&metadata);
        // The sensor's clock starts at 7 s; the log's packets are recorded 1.5 ms
        // after their last column.
        let log_ns = |sensor_ns: u64| 1_000_000_000_000 + sensor_ns + 1_500_000;
        let mut scans = Vec::new();
        for n in 0..4u16 {
            let first_ns = 7_000_000_000 + u64::from(n) * 4_000_000;
            let packet = packet(9, n * 4, first_ns, 10_000, Some(6));
            scans.extend(
                assembler
                    .push(&packet, log_ns(first_ns + 3_000_000))
                    .unwrap(),
            );
            // Handed on at the window's last column, not before.
            assert_eq!(scans.len(), usize::from(n == 3));
        }
        let scan = &scans[0];
        assert_eq!(scan.stamp_ns, log_ns(7_000_000_000));
        // 15 valid columns of 3 returns (beam 3 saw nothing).
        assert_eq!(scan.points.len(), 45);
        let (directions, origins) = metadata.beams();
        for point in &scan.points {
            // Beams are numbered from the top, rings from the bottom.
            let (id, beam) = (point.azimuth_centideg, 3 - usize::from(point.ring));
            let id = ((u32::from(id) + 18_000) % 36_000 * 16 / 36_000) as usize;
            let k = id * 4 + beam;
            let expected: [f32; 3] =
                std::array::from_fn(|i| origins[k][i] + 10.0 * directions[k][i]);
            assert_eq!(point.xyz_m, expected);
            assert_eq!(point.intensity, beam as u8 * 10);
            // Every column keeps its own time.
            assert_eq!(point.time_ns, log_ns(7_000_000_000 + id as u64 * 1_000_000));
        }
        // A point 10 m out along its beam, from an origin at the sensor.
        let norm = |p: [f32; 3]| p.iter().map(|v| v * v).sum::<f32>().sqrt();
        assert!((norm(scan.points[0].xyz_m) - 10.0).abs() < 1e-4);
    }

    #[test]
    fn a_lost_last_packet_ends_the_frame_at_the_next_and_strays_are_dropped() {
        let mut assembler = OusterAssembler::new(&metadata()).stamps_only();
        let push = |assembler: &mut OusterAssembler, frame, first, ns| {
            // Recorded as its last column was measured.
            let packet = packet(frame, first, ns, 5_000, None);
            assembler.push(&packet, ns + 3_000_000).unwrap()
        };
        assert!(push(&mut assembler, 1, 0, 100).is_empty());
        assert!(push(&mut assembler, 1, 4, 200).is_empty());
        // Frame 1's last packets were lost: frame 2's first hands it on.
        let scans = push(&mut assembler, 2, 0, 300);
        assert_eq!(scans.iter().map(|s| s.stamp_ns).collect::<Vec<_>>(), [100]);
        assert!(scans[0].points.is_empty(), "stamps only");
        for first in [4, 8] {
            assert!(push(&mut assembler, 2, first, 400).is_empty());
        }
        assert_eq!(push(&mut assembler, 2, 12, 500).len(), 1);
        // A straggler of frame 2 after it was handed on starts nothing.
        assert!(push(&mut assembler, 2, 8, 600).is_empty());
        assert!(push(&mut assembler, 3, 12, 700).len() == 1);
    }

    #[test]
    fn a_packet_the_metadata_does_not_describe_is_refused() {
        let mut assembler = OusterAssembler::new(&metadata());
        let short = &packet(1, 0, 0, 1_000, None)[..100];
        let problem = assembler.push(short, 0).unwrap_err();
        assert!(
            problem.contains(
                "a packet of 100 bytes where the metadata's Ouster LEGACY packets are 272"
            ),
            "{problem}"
        );
        let mut beyond = packet(1, 0, 0, 1_000, None);
        beyond[8..10].copy_from_slice(&16u16.to_le_bytes());
        let problem = assembler.push(&beyond, 0).unwrap_err();
        assert!(
            problem.contains("measurement id 16 in a frame of 16 columns"),
            "{problem}"
        );
    }
}
