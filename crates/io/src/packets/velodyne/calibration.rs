//! Velodyne calibrations: each laser's elevation, azimuth correction and offsets,
//! built in for the fixed-geometry models or read from velodyne_pointcloud's YAML.

use std::f64::consts::PI;
use travmap_core::option_files::{TEXT_MAX_BYTES, read_option_text};

use serde::Deserialize;

use super::packet::VelodyneModel;

/// One laser's corrections.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Laser {
    pub(super) sin_vert: f32,
    pub(super) cos_vert: f32,
    /// The azimuth correction in 0.01 degree, subtracted from the firing's azimuth.
    pub(super) rot_centideg: f64,
    pub(super) dist_correction_m: f32,
    pub(super) vert_offset_m: f32,
    pub(super) horiz_offset_m: f32,
    /// Rank by elevation: ring 0 is the lowest beam.
    pub(super) ring: u16,
}

/// A sensor's calibration: its lasers' angles and offsets, by laser id.
#[derive(Clone, Debug, PartialEq)]
pub struct VelodyneCalibration {
    pub(super) lasers: Vec<Laser>,
    pub(super) distance_resolution_m: f32,
}

/// velodyne_pointcloud's and nebula's calibration YAML.
#[derive(Deserialize)]
struct CalibrationFile {
    lasers: Vec<LaserEntry>,
    distance_resolution: Option<f64>,
}

#[derive(Deserialize)]
struct LaserEntry {
    laser_id: usize,
    rot_correction: f64,
    vert_correction: f64,
    #[serde(default)]
    dist_correction: f64,
    #[serde(default)]
    vert_offset_correction: f64,
    #[serde(default)]
    horiz_offset_correction: f64,
}

/// VLP-16 elevations by laser id, degrees (the manual's table): every 2 degrees,
/// interleaved.
const VLP16_ELEVATION_DEG: [f64; 16] = [
    -15.0, 1.0, -13.0, 3.0, -11.0, 5.0, -9.0, 7.0, -7.0, 9.0, -5.0, 11.0, -3.0, 13.0, -1.0, 15.0,
];
/// VLP-32C elevations and azimuth offsets by laser id, degrees (the manual's table).
const VLP32C_ELEVATION_DEG: [f64; 32] = [
    -25.0, -1.0, -1.667, -15.639, -11.31, 0.0, -0.667, -8.843, -7.254, 0.333, -0.333, -6.148,
    -5.333, 1.333, 0.667, -4.0, -4.667, 1.667, 1.0, -3.667, -3.333, 3.333, 2.333, -2.667, -3.0,
    7.0, 4.667, -2.333, -2.0, 15.0, 10.333, -1.333,
];
const VLP32C_AZIMUTH_OFFSET_DEG: [f64; 32] = [
    1.4, -4.2, 1.4, -1.4, 1.4, -1.4, 4.2, -1.4, 1.4, -4.2, 1.4, -1.4, 4.2, -1.4, 4.2, -1.4, 1.4,
    -4.2, 1.4, -4.2, 4.2, -1.4, 1.4, -1.4, 1.4, -1.4, 1.4, -4.2, 4.2, -1.4, 1.4, -1.4,
];

impl VelodyneCalibration {
    /// The model's own table, for the models whose geometry is fixed (VLP-16,
    /// VLP-32C); the others need a calibration file.
    pub fn builtin(model: VelodyneModel) -> Option<Self> {
        let (elevations, offsets, resolution): (&[f64], &[f64], f64) = match model {
            VelodyneModel::Vlp16 => (&VLP16_ELEVATION_DEG, &[0.0; 16], 0.002),
            VelodyneModel::Vlp32c => (&VLP32C_ELEVATION_DEG, &VLP32C_AZIMUTH_OFFSET_DEG, 0.004),
            VelodyneModel::Hdl32e | VelodyneModel::Vls128 => return None,
        };
        let entries = elevations
            .iter()
            .zip(offsets)
            .enumerate()
            .map(|(laser_id, (elevation, offset))| LaserEntry {
                laser_id,
                // The YAML's rot_correction is subtracted: minus the manual's offset.
                rot_correction: -offset.to_radians(),
                vert_correction: elevation.to_radians(),
                dist_correction: 0.0,
                vert_offset_correction: 0.0,
                horiz_offset_correction: 0.0,
            })
            .collect();
        Self::of_entries(entries, resolution).ok()
    }

    /// A velodyne_pointcloud / nebula calibration YAML (`lasers:` with `laser_id`,
    /// `rot_correction`, `vert_correction` in radians, offsets in metres;
    /// `distance_resolution`).
    pub fn from_yaml(text: &str) -> Result<Self, String> {
        let file: CalibrationFile = crate::yaml::from_str(text)?;
        Self::of_entries(file.lasers, file.distance_resolution.unwrap_or(0.002))
    }

    fn of_entries(mut entries: Vec<LaserEntry>, resolution_m: f64) -> Result<Self, String> {
        entries.sort_by_key(|e| e.laser_id);
        for (expected, entry) in entries.iter().enumerate() {
            if entry.laser_id != expected {
                return Err(format!(
                    "laser ids must run 0..{} without gaps; laser {expected} is missing",
                    entries.len()
                ));
            }
        }
        let mut by_elevation: Vec<usize> = (0..entries.len()).collect();
        by_elevation.sort_by(|&a, &b| {
            entries[a]
                .vert_correction
                .total_cmp(&entries[b].vert_correction)
        });
        let mut rings = vec![0u16; entries.len()];
        for (ring, &laser) in by_elevation.iter().enumerate() {
            rings[laser] = ring as u16;
        }
        let lasers = entries
            .iter()
            .zip(rings)
            .map(|(e, ring)| {
                let vert = e.vert_correction as f32;
                Laser {
                    sin_vert: vert.sin(),
                    cos_vert: vert.cos(),
                    rot_centideg: e.rot_correction * 180.0 / PI * 100.0,
                    dist_correction_m: e.dist_correction as f32,
                    vert_offset_m: e.vert_offset_correction as f32,
                    horiz_offset_m: e.horiz_offset_correction as f32,
                    ring,
                }
            })
            .collect();
        Ok(Self {
            lasers,
            distance_resolution_m: resolution_m as f32,
        })
    }

    /// The calibration of `model`: the YAML `file` when given, else the model's own
    /// table; refused when its laser count is not the model's.
    pub fn for_model(model: VelodyneModel, file: Option<&std::path::Path>) -> Result<Self, String> {
        let calibration = match file {
            Some(file) => {
                let text = read_option_text(file, TEXT_MAX_BYTES)
                    .map_err(|e| format!("cannot read --lidar-calibration: {e}"))?;
                Self::from_yaml(&text)
                    .map_err(|e| format!("--lidar-calibration {}: {e}", file.display()))?
            }
            None => Self::builtin(model).ok_or_else(|| {
                format!(
                    "the {} has no built-in angle table: pass its calibration with --lidar-calibration FILE (velodyne_pointcloud / nebula YAML)",
                    model.name()
                )
            })?,
        };
        if calibration.lasers() != model.lasers() {
            return Err(format!(
                "the packets are from a {} ({} lasers), the calibration has {} lasers",
                model.name(),
                model.lasers(),
                calibration.lasers()
            ));
        }
        Ok(calibration)
    }

    pub fn lasers(&self) -> usize {
        self.lasers.len()
    }
}
