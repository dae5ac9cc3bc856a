//! Stage 6a (adaptation only), footprint: the cells of a frame's grid that the
//! vehicle drove over, swept by its width along the recorded trajectory within a
//! horizon ahead of and behind the frame, and half its length past the ends. The
//! ground a vehicle drove over was traversable for it: the self-supervised labels of
//! `travmap adapt` start here (docs/method.md "Adaptation").
//!
//! Input: the frame's [`GridLayout`] and the [`Trajectory`] of the drive (every pose
//! the input has, also those past the last scan). Output: one bool per cell.
//! Without a trajectory beyond the frame's own pose, the path is straight along the
//! sensor's x axis over the horizon either way ([`PathKind::Straight`]).

use nalgebra::{Isometry3, Vector3};

use crate::grid::GridLayout;
use travmap_core::config::VehicleConfig;

/// The drive's poses in order: where the sensor was on the ground plane.
#[derive(Clone, Debug, Default)]
pub struct Trajectory {
    /// Frame number of each pose (KITTI: the poses.txt line; a log: the cloud).
    indices: Vec<usize>,
    positions: Vec<[f64; 2]>,
    /// Distance travelled up to each pose, metres.
    along_m: Vec<f64>,
}

/// Where a frame's footprint path came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PathKind {
    /// The recorded (or estimated) trajectory.
    Trajectory,
    /// A straight line along the sensor's x axis: the input had no trajectory
    /// beyond one pose.
    Straight,
}

impl Trajectory {
    /// The trajectory of `poses` (frame number, `drive_from_velodyne`), in order.
    pub fn new(poses: &[(usize, Isometry3<f64>)]) -> Self {
        let mut trajectory = Self::default();
        for (index, pose) in poses {
            let position = [pose.translation.x, pose.translation.y];
            let along = match trajectory.positions.last() {
                Some(last) => {
                    trajectory.along_m[trajectory.along_m.len() - 1] + distance(*last, position)
                }
                None => 0.0,
            };
            trajectory.indices.push(*index);
            trajectory.positions.push(position);
            trajectory.along_m.push(along);
        }
        trajectory
    }

    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Length of the whole path, metres.
    pub fn length_m(&self) -> f64 {
        self.along_m.last().copied().unwrap_or(0.0)
    }

    /// The path through frame `index` from
    /// `horizon_m` behind it to `horizon_m` ahead, as points on the ground plane.
    fn path_around(&self, index: usize, horizon_m: f64) -> Option<Vec<[f64; 2]>> {
        if self.positions.len() < 2 {
            return None;
        }
        let at = match self.indices.binary_search(&index) {
            Ok(at) => at,
            // A frame between poses: the pose before it.
            Err(at) => at.checked_sub(1)?,
        };
        let centre = self.along_m[at];
        let (from, to) = (centre - horizon_m, centre + horizon_m);
        let mut path = Vec::new();
        for k in 0..self.positions.len() {
            let along = self.along_m[k];
            if along < from {
                continue;
            }
            if along > to {
                // The last piece up to exactly the horizon.
                if let Some(previous) = k.checked_sub(1) {
                    path.push(self.point_at(previous, to));
                }
                break;
            }
            if path.is_empty()
                && let Some(previous) = k.checked_sub(1)
                && self.along_m[previous] < from
            {
                path.push(self.point_at(previous, from));
            }
            path.push(self.positions[k]);
        }
        Some(path)
    }

    /// The point `along_m` metres along the path, on the segment from pose `k`.
    fn point_at(&self, k: usize, along_m: f64) -> [f64; 2] {
        let (a, b) = (self.positions[k], self.positions[k + 1]);
        let length = self.along_m[k + 1] - self.along_m[k];
        let t = if length > 0.0 {
            ((along_m - self.along_m[k]) / length).clamp(0.0, 1.0)
        } else {
            0.0
        };
        [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
    }
}

fn distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

/// The footprint of a vehicle along a trajectory.
#[derive(Clone, Debug)]
pub struct Footprint {
    pub vehicle: VehicleConfig,
    pub horizon_m: f64,
}

impl Footprint {
    /// The cells of `layout` the vehicle covers on its path through frame `index`
    /// (posed at `drive_from_velodyne`), and where the path came from.
    pub fn cells(
        &self,
        layout: &GridLayout,
        trajectory: &Trajectory,
        index: usize,
        drive_from_velodyne: &Isometry3<f64>,
    ) -> (Vec<bool>, PathKind) {
        let (mut path, kind) = match trajectory.path_around(index, self.horizon_m) {
            Some(path) if !path.is_empty() => (path, PathKind::Trajectory),
            _ => {
                let forward = drive_from_velodyne.rotation * Vector3::x();
                let origin = drive_from_velodyne.translation.vector;
                let at = |t: f64| [origin.x + t * forward.x, origin.y + t * forward.y];
                (
                    vec![at(-self.horizon_m), at(self.horizon_m)],
                    PathKind::Straight,
                )
            }
        };
        extend_ends(&mut path, 0.5 * self.vehicle.length_m);
        (self.sweep(layout, &path), kind)
    }

    /// Cells whose centre lies within half the vehicle's width of `path`.
    fn sweep(&self, layout: &GridLayout, path: &[[f64; 2]]) -> Vec<bool> {
        let mut covered = vec![false; layout.cell_count()];
        let half_width = 0.5 * self.vehicle.width_m;
        let r = layout.cell_size_m;
        let [min_x, min_y] = layout.min_corner_in_drive();
        let n = layout.cells_per_side as i64;
        let segments: Vec<([f64; 2], [f64; 2])> = match path {
            [only] => vec![(*only, *only)],
            _ => path.windows(2).map(|w| (w[0], w[1])).collect(),
        };
        for (a, b) in segments {
            // Only the cells of the segment's bounding box, widened by the half width.
            let range = |lo: f64, hi: f64, min: f64| {
                let first = (((lo - half_width - min) / r).floor() as i64).clamp(0, n);
                let last = (((hi + half_width - min) / r).ceil() as i64).clamp(0, n);
                first..last
            };
            for row in range(a[1].min(b[1]), a[1].max(b[1]), min_y) {
                for col in range(a[0].min(b[0]), a[0].max(b[0]), min_x) {
                    let cell = (row * n + col) as usize;
                    if covered[cell] {
                        continue;
                    }
                    let centre = layout.cell_centre_in_drive(cell);
                    covered[cell] = segment_distance(centre, a, b) <= half_width;
                }
            }
        }
        covered
    }
}

/// The path lengthened by `extra_m` past each end, along its end segments.
fn extend_ends(path: &mut [[f64; 2]], extra_m: f64) {
    let last = path.len() - 1;
    let mut push_out = |end: usize, towards: usize| {
        let (p, q) = (path[end], path[towards]);
        let length = distance(p, q);
        if length > 1e-9 {
            let s = extra_m / length;
            path[end] = [p[0] + s * (p[0] - q[0]), p[1] + s * (p[1] - q[1])];
        }
    };
    if last > 0 {
        push_out(0, 1);
        push_out(last, last - 1);
    }
}

/// Distance from `p` to the segment `a`-`b`.
fn segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let length2 = dx * dx + dy * dy;
    let t = if length2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / length2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    distance(p, [a[0] + t * dx, a[1] + t * dy])
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};
    use travmap_core::posing::DriveFrame;

    fn pose(x: f64, y: f64, yaw_rad: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(x, y, 0.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_rad),
        )
    }

    fn footprint(horizon_m: f64) -> Footprint {
        Footprint {
            vehicle: VehicleConfig {
                width_m: 1.6,
                length_m: 0.0,
                ..VehicleConfig::default()
            },
            horizon_m,
        }
    }

    /// A 40 x 40 m grid of 0.4 m cells centred on the origin.
    fn layout() -> GridLayout {
        GridLayout::centred_on([0.0, 0.0], DriveFrame::default(), 0.4, 100)
    }

    /// The covered cells as lattice keys.
    fn keys(covered: &[bool], layout: &GridLayout) -> Vec<[i64; 2]> {
        (0..covered.len())
            .filter(|&c| covered[c])
            .map(|c| layout.cell_key(c))
            .collect()
    }

    #[test]
    fn a_straight_drive_covers_a_strip_as_wide_as_the_vehicle() {
        let poses: Vec<_> = (0..41)
            .map(|i| (i, pose(i as f64 - 20.0, 0.0, 0.0)))
            .collect();
        let trajectory = Trajectory::new(&poses);
        assert!((trajectory.length_m() - 40.0).abs() < 1e-9);
        let layout = layout();
        let (covered, kind) = footprint(10.0).cells(&layout, &trajectory, 20, &poses[20].1);
        assert_eq!(kind, PathKind::Trajectory);
        // Centres at y = +-0.2 and +-0.6 are within 0.8 m, from x = -10 to 10 m (the
        // ends are round: half the width further where the strip's middle is).
        let covered_keys = keys(&covered, &layout);
        for key in &covered_keys {
            let (x, y) = ((key[0] as f64 + 0.5) * 0.4, (key[1] as f64 + 0.5) * 0.4);
            assert!(y.abs() <= 0.8 && x.abs() <= 10.8, "{x} {y}");
        }
        for col in -25..25 {
            for row in -2..2 {
                assert!(covered_keys.contains(&[col, row]), "{col} {row}");
            }
        }
    }

    #[test]
    fn a_curve_is_followed_not_cut() {
        // A quarter circle of radius 10 m around (0, 10), from (0, 0) heading +x.
        let poses: Vec<_> = (0..=30)
            .map(|i| {
                let angle = std::f64::consts::FRAC_PI_2 * i as f64 / 30.0;
                (
                    i,
                    pose(10.0 * angle.sin(), 10.0 - 10.0 * angle.cos(), angle),
                )
            })
            .collect();
        let trajectory = Trajectory::new(&poses);
        let layout = layout();
        let (covered, _) = footprint(30.0).cells(&layout, &trajectory, 0, &poses[0].1);
        for c in (0..covered.len()).filter(|&c| covered[c]) {
            let [x, y] = layout.cell_centre_in_drive(c);
            let radius = (x * x + (y - 10.0).powi(2)).sqrt();
            // Within the half width (and the chord error of 31 poses) of the arc.
            assert!((radius - 10.0).abs() <= 0.85, "{x} {y}: radius {radius}");
        }
        // The chord from start to end, which a straight sweep would cover, is not.
        let mid_chord = layout.cell_of_local(5.0 + 20.0, 5.0 + 20.0).unwrap();
        assert!(!covered[mid_chord]);
    }

    #[test]
    fn reversing_covers_the_same_ground() {
        // Forward 10 m, then back 5 m with the vehicle facing +x all along.
        let xs: Vec<f64> = (0..=10)
            .map(f64::from)
            .chain((5..10).rev().map(f64::from))
            .collect();
        let poses: Vec<_> = xs
            .iter()
            .enumerate()
            .map(|(i, &x)| (i, pose(x, 0.0, 0.0)))
            .collect();
        let trajectory = Trajectory::new(&poses);
        assert!((trajectory.length_m() - 15.0).abs() < 1e-9);
        let layout = layout();
        let (covered, _) = footprint(30.0).cells(&layout, &trajectory, 15, &poses[15].1);
        for key in keys(&covered, &layout) {
            let x = (key[0] as f64 + 0.5) * 0.4;
            assert!((-0.8..=10.8).contains(&x), "{x}");
        }
    }

    #[test]
    fn standing_still_covers_only_the_vehicle() {
        let poses: Vec<_> = (0..20).map(|i| (i, pose(0.0, 0.0, 0.0))).collect();
        let trajectory = Trajectory::new(&poses);
        let layout = layout();
        let mut still = footprint(20.0);
        still.vehicle.length_m = 4.0;
        let (covered, kind) = still.cells(&layout, &trajectory, 5, &poses[5].1);
        assert_eq!(kind, PathKind::Trajectory);
        // No segment has a direction to extend along: the width around one point.
        assert!(keys(&covered, &layout).len() <= 16);
    }

    #[test]
    fn one_pose_gives_a_straight_path_along_the_sensor_x_axis() {
        let only = pose(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let trajectory = Trajectory::new(&[(0, only)]);
        let layout = layout();
        let (covered, kind) = footprint(5.0).cells(&layout, &trajectory, 0, &only);
        assert_eq!(kind, PathKind::Straight);
        // Along world y (the sensor's x axis), +-5 m.
        let covered_keys = keys(&covered, &layout);
        for key in &covered_keys {
            let (x, y) = ((key[0] as f64 + 0.5) * 0.4, (key[1] as f64 + 0.5) * 0.4);
            assert!(x.abs() <= 0.8 && y.abs() <= 5.8, "{x} {y}");
        }
        assert!(covered_keys.contains(&[0, 12]) && covered_keys.contains(&[-1, -13]));
        assert!(!covered_keys.contains(&[12, 0]), "not along world x");
    }

    #[test]
    fn the_horizon_cuts_a_long_drive() {
        let poses: Vec<_> = (0..200)
            .map(|i| (i, pose(i as f64 * 0.5 - 50.0, 0.0, 0.0)))
            .collect();
        let trajectory = Trajectory::new(&poses);
        let layout = layout();
        let (covered, _) = footprint(3.0).cells(&layout, &trajectory, 100, &poses[100].1);
        let covered_keys = keys(&covered, &layout);
        for key in &covered_keys {
            let x = (key[0] as f64 + 0.5) * 0.4;
            assert!(x.abs() <= 3.8, "{x}");
        }
        assert!(covered_keys.contains(&[7, 0]) && !covered_keys.contains(&[10, 0]));
    }
}
