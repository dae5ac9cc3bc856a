//! Stage 0, posing: whether a drive's recorded poses agree with its scans. Poses
//! from a 2-D localisation (nuScenes' ego poses; many fleets' wheel odometry) leave
//! a scan's height and tilt to chance, and integrating such scans smears the ground
//! into steps that look like obstacles. Two consecutive scans moved into the world
//! by their poses should lay the same ground at the same height; how far apart they
//! lay it says whether the poses need refining by registration.
//!
//! Input: scans (points in the sensor frame, `world_from_sensor`), each laid as a
//! [`ScanGround`] once. Output: the median height difference of the ground two of
//! them see, metres.

use std::collections::HashMap;
use std::ops::Range;

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

/// The ground one scan lays, by world cell ([`ScanGround::of`]).
#[derive(Clone, Debug, Default)]
pub struct ScanGround {
    /// Each cell's ground height, by the cell's world key.
    height_by_cell: HashMap<[i64; 2], f64>,
}

impl ScanGround {
    /// The ground of a scan by world cell: the 10th percentile of the heights of
    /// its points there (the ground under any clutter).
    pub fn of(world_from_sensor: &Isometry3<f64>, points: &[[f32; 4]]) -> Self {
        let mut cells: Vec<([i64; 2], f64)> = Vec::with_capacity(points.len() / 2);
        for p in points {
            // Squared: a square root (let alone `hypot`) a point costs more than the rest.
            let range_sq = (p[0] as f64).powi(2) + (p[1] as f64).powi(2);
            if !(NEAR_M * NEAR_M..=FAR_M * FAR_M).contains(&range_sq) {
                continue;
            }
            let w = world_from_sensor * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            let cell = [(w.x / CELL_M).floor() as i64, (w.y / CELL_M).floor() as i64];
            cells.push((cell, w.z));
        }
        let (mut heights, groups) = grouped_by_cell(cells);
        let mut height_by_cell = HashMap::new();
        for (cell, range) in groups {
            let group = &mut heights[range];
            if group.len() >= MIN_POINTS {
                let at = group.len() / 10;
                let ground = *group.select_nth_unstable_by(at, f64::total_cmp).1;
                height_by_cell.insert(cell, ground);
            }
        }
        Self { height_by_cell }
    }
}

/// The heights of `cells` grouped by cell, and each cell's range of them: counted
/// into the cells between the least and greatest key (a scan's lie within about
/// FAR_M of its sensor), or sorted where a few far points would make that span
/// large. Not a growing list per cell; a cell's heights in any order (its 10th
/// percentile is the same value).
type HeightsByCell = (Vec<f64>, Vec<([i64; 2], Range<usize>)>);

fn grouped_by_cell(mut cells: Vec<([i64; 2], f64)>) -> HeightsByCell {
    let Some(lower) = (cells.iter())
        .map(|(cell, _)| *cell)
        .reduce(|a, b| [a[0].min(b[0]), a[1].min(b[1])])
    else {
        return (Vec::new(), Vec::new());
    };
    let upper = (cells.iter()).fold(lower, |a, (b, _)| [a[0].max(b[0]), a[1].max(b[1])]);
    let span = [0, 1].map(|axis| (upper[axis].abs_diff(lower[axis]) as usize).saturating_add(1));
    let slots = span[0].saturating_mul(span[1]);
    if slots > 4 * cells.len() + 4096 {
        cells.sort_unstable_by_key(|(cell, _)| *cell);
        let mut groups = Vec::new();
        let mut start = 0;
        for group in cells.chunk_by(|a, b| a.0 == b.0) {
            groups.push((group[0].0, start..start + group.len()));
            start += group.len();
        }
        return (cells.into_iter().map(|(_, z)| z).collect(), groups);
    }
    let slot =
        |cell: &[i64; 2]| (cell[1] - lower[1]) as usize * span[0] + (cell[0] - lower[0]) as usize;
    let mut start = vec![0usize; slots + 1];
    for (cell, _) in &cells {
        start[slot(cell) + 1] += 1;
    }
    for s in 0..slots {
        start[s + 1] += start[s];
    }
    let mut next = start.clone();
    let mut heights = vec![0f64; cells.len()];
    for (cell, z) in &cells {
        heights[next[slot(cell)]] = *z;
        next[slot(cell)] += 1;
    }
    let groups = (0..slots)
        .filter(|&s| start[s + 1] > start[s])
        .map(|s| {
            let cell = [
                lower[0] + (s % span[0]) as i64,
                lower[1] + (s / span[0]) as i64,
            ];
            (cell, start[s]..start[s + 1])
        })
        .collect();
    (heights, groups)
}

/// The median absolute difference of the ground heights two scans lay in the cells
/// both see, metres; None when they share too little ground to say.
pub fn ground_disagreement_m(a: &ScanGround, b: &ScanGround) -> Option<f64> {
    let mut differences: Vec<f64> = (a.height_by_cell.iter())
        .filter_map(|(cell, za)| Some((za - b.height_by_cell.get(cell)?).abs()))
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

    fn disagreement(
        a: (&Isometry3<f64>, &[[f32; 4]]),
        b: (&Isometry3<f64>, &[[f32; 4]]),
    ) -> Option<f64> {
        ground_disagreement_m(&ScanGround::of(a.0, a.1), &ScanGround::of(b.0, b.1))
    }

    #[test]
    fn scans_that_lay_one_ground_agree_and_a_height_or_a_tilt_disagrees() {
        let scan = ground_scan();
        let agree = disagreement((&pose(0.0, 1.8, 0.0), &scan), (&pose(2.0, 1.8, 0.0), &scan));
        assert!(agree.unwrap() < 1e-9);
        let lifted = disagreement((&pose(0.0, 1.8, 0.0), &scan), (&pose(2.0, 2.1, 0.0), &scan));
        assert!((lifted.unwrap() - 0.3).abs() < 1e-9);
        // One degree of pitch lifts the ground 0.17 m ten metres ahead.
        let tilted = disagreement(
            (&pose(0.0, 1.8, 0.0), &scan),
            (&pose(2.0, 1.8, 1f64.to_radians()), &scan),
        );
        assert!(tilted.unwrap() > 0.05, "{tilted:?}");
        let apart = disagreement(
            (&pose(0.0, 1.8, 0.0), &scan),
            (&pose(500.0, 1.8, 0.0), &scan),
        );
        assert_eq!(apart, None, "no shared ground, no verdict");
    }

    #[test]
    fn a_far_point_lays_no_ground_and_moves_none() {
        let tilted = pose(0.0, 1.8, 0.3);
        let scan = ground_scan();
        let mut with_far = scan.clone();
        // 20 m out, 100 km up: tilted, far along the world's x too (the cells are
        // then sorted, not counted in the span between the extreme ones).
        with_far.push([20.0, 0.0, 1e5, 0.2]);
        let (near, far) = (
            ScanGround::of(&tilted, &scan),
            ScanGround::of(&tilted, &with_far),
        );
        assert!(near.height_by_cell.len() > 100);
        assert_eq!(near.height_by_cell, far.height_by_cell);
    }
}
