//! Stage 1, integration (METHOD.md section 2): a scan moved into the world frame
//! with its own pose, keeping its sensor origin, plus the ground plane of the
//! integrated cloud.
//!
//! Input: a [`Frame`]. Output: a [`WorldScan`]; the pipeline keeps the last n of them
//! and [`ground_normal`] fits the plane of their union.

use crate::geometry::Moments;
use crate::reading::Frame;

/// One scan in the world frame.
#[derive(Clone, Debug)]
pub struct WorldScan {
    pub index: usize,
    pub stamp_ns: u64,
    pub points_in_world: Vec<[f32; 3]>,
    /// Where the sensor was when it took this scan; curvity measures ranges from it.
    pub origin_in_world: [f64; 3],
    pub labels: Option<Vec<u32>>,
    /// Moments of `points_in_world`, so that the plane of several scans costs O(1).
    pub moments: Moments,
}

/// Moves every point of `frame` into the world frame (the pose is applied in f64).
pub fn scan_to_world(frame: Frame) -> WorldScan {
    let m = frame.world_from_velodyne.to_homogeneous();
    let mut moments = Moments::default();
    let points_in_world = frame
        .points_in_velodyne
        .iter()
        .map(|p| {
            let (x, y, z) = (p[0] as f64, p[1] as f64, p[2] as f64);
            let w = [
                m[(0, 0)] * x + m[(0, 1)] * y + m[(0, 2)] * z + m[(0, 3)],
                m[(1, 0)] * x + m[(1, 1)] * y + m[(1, 2)] * z + m[(1, 3)],
                m[(2, 0)] * x + m[(2, 1)] * y + m[(2, 2)] * z + m[(2, 3)],
            ];
            moments.add(w);
            [w[0] as f32, w[1] as f32, w[2] as f32]
        })
        .collect();
    WorldScan {
        index: frame.index,
        stamp_ns: frame.stamp_ns,
        points_in_world,
        origin_in_world: [m[(0, 3)], m[(1, 3)], m[(2, 3)]],
        labels: frame.labels,
        moments,
    }
}

/// Unit normal (z >= 0) of the plane fitted by least squares to all points of
/// `scans`: the ground-plane normal that zeta difference projects on (section 4).
pub fn ground_normal(scans: &[&WorldScan]) -> [f64; 3] {
    let mut all = Moments::default();
    for scan in scans {
        all.merge(&scan.moments);
    }
    all.covariance().smallest_eigen().normal
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pose_moves_points_and_origin() {
        // 90 degrees about z (velodyne x becomes world y), 10 m along x.
        let world_from_velodyne = nalgebra::Isometry3::new(
            nalgebra::Vector3::new(10.0, 0.0, 0.0),
            nalgebra::Vector3::new(0.0, 0.0, std::f64::consts::FRAC_PI_2),
        );
        let frame = Frame {
            index: 4,
            stamp_ns: 7,
            world_from_velodyne,
            points_in_velodyne: vec![[1.0, 0.0, 2.0, 0.5], [0.0, 1.0, 0.0, 0.1]],
            labels: None,
            camera: None,
            dropped_points: 0,
        };
        let scan = scan_to_world(frame);
        let expected = [[10.0, 1.0, 2.0], [9.0, 0.0, 0.0]];
        for (p, e) in scan.points_in_world.iter().zip(expected) {
            assert!(p.iter().zip(e).all(|(a, b)| (a - b).abs() < 1e-6), "{p:?}");
        }
        assert_eq!(scan.origin_in_world, [10.0, 0.0, 0.0]);
        assert_eq!(scan.moments.count, 2);
    }
}
