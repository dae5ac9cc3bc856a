//! What the readers produce and the method consumes: a [`Frame`] (one LiDAR scan
//! with its pose, stamp, labels) and its [`CameraImage`]. Nothing here reads a file.

use nalgebra::{Isometry3, Matrix3, Matrix3x4, Matrix4};

use crate::config::RemissionScaling;
use crate::lens::Distortion;

/// One LiDAR scan with everything the method needs about it.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Frame number in its sequence (the file stem).
    pub index: usize,
    /// Time since the start of the sequence, nanoseconds.
    pub stamp_ns: u64,
    /// Sensor pose: maps velodyne coordinates to the z-up world frame.
    pub world_from_velodyne: Isometry3<f64>,
    /// x, y, z (metres) and remission per point, in the velodyne frame; remission
    /// on a 0..1 scale when `remission` says it is usable, else 0.
    pub points_in_velodyne: Vec<[f32; 4]>,
    /// What the input's remission / intensity was, and so whether it is usable.
    pub remission: RemissionScale,
    /// SemanticKITTI label per point (lower 16 bits class, upper 16 instance).
    pub labels: Option<Vec<u32>>,
    /// The colour camera's image of this frame, when the input has one.
    pub camera: Option<CameraImage>,
    /// Points the reader dropped as no return: a NaN or infinite coordinate, or the
    /// sensor's origin (`io::cloud::is_return`).
    pub dropped_points: usize,
    /// The cloud topics whose points the frame holds, when several sensors are
    /// merged (`--cloud-topic all`); empty for an input of one sensor.
    pub sensors: Vec<String>,
}

impl Frame {
    /// SHA-256 of the scan's points (and labels), hex: which scan this is by its
    /// content, however the input is spelled or stored (a KITTI file, an MCAP copy).
    pub fn content_sha256(&self) -> String {
        use sha2::{Digest, Sha256};
        let mut hash = Sha256::new();
        for p in &self.points_in_velodyne {
            for v in &p[..3] {
                hash.update(v.to_le_bytes());
            }
        }
        for label in self.labels.iter().flatten() {
            hash.update(label.to_le_bytes());
        }
        hash.finalize().iter().map(|b| format!("{b:02x}")).collect()
    }
}

/// The scale an input's remission / intensity came on. Readers bring every usable
/// scale to 0..1 (KITTI's own): remission features mean the same on every sensor.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RemissionScale {
    /// 0..1 as recorded (KITTI `.bin`, float intensity that never exceeds 1).
    Unit,
    /// 0..255 (Velodyne drivers: uint8, or float up to 255), divided by 255.
    Byte,
    /// No intensity field.
    Missing,
    /// An intensity field on a scale travmap does not know (a uint16 photon count,
    /// LAS intensity of 8, 12 or 16 bits): only its order within a scan means
    /// anything.
    Unknown,
}

impl RemissionScale {
    /// Whether remission features can be computed from it when each scan's
    /// remission is scaled as `scaling` says: an unknown scale only where each scan
    /// is ranked or scaled by itself.
    pub fn is_usable(self, scaling: RemissionScaling) -> bool {
        match self {
            RemissionScale::Unit | RemissionScale::Byte => true,
            RemissionScale::Missing => false,
            RemissionScale::Unknown => scaling != RemissionScaling::AsRead,
        }
    }
}

/// Keeps the points `keep` accepts, and their labels with them, so that labels stay
/// one a point; returns how many points were left out.
pub fn retain_points(
    points: &mut Vec<[f32; 4]>,
    labels: Option<&mut Vec<u32>>,
    keep: impl Fn(&[f32; 4]) -> bool,
) -> usize {
    if let Some(labels) = labels {
        let mut index = 0;
        labels.retain(|_| {
            index += 1;
            keep(&points[index - 1])
        });
    }
    let before = points.len();
    points.retain(|p| keep(p));
    before - points.len()
}

/// A decoded 8-bit RGB image, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbImage {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
}

/// The colour camera of a frame and its image.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraImage {
    /// `P2 * Tr`: homogeneous velodyne coordinates to homogeneous pixels, as a
    /// pinhole camera (a rectified image) sees them.
    pub image_from_velodyne: Matrix3x4<f64>,
    /// A raw image's lens, when it bends rays: then points are projected through it.
    pub lens: Option<Lens>,
    pub image: RgbImage,
}

/// A camera whose lens distorts: its pose, intrinsics and distortion, applied in
/// that order.
#[derive(Clone, Debug, PartialEq)]
pub struct Lens {
    pub camera_from_velodyne: Matrix3x4<f64>,
    pub k: Matrix3<f64>,
    pub distortion: Distortion,
}

impl CameraImage {
    pub fn new(
        projection: &Matrix4<f64>,
        cam0_from_velodyne: &Matrix4<f64>,
        image: RgbImage,
    ) -> Self {
        let p = projection * cam0_from_velodyne;
        Self {
            image_from_velodyne: p.fixed_view::<3, 4>(0, 0).into_owned(),
            lens: None,
            image,
        }
    }

    /// From intrinsics K, the lens's distortion (None: a pinhole) and the camera's
    /// pose: `K [R | t]` with `[R | t]` = `camera_from_velodyne`.
    pub fn from_intrinsics(
        k: &Matrix3<f64>,
        distortion: Option<Distortion>,
        camera_from_velodyne: &Isometry3<f64>,
        image: RgbImage,
    ) -> Self {
        let extrinsics: Matrix3x4<f64> = camera_from_velodyne
            .to_homogeneous()
            .fixed_view::<3, 4>(0, 0)
            .into_owned();
        Self {
            image_from_velodyne: k * extrinsics,
            lens: distortion.map(|distortion| Lens {
                camera_from_velodyne: extrinsics,
                k: *k,
                distortion,
            }),
            image,
        }
    }

    /// Pixel coordinates (x right, y down; pixel (i, j) spans [i, i+1) x [j, j+1)) of a
    /// velodyne point, None behind (or within 1 mm of) the camera plane, or where
    /// the lens model folds back.
    pub fn project(&self, p: [f64; 3]) -> Option<[f64; 2]> {
        let (m, lens) = match &self.lens {
            None => (&self.image_from_velodyne, None),
            Some(lens) => (&lens.camera_from_velodyne, Some(lens)),
        };
        let row = |r: usize| m[(r, 0)] * p[0] + m[(r, 1)] * p[1] + m[(r, 2)] * p[2] + m[(r, 3)];
        let w = row(2);
        (w > 1e-3).then_some(())?;
        let Some(lens) = lens else {
            return Some([row(0) / w, row(1) / w]);
        };
        let [x, y] = lens.distortion.distort([row(0) / w, row(1) / w])?;
        let k = &lens.k;
        Some([
            k[(0, 0)] * x + k[(0, 1)] * y + k[(0, 2)],
            k[(1, 1)] * y + k[(1, 2)],
        ])
    }
}
