//! Where the scans' poses come from, and the settings of scan registration.

use serde::{Deserialize, Serialize};

/// Where the scans' poses come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseSource {
    /// The input's recorded poses (KITTI `poses.txt`, a log's /tf, Odometry or pose
    /// topic) when they move the scans' frame, else registration, said in a notice.
    #[default]
    Auto,
    /// A log's /tf and /tf_static only (KITTI: `poses.txt`).
    Tf,
    /// A log's `nav_msgs/Odometry`, or one PoseStamped / PoseWithCovarianceStamped
    /// topic (with /tf_static) only (KITTI: `poses.txt`).
    Odometry,
    /// Estimated by scan registration, whatever the input records.
    Registration,
    /// None: each scan alone (integration of 1 scan).
    None,
}

impl PoseSource {
    pub fn name(self) -> &'static str {
        match self {
            PoseSource::Auto => "auto",
            PoseSource::Tf => "tf",
            PoseSource::Odometry => "odometry",
            PoseSource::Registration => "registration",
            PoseSource::None => "none",
        }
    }
}

/// Scan registration (`--poses registration`, `method/registration.rs`); the
/// defaults are KISS-ICP 1.3's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RegistrationConfig {
    /// Farther points are dropped, and map voxels farther from the sensor, metres
    /// (default 100).
    pub max_range_m: f64,
    /// Nearer points are dropped, metres (default 0).
    pub min_range_m: f64,
    /// Side of a map voxel, metres; 0 means max_range_m / 100 (default 0).
    pub voxel_size_m: f64,
    /// Points kept per map voxel (default 20).
    pub max_points_per_voxel: usize,
    /// Adaptive threshold before any motion has been seen, metres (default 2).
    pub initial_threshold_m: f64,
    /// Deviations from the prediction below this leave the threshold alone, metres
    /// (default 0.1).
    pub min_motion_m: f64,
    /// ICP stops when its update, metres and radians as one 6-vector, is shorter
    /// (default 1e-4).
    pub convergence: f64,
    /// ICP iterations after which the registration counts as diverged (default 500).
    pub max_iterations: usize,
}

impl Default for RegistrationConfig {
    fn default() -> Self {
        Self {
            max_range_m: 100.0,
            min_range_m: 0.0,
            voxel_size_m: 0.0,
            max_points_per_voxel: 20,
            initial_threshold_m: 2.0,
            min_motion_m: 0.1,
            convergence: 1e-4,
            max_iterations: 500,
        }
    }
}

impl RegistrationConfig {
    /// The map voxel side, metres, with 0 resolved.
    pub fn effective_voxel_size_m(&self) -> f64 {
        match self.voxel_size_m > 0.0 {
            true => self.voxel_size_m,
            false => self.max_range_m / 100.0,
        }
    }

    /// Checks what `Odometry` relies on.
    pub fn validate(&self) -> Result<(), String> {
        let check = |holds: bool, rule: &str| match holds {
            true => Ok(()),
            false => Err(format!("registration needs finite {rule}, got {self:?}")),
        };
        let (c, positive) = (self, |v: f64| v.is_finite() && v > 0.0);
        check(positive(c.max_range_m), "max_range_m > 0")?;
        let in_range = (0.0..c.max_range_m).contains(&c.min_range_m);
        check(in_range, "0 <= min_range_m < max_range_m")?;
        let voxel = c.voxel_size_m == 0.0 || positive(c.voxel_size_m);
        check(voxel, "voxel_size_m >= 0")?;
        // KISS-ICP keeps 20; 10^4 would already allocate gigabytes for the map.
        let voxel_points = (1..=10_000).contains(&c.max_points_per_voxel);
        check(voxel_points, "max_points_per_voxel in 1..=10000")?;
        check(positive(c.initial_threshold_m), "initial_threshold_m > 0")?;
        let motion = c.min_motion_m == 0.0 || positive(c.min_motion_m);
        check(motion, "min_motion_m >= 0")?;
        check(positive(c.convergence), "convergence > 0")?;
        check(
            (1..=10_000).contains(&c.max_iterations),
            "max_iterations in 1..=10000",
        )
    }
}
