//! A folder of scans as a drive: `.pcd` files ([`super::pcd`]) or KITTI-style `.bin`
//! files (float32 x, y, z, remission), in name order, with no poses (the method's
//! registration stage estimates them). Stamps come from the file names when they are
//! nanoseconds since the epoch (`1317000000123456789.pcd`), else from a rate.

use std::ops::Range;
use std::path::{Path, PathBuf};

use nalgebra::Isometry3;

use super::pcd::parse_pcd;
use crate::format::{ScanFormat, scan_format};
use crate::kitti::{drop_non_returns, parse_scan};
use crate::payloads::cloud::{check_some_finite, cloud_points};
use travmap_core::error::{Error, Result};
use travmap_core::frame::{Frame, RemissionScale};

/// The frame of the scans, as written to MCAP.
pub const SENSOR_FRAME: &str = "lidar";

/// The rate stamps are made at when the names are not times and none is given.
pub const DEFAULT_RATE_HZ: f64 = 10.0;

/// File names at or above this many nanoseconds (1973) are read as times.
const SMALLEST_STAMP_NS: u64 = 100_000_000_000_000_000;

/// An opened folder of scans.
pub struct ScanFolder {
    dir: PathBuf,
    format: ScanFormat,
    files: Vec<PathBuf>,
    stamps_ns: Vec<u64>,
    /// How the stamps were made, for the user to hear.
    notice: String,
}

impl ScanFolder {
    /// Opens `dir`; stamps from numeric file names in ns, else at `rate_hz` (10 Hz when
    /// None).
    pub fn open(dir: &Path, rate_hz: Option<f64>) -> Result<Self> {
        let problem = |message: String| Error::Sequence {
            path: dir.to_path_buf(),
            message,
        };
        let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
            .map_err(|e| Error::io(dir, e))?
            .flatten()
            .map(|e| e.path())
            .filter(|p| scan_format(p).is_some())
            .collect();
        files.sort();
        let format = match files.first().and_then(|f| scan_format(f)) {
            Some(format) => format,
            None => return Err(problem("no .pcd or .bin scans".into())),
        };
        if files.iter().any(|f| scan_format(f) != Some(format)) {
            return Err(problem(
                "both .pcd and .bin scans: a folder of scans holds one kind".into(),
            ));
        }
        let named: Option<Vec<u64>> = files
            .iter()
            .map(|f| {
                f.file_stem()
                    .and_then(|s| s.to_str())
                    .and_then(|s| s.parse::<u64>().ok())
                    .filter(|ns| *ns >= SMALLEST_STAMP_NS)
            })
            .collect();
        let (stamps_ns, notice) = match (named, rate_hz) {
            (Some(stamps), None) => (
                stamps,
                "stamps from the file names (nanoseconds)".to_string(),
            ),
            (_, rate) => {
                let rate = rate.unwrap_or(DEFAULT_RATE_HZ);
                if !(rate.is_finite() && rate > 0.0) {
                    return Err(problem(format!("a rate of {rate} Hz")));
                }
                let stamps = (0..files.len())
                    .map(|i| (i as f64 * 1e9 / rate).round() as u64)
                    .collect();
                let said = if rate_hz.is_some() {
                    ""
                } else {
                    " (--rate to set)"
                };
                (stamps, format!("stamps at {rate} Hz{said}"))
            }
        };
        Ok(Self {
            dir: dir.to_path_buf(),
            format,
            files,
            stamps_ns,
            notice: format!(
                "{}: a folder of {} scans; {notice}",
                dir.display(),
                match format {
                    ScanFormat::Pcd => "PCD",
                    ScanFormat::Bin => ".bin",
                }
            ),
        })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn notice(&self) -> &str {
        &self.notice
    }

    /// Frame numbers in `range`: positions in name order.
    pub fn frames_in(&self, range: &Range<usize>) -> Vec<usize> {
        (range.start.min(self.files.len())..range.end.min(self.files.len())).collect()
    }

    /// Frame `index`, posed at the identity (registration poses it).
    pub fn read_frame(&self, index: usize) -> Result<Frame> {
        let path = &self.files[index];
        let bytes = crate::format::read_data_file(path)?;
        let (points, remission, dropped_points) = match self.format {
            ScanFormat::Bin => {
                let mut points = parse_scan(&bytes, path)?;
                let dropped = drop_non_returns(&mut points, None);
                (points, RemissionScale::Unit, dropped)
            }
            ScanFormat::Pcd => {
                let fail = |message: String| Error::Sequence {
                    path: path.clone(),
                    message,
                };
                let cloud = parse_pcd(&bytes, SENSOR_FRAME).map_err(fail)?;
                let points = cloud_points(&cloud).map_err(fail)?;
                (points.points, points.remission, points.dropped)
            }
        };
        check_some_finite(points.len(), dropped_points).map_err(|message| Error::Sequence {
            path: path.clone(),
            message,
        })?;
        Ok(Frame {
            index,
            stamp_ns: self.stamps_ns[index],
            world_from_velodyne: Isometry3::identity(),
            points_in_velodyne: points,
            remission,
            labels: None,
            camera: None,
            dropped_points,
            sensors: Vec::new(),
        })
    }
}
