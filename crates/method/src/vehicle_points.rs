//! Stage 0a, the vehicle's own points: a box in the sensor frame around the
//! recording vehicle's body, whose points are left out before anything else sees
//! the scan, so that the car never becomes an obstacle under its own sensor (a roof
//! LiDAR on nuScenes' car returns a quarter of its points from the car).
//!
//! The box is given (`vehicle.own_points_box_m`) or found by [`find_vehicle_box`]:
//! the voxels of the sensor frame that the surveyed scans fill nearly every time,
//! while the world under them moved, and whose points the world does not keep (seen
//! from elsewhere, the place a body point stood is empty: the body went on with the
//! vehicle). A wall the vehicle drives along fills the same voxels of the sensor
//! frame too, but it stays where it is in the world, so it is not taken; nor is the
//! ground, whose rings fill the same voxels on a flat road.
//!
//! Input: surveyed scans (points in the sensor frame, `world_from_sensor`). Output: a
//! [`VehicleBox`], which [`VehicleBox::remove_from`] applies to every scan.

use std::collections::{HashMap, HashSet};

use nalgebra::{Isometry3, Point3};
use rayon::prelude::*;
use travmap_core::frame::retain_points;

use crate::voxel_map::{KeyHash, pack};

/// Side of the sensor-frame voxels whose persistence is counted, metres.
const VOXEL_M: f32 = 0.2;
/// The body lies within this horizontal distance of the sensor, metres (a car is
/// at most ~5 m long with its sensor near the middle; a wall beyond is not weighed).
const REACH_M: f32 = 3.5;
/// A voxel is persistent when this share of the surveyed scans fill it.
const PERSISTENT_SHARE: f64 = 0.75;
/// Fewest scans, each at least [`SURVEY_SPACING_M`] from the others, that make a
/// survey: fewer, and a parked car beside a slow vehicle would look persistent.
pub const MIN_SURVEY_SCANS: usize = 4;
/// How far apart surveyed scans are taken, metres: farther than the vehicle is
/// long, so that where its body stood is seen from outside it.
pub const SURVEY_SPACING_M: f64 = 6.0;
/// Seen from another surveyed scan, a world point within this distance of a point
/// of that scan is kept by the world, metres.
const WORLD_SUPPORT_M: f32 = 0.3;
/// A persistent voxel is the vehicle's when at most this share of its world
/// positions are kept by the world (points far out of other scans' reach count as
/// neither).
const MAX_SUPPORTED_SHARE: f64 = 0.2;
/// Fewest body voxels that make a box; fewer is noise.
const MIN_BODY_VOXELS: usize = 4;
/// Voxels this close above the ground are the ground's: a beam draws the same ring
/// on flat ground in every scan, and rings are too sparse for other scans to keep
/// every ring point, metres.
const ABOVE_GROUND_M: f32 = 0.25;

/// An axis-aligned box in the sensor frame, metres.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct VehicleBox {
    pub min_m: [f32; 3],
    pub max_m: [f32; 3],
}

impl VehicleBox {
    /// The box of `[xmin, ymin, zmin, xmax, ymax, zmax]`.
    pub fn from_corners(corners_m: [f64; 6]) -> Self {
        let c = corners_m.map(|v| v as f32);
        Self {
            min_m: [c[0], c[1], c[2]],
            max_m: [c[3], c[4], c[5]],
        }
    }

    pub fn contains(&self, p: &[f32; 4]) -> bool {
        (0..3).all(|i| p[i] >= self.min_m[i] && p[i] <= self.max_m[i])
    }

    /// Leaves out the points inside the box (and their labels, which stay in
    /// step); returns how many.
    pub fn remove_from(&self, points: &mut Vec<[f32; 4]>, labels: Option<&mut Vec<u32>>) -> usize {
        retain_points(points, labels, |p| !self.contains(p))
    }
}

type Voxel = [i32; 3];

fn voxel_of(p: [f32; 3], size_m: f32) -> Voxel {
    p.map(|v| (v / size_m).floor() as i32)
}

/// A voxel as one key of the fast hash (21 bits an axis: the sensor-frame voxels
/// near the body and the drive-frame voxels of a survey span far fewer).
fn key(v: Voxel) -> u64 {
    pack(v.map(|i| i as u64))
}

/// Keys of voxels, hashed fast: a survey's scans hold about a million points.
type VoxelKeys = HashSet<u64, KeyHash>;

/// A point's squared horizontal distance from the sensor: compared with squared
/// distances, as `hypot` costs more than the rest of a million points' work.
fn horizontal_sq(p: &[f32; 4]) -> f32 {
    p[0] * p[0] + p[1] * p[1]
}

fn centre_of(v: Voxel) -> [f32; 3] {
    v.map(|i| (i as f32 + 0.5) * VOXEL_M)
}

/// The box of the vehicle's own points, found in `scans` (points in the sensor
/// frame, each scan's `world_from_sensor`), taken at least [`SURVEY_SPACING_M`]
/// apart; None when they are too few or show no body.
pub fn find_vehicle_box(scans: &[(Isometry3<f64>, &[[f32; 4]])]) -> Option<VehicleBox> {
    if scans.len() < MIN_SURVEY_SCANS {
        return None;
    }
    // 1. How many scans fill each voxel of the sensor frame near the sensor.
    let near: Vec<HashSet<Voxel, KeyHash>> = (scans.par_iter())
        .map(|(_, points)| {
            (points.iter())
                .filter(|p| horizontal_sq(p) <= REACH_M * REACH_M)
                .map(|p| voxel_of([p[0], p[1], p[2]], VOXEL_M))
                .collect()
        })
        .collect();
    let mut filled: HashMap<Voxel, usize, KeyHash> = HashMap::default();
    for voxel in near.into_iter().flatten() {
        *filled.entry(voxel).or_default() += 1;
    }
    let needed = (PERSISTENT_SHARE * scans.len() as f64).ceil() as usize;
    let floor_m = ground_z_m(scans)? + ABOVE_GROUND_M;
    let persistent: Vec<Voxel> = filled
        .into_iter()
        .filter(|(voxel, count)| *count >= needed && voxel[2] as f32 * VOXEL_M >= floor_m)
        .map(|(voxel, _)| voxel)
        .collect();
    if persistent.is_empty() {
        return None;
    }
    // 2. Which of them the world keeps: each scan's points by world voxel.
    let support_voxel = |p: [f32; 3]| voxel_of(p, WORLD_SUPPORT_M);
    // And by 1 m columns: where a scan saw anything at all (a body's old place is
    // seen as the road under it; a wall beyond a scan's reach is not seen).
    let column_of =
        |v: Voxel| [v[0], v[1]].map(|i| ((i as f32 + 0.5) * WORLD_SUPPORT_M).floor() as i32);
    // Only the world around the surveyed sensors is asked about: a persistent
    // voxel's places lie as far from a sensor as the voxel from the sensor frame's
    // origin, and a place asks about points within 2.2 m of it along x and y.
    let reach_m = (persistent.iter())
        .map(|&v| centre_of(v).map(f64::from))
        .map(|c| (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt())
        .fold(0.0, f64::max)
        + 3.0;
    let sensors_in_world: Vec<[f64; 2]> = (scans.iter())
        .map(|(world_from_sensor, _)| world_from_sensor.translation.vector.xy().into())
        .collect();
    let asked_about = |w: &Point3<f64>| {
        (sensors_in_world.iter())
            .any(|s| (w.x - s[0]).abs() <= reach_m && (w.y - s[1]).abs() <= reach_m)
    };
    let (world, columns): (Vec<VoxelKeys>, Vec<VoxelKeys>) = (scans.par_iter())
        .map(|(world_from_sensor, points)| {
            let (mut voxels, mut columns) = (VoxelKeys::default(), VoxelKeys::default());
            for p in points.iter() {
                let w = world_from_sensor * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                if !asked_about(&w) {
                    continue;
                }
                let voxel = support_voxel([w.x as f32, w.y as f32, w.z as f32]);
                let [x, y] = column_of(voxel);
                voxels.insert(key(voxel));
                columns.insert(key([x, y, 0]));
            }
            (voxels, columns)
        })
        .unzip();
    let sees = |scan: usize, w: [f32; 3]| {
        let c = [w[0].floor() as i32, w[1].floor() as i32];
        (-1..=1)
            .any(|dx| (-1..=1).any(|dy| columns[scan].contains(&key([c[0] + dx, c[1] + dy, 0]))))
    };
    let kept_by = |scan: usize, w: [f32; 3]| {
        let v = support_voxel(w);
        (-1..=1).any(|dx| {
            (-1..=1).any(|dy| {
                (-1..=1).any(|dz| world[scan].contains(&key([v[0] + dx, v[1] + dy, v[2] + dz])))
            })
        })
    };
    let body: Vec<Voxel> = persistent
        .into_iter()
        .filter(|&voxel| {
            let c = centre_of(voxel);
            let (mut seen, mut kept) = (0usize, 0usize);
            for (j, (world_from_j, _)) in scans.iter().enumerate() {
                let w = world_from_j * Point3::new(c[0] as f64, c[1] as f64, c[2] as f64);
                for (k, (world_from_k, _)) in scans.iter().enumerate() {
                    let apart =
                        (world_from_k.translation.vector - world_from_j.translation.vector).norm();
                    // Another scan, taken outside the body's place, that saw the place.
                    let place = [w.x as f32, w.y as f32, w.z as f32];
                    if k == j || apart < SURVEY_SPACING_M * 0.5 || !sees(k, place) {
                        continue;
                    }
                    seen += 1;
                    kept += usize::from(kept_by(k, [w.x as f32, w.y as f32, w.z as f32]));
                }
            }
            seen > 0 && (kept as f64) <= MAX_SUPPORTED_SHARE * seen as f64
        })
        .collect();
    if body.len() < MIN_BODY_VOXELS {
        return None;
    }
    let mut min_m = [f32::INFINITY; 3];
    let mut max_m = [f32::NEG_INFINITY; 3];
    for voxel in body {
        let lower = voxel.map(|i| i as f32 * VOXEL_M);
        for axis in 0..3 {
            min_m[axis] = min_m[axis].min(lower[axis]);
            max_m[axis] = max_m[axis].max(lower[axis] + VOXEL_M);
        }
    }
    Some(VehicleBox { min_m, max_m })
}

/// The ground's height in the sensor frame (z up): the 10th percentile of the
/// heights of the surveyed points beyond the body's reach, within 15 m.
fn ground_z_m(scans: &[(Isometry3<f64>, &[[f32; 4]])]) -> Option<f32> {
    let mut heights: Vec<f32> = scans
        .iter()
        .flat_map(|(_, points)| points.iter())
        .filter(|p| (REACH_M * REACH_M..=225.0).contains(&horizontal_sq(p)) && p[2].is_finite())
        .map(|p| p[2])
        .collect();
    if heights.is_empty() {
        return None;
    }
    let at = heights.len() / 10;
    Some(*heights.select_nth_unstable_by(at, f32::total_cmp).1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    /// A drive along x past a wall 2.5 m to its left, over flat ground 1.8 m below
    /// the sensor, with a body (a roof slab under the sensor) in every scan.
    fn drive(with_body: bool) -> Vec<(Isometry3<f64>, Vec<[f32; 4]>)> {
        (0..6)
            .map(|step| {
                let x0 = step as f64 * SURVEY_SPACING_M;
                let world_from_sensor = Isometry3::from_parts(
                    Translation3::new(x0, 0.0, 1.8),
                    UnitQuaternion::identity(),
                );
                let mut points = Vec::new();
                // The ground, rings the beams draw: the same sensor-frame voxels in
                // every scan, kept by the world (every scan sees the road).
                for ring in [3.0f32, 4.0, 6.0, 9.0] {
                    for k in 0..360 {
                        let a = (k as f32).to_radians();
                        points.push([ring * a.cos(), ring * a.sin(), -1.8, 0.1]);
                    }
                }
                // The wall along the whole drive in the world, 2.5 m to the left, 0 to
                // 2 m high: each scan sees the 12 m of it nearest.
                for world_x in -100..450 {
                    let x = world_x as f32 * 0.1 - x0 as f32;
                    if x.abs() > 6.0 {
                        continue;
                    }
                    for dz in 0..10 {
                        points.push([x, 2.5, -1.8 + dz as f32 * 0.2, 0.3]);
                    }
                }
                if with_body {
                    for ix in -10..10 {
                        for iy in -4..4 {
                            points.push([ix as f32 * 0.1, iy as f32 * 0.1, -0.4, 0.5]);
                        }
                    }
                }
                (world_from_sensor, points)
            })
            .collect()
    }

    fn found(scans: &[(Isometry3<f64>, Vec<[f32; 4]>)]) -> Option<VehicleBox> {
        let borrowed: Vec<_> = scans
            .iter()
            .map(|(pose, p)| (*pose, p.as_slice()))
            .collect();
        find_vehicle_box(&borrowed)
    }

    #[test]
    fn the_body_is_found_and_the_wall_and_the_ground_are_not() {
        let body = found(&drive(true)).expect("a body in every scan");
        assert!(body.min_m[0] <= -1.0 && body.max_m[0] >= 0.9, "{body:?}");
        assert!(body.min_m[1] <= -0.4 && body.max_m[1] >= 0.3, "{body:?}");
        assert!(body.min_m[2] <= -0.4 && body.max_m[2] >= -0.4, "{body:?}");
        // Neither the wall (y 2.5) nor the ground (z -1.8) is in it.
        assert!(body.max_m[1] < 2.4 && body.min_m[2] > -1.7, "{body:?}");
        assert_eq!(found(&drive(false)), None, "no body, no box");
    }

    #[test]
    fn too_few_scans_find_nothing_and_the_box_leaves_its_points_out() {
        let scans = drive(true);
        assert_eq!(found(&scans[..MIN_SURVEY_SCANS - 1]), None);
        let body = VehicleBox::from_corners([-1.0, -0.5, -0.5, 1.0, 0.5, -0.3]);
        let mut points = vec![
            [0.0, 0.0, -0.4, 1.0],
            [5.0, 0.0, -0.4, 1.0],
            [0.5, 0.2, -0.35, 1.0],
        ];
        let mut labels = vec![31, 40, 31];
        assert_eq!(body.remove_from(&mut points, Some(&mut labels)), 2);
        assert_eq!(points, vec![[5.0, 0.0, -0.4, 1.0]]);
        assert_eq!(labels, vec![40]);
    }
}
