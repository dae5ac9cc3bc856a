//! KITTI odometry / SemanticKITTI sequence directories (METHOD.md section 1):
//! `velodyne/NNNNNN.bin`, optional `labels/NNNNNN.label` and `image_2/NNNNNN.png`,
//! `calib.txt`, `poses.txt`, `times.txt`. Output: per frame the scan in the velodyne
//! frame, its labels, its camera image, its stamp and `world_from_velodyne`, where
//! `world` is the first scan's z-up velodyne frame. Every malformed input is an
//! [`Error`] naming the file.
//!
//! Other datasets laid out as KITTI's (nuScenes-lidarseg as its conversions ship it)
//! bend three of its rules, and each is told from the files and said in a notice:
//! labels of one byte a point, intensity on 0-255, and no `calib.txt` or `times.txt`.

pub(crate) mod text;

use std::io::Read;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use nalgebra::{Isometry3, Matrix4};
use rayon::prelude::*;

pub use crate::kitti::text::{KittiCalibration, read_calibration, read_poses, read_times};
use crate::payloads::cloud::{check_some_finite, is_return};
use crate::payloads::image::decode_png;
use travmap_core::error::{Error, Result};
use travmap_core::frame::{Frame, RemissionScale, retain_points};
use travmap_core::geometry::rigid;

/// How wide a sequence's label files are, told from their size against the scan's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LabelWidth {
    /// SemanticKITTI's: a little-endian uint32 a point (class in the lower 16 bits).
    U32,
    /// One byte a point: nuScenes-lidarseg's ids, as its KITTI-layout conversions
    /// store them.
    U8,
}

/// The rate stamps are made at when `times.txt` is missing: KITTI's scans.
const DEFAULT_RATE_HZ: f64 = 10.0;
/// ... and nuScenes-lidarseg's, whose labelled scans are its 2 Hz keyframes.
const KEYFRAME_RATE_HZ: f64 = 2.0;

/// An opened sequence: calibration, poses and times are read at once, scans on demand.
#[derive(Clone, Debug)]
pub struct KittiSequence {
    dir: PathBuf,
    calibration: KittiCalibration,
    /// `pose_i` of poses.txt: cam0 of frame i in the first cam0 frame.
    first_cam0_from_cam0: Vec<Matrix4<f64>>,
    /// `world_from_velodyne` of every pose, once asked for ([`Self::recorded_poses`]):
    /// a drive asks several times, and each of a sequence's 4,541 costs 2 us.
    world_from_velodyne: OnceLock<Vec<Isometry3<f64>>>,
    stamps_ns: Vec<u64>,
    /// Frame numbers that have a `velodyne/NNNNNN.bin`, ascending.
    frames: Vec<usize>,
    /// Decode `image_2` PNGs into frames (when P2 is known).
    read_images: bool,
    /// Read `labels/` (false: the frames come without labels, as unlabelled drives).
    read_labels: bool,
    label_width: LabelWidth,
    /// The scale of the scans' fourth value, told from the first scan.
    remission: RemissionScale,
}

impl KittiSequence {
    /// Opens `dir`, a directory holding `velodyne/`, `calib.txt`, `poses.txt`,
    /// `times.txt`. Without `calib.txt` the poses are the LiDAR's own (`Tr` the
    /// identity) and there is no camera; without `times.txt` the scans are stamped at
    /// `rate_hz` (10 Hz, or 2 Hz for nuScenes-lidarseg's keyframes, told by their
    /// one-byte labels). `on_notice` hears each thing assumed.
    pub fn open(dir: &Path, rate_hz: Option<f64>, on_notice: &dyn Fn(&str)) -> Result<Self> {
        if !dir.is_dir() {
            return Err(Error::Sequence {
                path: dir.to_path_buf(),
                message: "not a directory; expected a KITTI sequence directory holding \
                          velodyne/, calib.txt, poses.txt and times.txt"
                    .into(),
            });
        }
        let said = |notice: String| on_notice(&format!("{}: {notice}", dir.display()));
        let calib_path = dir.join("calib.txt");
        let calibration = if calib_path.exists() {
            read_calibration(&calib_path)?
        } else {
            said("no calib.txt: the poses in poses.txt are taken as the LiDAR's own, and there is no camera".into());
            KittiCalibration::lidar_alone()
        };
        let first_cam0_from_cam0 = read_poses(&dir.join("poses.txt"))?;
        let frames = list_scans(&dir.join("velodyne"))?;
        let label_width = label_width(dir, &frames)?;
        if label_width == LabelWidth::U8 {
            said("labels of one byte a point (nuScenes-lidarseg's ids, as its KITTI-layout conversions store them), told from their size".into());
        }
        let times_path = dir.join("times.txt");
        let stamps_ns = if times_path.exists() {
            if let Some(rate_hz) = rate_hz {
                said(format!(
                    "times.txt gives the scans' stamps: --rate {rate_hz} is not used"
                ));
            }
            read_times(&times_path)?
        } else {
            let (rate_hz, why) = match (rate_hz, label_width) {
                (Some(rate_hz), _) => (rate_hz, "as --rate says"),
                (None, LabelWidth::U8) => (
                    KEYFRAME_RATE_HZ,
                    "nuScenes-lidarseg's keyframes; --rate to set",
                ),
                (None, LabelWidth::U32) => (DEFAULT_RATE_HZ, "KITTI's rate; --rate to set"),
            };
            said(format!(
                "no times.txt: the scans stamped at {rate_hz} Hz ({why})"
            ));
            let last = frames.last().map_or(0, |last| last + 1);
            (0..last.max(first_cam0_from_cam0.len()))
                .map(|i| (i as f64 * 1e9 / rate_hz).round() as u64)
                .collect()
        };
        let remission = match frames.first() {
            Some(first) => remission_scale(&dir.join("velodyne").join(format!("{first:06}.bin")))?,
            None => RemissionScale::Unit,
        };
        if remission == RemissionScale::Byte {
            said("intensity on 0-255 (not KITTI's 0..1 remission): divided by 255".into());
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            calibration,
            first_cam0_from_cam0,
            world_from_velodyne: OnceLock::new(),
            stamps_ns,
            frames,
            read_images: true,
            read_labels: true,
            label_width,
            remission,
        })
    }

    /// Whether [`Self::read_frame`] decodes `image_2` (default true); decoding costs
    /// more than the rest of the method, so it is skipped when appearance is off.
    pub fn set_read_images(&mut self, read_images: bool) {
        self.read_images = read_images;
    }

    /// Whether [`Self::read_frame`] reads `labels/` (default true).
    pub fn set_read_labels(&mut self, read_labels: bool) {
        self.read_labels = read_labels;
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn calibration(&self) -> &KittiCalibration {
        &self.calibration
    }

    /// Frame numbers with a scan inside `range`.
    pub fn frames_in(&self, range: &Range<usize>) -> Vec<usize> {
        self.frames
            .iter()
            .copied()
            .filter(|f| range.contains(f))
            .collect()
    }

    /// `T_world_velo(i) = inv(Tr) * pose_i * Tr` (METHOD.md section 1): the pose file
    /// holds cam0 poses, and the world is the first scan's velodyne frame, so that the
    /// ground is the world x-y plane.
    pub fn world_from_velodyne(&self, index: usize) -> Result<Isometry3<f64>> {
        let pose = self
            .first_cam0_from_cam0
            .get(index)
            .ok_or_else(|| Error::MissingPose {
                path: self.dir.join("poses.txt"),
                frame: index,
                lines: self.first_cam0_from_cam0.len(),
            })?;
        Ok(rigid(
            &(self.velodyne_from_cam0()? * pose * self.calibration.cam0_from_velodyne),
        ))
    }

    fn velodyne_from_cam0(&self) -> Result<Matrix4<f64>> {
        (self.calibration.cam0_from_velodyne.try_inverse()).ok_or_else(|| Error::Parse {
            path: self.dir.join("calib.txt"),
            line: 0,
            message: "Tr is not invertible".into(),
        })
    }

    /// Every pose poses.txt holds, frame number and `world_from_velodyne`: also
    /// those of frames past the last scan here.
    pub fn recorded_poses(&self) -> Result<Vec<(usize, Isometry3<f64>)>> {
        if self.world_from_velodyne.get().is_none() {
            let (velodyne_from_cam0, tr) = (
                self.velodyne_from_cam0()?,
                self.calibration.cam0_from_velodyne,
            );
            let poses = (self.first_cam0_from_cam0.par_iter())
                .map(|pose| rigid(&(velodyne_from_cam0 * pose * tr)))
                .collect();
            // Another thread may have laid them first: the same poses.
            let _ = self.world_from_velodyne.set(poses);
        }
        let poses = self.world_from_velodyne.get().expect("laid above");
        Ok(poses.iter().copied().enumerate().collect())
    }

    pub fn stamp_ns(&self, index: usize) -> Result<u64> {
        self.stamps_ns
            .get(index)
            .copied()
            .ok_or_else(|| Error::MissingTime {
                path: self.dir.join("times.txt"),
                frame: index,
                lines: self.stamps_ns.len(),
            })
    }

    /// Reads frame `index`: scan, labels when present, pose and stamp.
    pub fn read_frame(&self, index: usize) -> Result<Frame> {
        let scan_path = self.scan_path(index);
        let mut points_in_velodyne = read_scan(&scan_path)?;
        if self.remission == RemissionScale::Byte {
            for point in &mut points_in_velodyne {
                point[3] /= 255.0;
            }
        }
        let label_path = self.label_path(index);
        let mut labels = if self.read_labels && label_path.is_file() {
            let points = points_in_velodyne.len();
            let bytes = crate::format::read_data_file(&label_path)?;
            Some(match self.label_width {
                LabelWidth::U32 => parse_labels(&bytes, &label_path, &scan_path, points)?,
                LabelWidth::U8 => parse_byte_labels(&bytes, &label_path, &scan_path, points)?,
            })
        } else {
            None
        };
        let dropped_points = drop_non_returns(&mut points_in_velodyne, labels.as_mut());
        check_some_finite(points_in_velodyne.len(), dropped_points).map_err(|message| {
            Error::Sequence {
                path: scan_path.clone(),
                message,
            }
        })?;
        let camera = match (self.read_images, self.image_path(index)) {
            (true, Some(_)) if self.calibration.projections[2].is_none() => {
                return Err(Error::MissingCalibration {
                    path: self.dir.join("calib.txt"),
                    key: "P2",
                    hint: " for the images in image_2/ (--set appearance.enabled=false ignores them)",
                });
            }
            (true, Some(path)) => {
                let bytes = crate::format::read_data_file(&path)?;
                self.calibration.camera_2_image(decode_png(&bytes, &path)?)
            }
            _ => None,
        };
        Ok(Frame {
            index,
            stamp_ns: self.stamp_ns(index)?,
            world_from_velodyne: self.world_from_velodyne(index)?,
            points_in_velodyne,
            remission: self.remission,
            labels,
            camera,
            dropped_points,
            sensors: Vec::new(),
        })
    }

    /// `image_2/NNNNNN.png` of frame `index`, when it exists.
    pub fn image_path(&self, index: usize) -> Option<PathBuf> {
        let path = self.dir.join("image_2").join(format!("{index:06}.png"));
        path.is_file().then_some(path)
    }

    fn scan_path(&self, index: usize) -> PathBuf {
        self.dir.join("velodyne").join(format!("{index:06}.bin"))
    }

    fn label_path(&self, index: usize) -> PathBuf {
        self.dir.join("labels").join(format!("{index:06}.label"))
    }
}

/// Reads a KITTI `.bin` scan: little-endian float32 x, y, z, remission per point.
/// Every point is kept, non-finite ones too, so that labels still line up.
pub fn read_scan(path: &Path) -> Result<Vec<[f32; 4]>> {
    let io_error = |e| Error::io(path, e);
    crate::format::refuse_special(path)?;
    let mut file = std::fs::File::open(path).map_err(io_error)?;
    // Read straight into the points: a scan is 2 MB, and parsing a copy of the
    // file's bytes cost as much as reading them.
    let mut points = scan_buffer(file.metadata().map_err(io_error)?.len(), path)?;
    file.read_exact(bytemuck::cast_slice_mut(&mut points))
        .map_err(io_error)?;
    if file.read(&mut [0u8; 1]).map_err(io_error)? != 0 {
        return Err(Error::io(
            path,
            std::io::Error::other("the file grew while it was read"),
        ));
    }
    Ok(from_little_endian(points))
}

/// [`read_scan`] on the file's bytes; `path` names it in errors.
pub fn parse_scan(bytes: &[u8], path: &Path) -> Result<Vec<[f32; 4]>> {
    let mut points = scan_buffer(bytes.len() as u64, path)?;
    bytemuck::cast_slice_mut(&mut points).copy_from_slice(bytes);
    Ok(from_little_endian(points))
}

/// Room for the points of a scan file of `size_bytes`: a whole number of 16-byte
/// records, at least one.
fn scan_buffer(size_bytes: u64, path: &Path) -> Result<Vec<[f32; 4]>> {
    check_record_size(size_bytes, path, 16, "float32 x, y, z, remission per point")?;
    // An empty file is a scan that was never written, not a scan of nothing.
    if size_bytes == 0 {
        return Err(Error::EmptyScan {
            path: path.to_path_buf(),
        });
    }
    Ok(vec![[0f32; 4]; (size_bytes / 16) as usize])
}

/// Points whose bytes were stored little-endian, as this machine's numbers.
fn from_little_endian(mut points: Vec<[f32; 4]>) -> Vec<[f32; 4]> {
    if cfg!(target_endian = "big") {
        for value in points.as_flattened_mut() {
            *value = f32::from_bits(u32::from_le(value.to_bits()));
        }
    }
    points
}

/// A file of fixed-size records must be a whole number of them.
fn check_record_size(
    size_bytes: u64,
    path: &Path,
    record_bytes: u64,
    what: &'static str,
) -> Result<()> {
    if size_bytes.is_multiple_of(record_bytes) {
        return Ok(());
    }
    Err(Error::RecordSize {
        path: path.to_path_buf(),
        size_bytes,
        record_bytes,
        what,
    })
}

/// Removes the points that are no return ([`is_return`]: a NaN or infinite
/// coordinate, or the sensor's origin), and their labels, so that one bad return
/// costs one point, not the frame. Returns how many were removed.
pub fn drop_non_returns(points: &mut Vec<[f32; 4]>, labels: Option<&mut Vec<u32>>) -> usize {
    retain_points(points, labels, |p| is_return(p[0], p[1], p[2]))
}

/// A SemanticKITTI `.label` file's bytes (uint32 per point), its count checked;
/// `path` names it in errors.
pub fn parse_labels(
    bytes: &[u8],
    path: &Path,
    scan_path: &Path,
    points: usize,
) -> Result<Vec<u32>> {
    check_record_size(bytes.len() as u64, path, 4, "uint32 label per point")?;
    check_label_count(bytes.len() / 4, path, scan_path, points)?;
    Ok(bytes
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect())
}

/// One label a point, or an error naming both files.
fn check_label_count(labels: usize, path: &Path, scan_path: &Path, points: usize) -> Result<()> {
    if labels != points {
        return Err(Error::LabelCount {
            path: path.to_path_buf(),
            scan: scan_path.to_path_buf(),
            labels,
            points,
        });
    }
    Ok(())
}

/// One-byte labels (nuScenes-lidarseg's ids), widened to the uint32 of a
/// SemanticKITTI label; the count checked as [`parse_labels`] does.
pub fn parse_byte_labels(
    bytes: &[u8],
    path: &Path,
    scan_path: &Path,
    points: usize,
) -> Result<Vec<u32>> {
    check_label_count(bytes.len(), path, scan_path, points)?;
    Ok(bytes.iter().map(|&id| u32::from(id)).collect())
}

/// How wide the sequence's labels are: the first label file's size against its
/// scan's point count (one byte a point, or SemanticKITTI's four).
fn label_width(dir: &Path, frames: &[usize]) -> Result<LabelWidth> {
    let labelled = frames.iter().find_map(|frame| {
        let label = dir.join("labels").join(format!("{frame:06}.label"));
        let scan = dir.join("velodyne").join(format!("{frame:06}.bin"));
        Some((
            std::fs::metadata(&label).ok()?.len(),
            std::fs::metadata(&scan).ok()?.len(),
        ))
    });
    Ok(match labelled {
        // A one-point scan is the same either way; SemanticKITTI's is the default.
        Some((label_bytes, scan_bytes)) if label_bytes * 16 == scan_bytes && scan_bytes > 16 => {
            LabelWidth::U8
        }
        _ => LabelWidth::U32,
    })
}

/// The scale of a scan file's fourth value: KITTI's 0..1 remission, or a 0-255
/// intensity (nuScenes' conversions), told from its largest finite value.
fn remission_scale(scan_path: &Path) -> Result<RemissionScale> {
    let largest = read_scan(scan_path)?
        .iter()
        .map(|p| p[3])
        .filter(|v| v.is_finite())
        .fold(0f32, f32::max);
    Ok(match largest {
        ..=1.0 => RemissionScale::Unit,
        ..=255.0 => RemissionScale::Byte,
        _ => RemissionScale::Unknown,
    })
}

/// Frame numbers of the `NNNNNN.bin` files in `velodyne_dir`, ascending.
fn list_scans(velodyne_dir: &Path) -> Result<Vec<usize>> {
    let entries = std::fs::read_dir(velodyne_dir).map_err(|e| Error::io(velodyne_dir, e))?;
    let mut frames = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| Error::io(velodyne_dir, e))?;
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if let Some(stem) = name.strip_suffix(".bin")
            && let Ok(index) = stem.parse::<usize>()
        {
            frames.push(index);
        }
    }
    if frames.is_empty() {
        return Err(Error::Sequence {
            path: velodyne_dir.to_path_buf(),
            message: "no NNNNNN.bin scans".into(),
        });
    }
    frames.sort_unstable();
    Ok(frames)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        path
    }

    #[test]
    fn a_scan_is_read_as_little_endian_records_and_an_empty_one_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let values = [1.5f32, -2.0, 3.25, 0.5, f32::NAN, 0.0, 1e-30, 1.0];
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let points = read_scan(&write(dir.path(), "a.bin", &bytes)).unwrap();
        let bits = |p: &[[f32; 4]]| {
            p.as_flattened()
                .iter()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>()
        };
        let parsed = parse_scan(&bytes, Path::new("a.bin")).unwrap();
        assert_eq!(bits(&points), bits(&parsed));
        assert_eq!(bits(&points), values.map(f32::to_bits));
        let err = read_scan(&write(dir.path(), "b.bin", &[]))
            .unwrap_err()
            .to_string();
        assert!(err.contains("b.bin"), "{err}");
    }

    #[test]
    fn scan_size_must_be_a_multiple_of_16() {
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "a.bin", &[0u8; 20]);
        let err = read_scan(&path).unwrap_err().to_string();
        assert!(
            err.contains("a.bin") && err.contains("20 bytes") && err.contains("16"),
            "{err}"
        );
    }

    #[test]
    fn points_that_are_no_return_are_dropped_with_their_labels() {
        let mut points = vec![
            [1.0, 2.0, 3.0, 0.5],
            [1.0, f32::NAN, 3.0, 0.5],
            [4.0, 5.0, 6.0, 0.5],
            [f32::INFINITY, 0.0, 0.0, 0.5],
            // A NaN remission is harmless: the method never reads it.
            [7.0, 8.0, 9.0, f32::NAN],
            // A beam without a return, as an Ouster scan records it; the origin
            // on one axis only is a return.
            [0.0, -0.0, 0.0, 0.0],
            [0.0, 0.0, 1.5, 0.0],
        ];
        let mut labels = vec![10, 11, 12, 13, 14, 15, 16];
        assert_eq!(drop_non_returns(&mut points, Some(&mut labels)), 3);
        assert_eq!(labels, [10, 12, 14, 16]);
        assert_eq!(points[1], [4.0, 5.0, 6.0, 0.5]);
        assert_eq!(points.len(), 4);
    }

    #[test]
    fn label_count_must_match_point_count() {
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "a.label", &[0u8; 12]);
        let err = parse_labels(&std::fs::read(&path).unwrap(), &path, Path::new("a.bin"), 4)
            .unwrap_err()
            .to_string();
        assert!(err.contains("3 labels for 4 points"), "{err}");
    }

    #[test]
    fn calibration_without_tr_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let p = "P0: 1 0 0 0 0 1 0 0 0 0 1 0\n";
        let path = write(dir.path(), "calib.txt", p.as_bytes());
        let err = read_calibration(&path).unwrap_err().to_string();
        assert!(err.contains("calib.txt") && err.contains("`Tr:`"), "{err}");
        let path = write(dir.path(), "calib.txt", b"Tr: 1 0 0\n");
        let err = read_calibration(&path).unwrap_err().to_string();
        assert!(
            err.contains("calib.txt:1") && err.contains("found 3"),
            "{err}"
        );
    }

    #[test]
    fn times_must_increase() {
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "times.txt", b"0.0\n0.1\n0.1\n");
        let err = read_times(&path).unwrap_err().to_string();
        assert!(err.contains("times.txt:3"), "{err}");
        let path = write(dir.path(), "times.txt", b"0.0\n1.037359e-01\n");
        assert_eq!(read_times(&path).unwrap(), vec![0, 103_735_900]);
    }
}

#[cfg(test)]
mod camera_tests;
