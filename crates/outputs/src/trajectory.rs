//! Estimated trajectories as text (`travmap odometry`), in the formats odometry
//! evaluation tools read: KITTI (the 3x4 pose of each scan, row-major, one line per
//! scan) and TUM (`stamp tx ty tz qx qy qz qw`, seconds).

use std::fmt::Write;
use std::path::Path;

use crate::atomic::write_atomically;
use travmap_core::error::Result;
use travmap_run::EstimatedPose;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrajectoryFormat {
    Kitti,
    Tum,
}

/// The trajectory as text in `format`.
pub fn trajectory_text(poses: &[EstimatedPose], format: TrajectoryFormat) -> String {
    let mut text = String::new();
    for pose in poses {
        let m = pose.world_from_velodyne.to_homogeneous();
        // Writing to a String cannot fail.
        let _ = match format {
            TrajectoryFormat::Kitti => {
                let values: Vec<String> = (0..3)
                    .flat_map(|r| (0..4).map(move |c| (r, c)))
                    .map(|(r, c)| format!("{:.9e}", m[(r, c)]))
                    .collect();
                writeln!(text, "{}", values.join(" "))
            }
            TrajectoryFormat::Tum => {
                let t = pose.world_from_velodyne.translation.vector;
                let q = pose.world_from_velodyne.rotation.coords;
                writeln!(
                    text,
                    "{:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9}",
                    pose.stamp_ns as f64 * 1e-9,
                    t.x,
                    t.y,
                    t.z,
                    q.x,
                    q.y,
                    q.z,
                    q.w
                )
            }
        };
    }
    text
}

/// Writes the trajectory to `path` (through a temporary file).
pub fn write_trajectory(
    path: &Path,
    poses: &[EstimatedPose],
    format: TrajectoryFormat,
) -> Result<()> {
    write_atomically(path, trajectory_text(poses, format).as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Isometry3, Translation3, UnitQuaternion};

    #[test]
    fn both_formats_write_the_pose_they_are_given() {
        let pose = EstimatedPose {
            index: 0,
            stamp_ns: 1_500_000_000,
            world_from_velodyne: Isometry3::from_parts(
                Translation3::new(1.0, -2.0, 0.5),
                UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2),
            ),
            register_ms: 0.0,
        };
        let kitti = trajectory_text(std::slice::from_ref(&pose), TrajectoryFormat::Kitti);
        let values: Vec<f64> = kitti
            .split_whitespace()
            .map(|v| v.parse().unwrap())
            .collect();
        let expected = [0.0, -1.0, 0.0, 1.0, 1.0, 0.0, 0.0, -2.0, 0.0, 0.0, 1.0, 0.5];
        assert_eq!(values.len(), 12);
        for (v, e) in values.iter().zip(expected) {
            assert!((v - e).abs() < 1e-9, "{kitti}");
        }
        let tum = trajectory_text(&[pose], TrajectoryFormat::Tum);
        let values: Vec<f64> = tum.split_whitespace().map(|v| v.parse().unwrap()).collect();
        let half = std::f64::consts::FRAC_1_SQRT_2;
        let expected = [1.5, 1.0, -2.0, 0.5, 0.0, 0.0, half, half];
        for (v, e) in values.iter().zip(expected) {
            assert!((v - e).abs() < 1e-9, "{tum}");
        }
    }
}
