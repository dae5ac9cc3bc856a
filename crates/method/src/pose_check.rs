//! Stage 0, posing: whether a drive's recorded poses agree with its scans. Poses
//! from a 2-D localisation (nuScenes' ego poses; many fleets' wheel odometry) leave
//! a scan's height and tilt to chance, and integrating such scans smears the ground
//! into steps that look like obstacles. Two consecutive scans moved into the world
//! by their poses should lay the same ground at the same height; how far apart they
//! lay it says whether the poses need refining by registration.
//!
//! Input: two scans (points in the sensor frame, `world_from_sensor`). Output: the
//! median height difference of the ground both see, metres.

use std::collections::HashMap;

use nalgebra::{Isometry3, Point3};

/// Side of the ground cells compared, metres.
const CELL_M: f64 = 1.0;
/// Ground seen between these distances from each sensor is compared (nearer is the
/// vehicle's, farther too sparse), metres.
const NEAR_M: f64 = 4.0;
const FAR_M: f64 = 20.0;
/// A cell's ground needs this many of a scan's points.
const MIN_POINTS: usize = 5;
/// Fewest cells both scans see for a verdict.
const MIN_CELLS: usize = 20;

/// The ground of one scan by world cell: the 10th percentile of the heights of
/// its points there (the ground under any clutter).
fn ground_by_cell(
    world_from_sensor: &Isometry3<f64>,
    points: &[[f32; 4]],
) -> HashMap<[i64; 2], f64> {
    let mut heights: HashMap<[i64; 2], Vec<f64>> = HashMap::new();
    for p in points {
        let range = (p[0] as f64).hypot(p[1] as f64);
        if !(NEAR_M..=FAR_M).contains(&range) {
            continue;
        }
        let w = world_from_sensor * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
        let cell = [(w.x / CELL_M).floor() as i64, (w.y / CELL_M).floor() as i64];
        heights.entry(cell).or_default().push(w.z);
    }
    heights
        .into_iter()
        .filter(|(_, z)| z.len() >= MIN_POINTS)
        .map(|(cell, mut z)| {
            let at = z.len() / 10;
            (cell, *z.select_nth_unstable_by(at, f64::total_cmp).1)
        })
        .collect()
}

/// The median absolute difference of the ground heights two scans lay in the cells
/// both see, metres; None when they share too little ground to say.
pub fn ground_disagreement_m(
    a: (&Isometry3<f64>, &[[f32; 4]]),
    b: (&Isometry3<f64>, &[[f32; 4]]),
) -> Option<f64> {
    let ground_a = ground_by_cell(a.0, a.1);
    let ground_b = ground_by_cell(b.0, b.1);
    let mut differences: Vec<f64> = ground_a
        .iter()
        .filter_map(|(cell, za)| Some((za - ground_b.get(cell)?).abs()))
        .collect();
    if differences.len() < MIN_CELLS {
        return None;
    }
    let middle = differences.len() / 2;
    Some(*differences.select_nth_unstable_by(middle, f64::total_cmp).1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    /// Flat ground 1.8 m below a sensor at `x`, sampled on a 0.25 m lattice.
    fn ground_scan() -> Vec<[f32; 4]> {
        let mut points = Vec::new();
        for ix in -80..80 {
            for iy in -80..80 {
                points.push([ix as f32 * 0.25, iy as f32 * 0.25, -1.8, 0.2]);
            }
        }
        points
    }

    fn pose(x: f64, z: f64, pitch: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(x, 0.0, z),
            UnitQuaternion::from_euler_angles(0.0, pitch, 0.0),
        )
    }

    #[test]
    fn scans_that_lay_one_ground_agree_and_a_height_or_a_tilt_disagrees() {
        let scan = ground_scan();
        let agree =
            ground_disagreement_m((&pose(0.0, 1.8, 0.0), &scan), (&pose(2.0, 1.8, 0.0), &scan));
        assert!(agree.unwrap() < 1e-9);
        let lifted =
            ground_disagreement_m((&pose(0.0, 1.8, 0.0), &scan), (&pose(2.0, 2.1, 0.0), &scan));
        assert!((lifted.unwrap() - 0.3).abs() < 1e-9);
        // One degree of pitch lifts the ground 0.17 m ten metres ahead.
        let tilted = ground_disagreement_m(
            (&pose(0.0, 1.8, 0.0), &scan),
            (&pose(2.0, 1.8, 1f64.to_radians()), &scan),
        );
        assert!(tilted.unwrap() > 0.05, "{tilted:?}");
        let apart = ground_disagreement_m(
            (&pose(0.0, 1.8, 0.0), &scan),
            (&pose(500.0, 1.8, 0.0), &scan),
        );
        assert_eq!(apart, None, "no shared ground, no verdict");
    }
}
