//! The vehicle whose drives adaptation learns from, and the settings of adaptation
//! (`travmap adapt`, docs/method.md "Adaptation").

use serde::{Deserialize, Serialize};

use super::training::{MAX_SVM_C, MAX_SVM_GAMMA, check_within};

/// The vehicle that recorded the drive.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VehicleConfig {
    /// Width of the ground the vehicle covers, metres (default 1.6).
    pub width_m: f64,
    /// Length, metres: the footprint reaches half of it ahead of the first pose and
    /// behind the last (default 4.0).
    pub length_m: f64,
    /// Height range within a cell that the vehicle cannot drive over, metres: such
    /// cells are obstacles, never footprint (default 0.3).
    pub clearance_m: f64,
    /// The vehicle's own points (its body as its LiDAR sees it) are left out of
    /// every scan: `auto` (default) finds them where the recorded poses show the
    /// world moving past points that stay put in the sensor frame; `off` keeps them.
    pub own_points: OwnPoints,
    /// The box around the vehicle's body in the sensor frame, `[xmin, ymin, zmin,
    /// xmax, ymax, zmax]` metres; given, it is used instead of one found.
    pub own_points_box_m: Option<[f64; 6]>,
}

/// Whether the vehicle's own points are found and left out.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OwnPoints {
    Auto,
    Off,
}

impl Default for VehicleConfig {
    fn default() -> Self {
        Self {
            width_m: 1.6,
            length_m: 4.0,
            clearance_m: 0.3,
            own_points: OwnPoints::Auto,
            own_points_box_m: None,
        }
    }
}

impl VehicleConfig {
    /// What is wrong with the vehicle's settings, if anything.
    pub fn validate(&self) -> Result<(), String> {
        if let Some(corners) = self.own_points_box_m {
            let ordered = (0..3).all(|i| corners[i] < corners[i + 3]);
            if !(ordered && corners.iter().all(|v| v.is_finite())) {
                return Err(format!(
                    "vehicle.own_points_box_m must be [xmin, ymin, zmin, xmax, ymax, zmax] with each min below its max, got {corners:?}"
                ));
            }
        }
        Ok(())
    }
}

/// The most self-training rounds `adapt.rounds` may ask for.
const MAX_ROUNDS: usize = 20;

/// How the adapted model learns from the prior and the drive.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Learner {
    /// An SVM of the drive's self-labelled cells alone.
    Drive,
    /// One SVM of the drive's cells and the prior's support vectors (labelled by
    /// their side), the latter weighted by `prior_weight`.
    DriveAndPrior,
    /// The drive's SVM and the prior together: the sum of their decision values,
    /// the prior's weighted by `prior_weight`.
    Sum,
}

/// Self-supervised adaptation to the ground a drive covers.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AdaptConfig {
    /// How far along the trajectory, ahead of and behind each scan, the ground the
    /// vehicle drove over is footprint, metres (default 10).
    pub horizon_m: f64,
    /// How the adapted model learns (default `sum`).
    pub learner: Learner,
    /// Cells the prior calls not traversable with a margin at or below minus this
    /// are negatives (default 2: at 1 the prior's doubts about road it had not seen
    /// became negatives, and adaptation lost 13 points on SemanticKITTI 00).
    pub negative_margin: f64,
    /// Cells over the vehicle's clearance are negatives too (default true).
    pub geometric_negatives: bool,
    /// Weight of the prior's cells (`drive_and_prior`) or decision value (`sum`)
    /// against the drive's (default 0.75).
    pub prior_weight: f64,
    /// The adapted SVM's C and gamma: a drive has no labels to choose them by
    /// (default 1 and 0.02).
    pub c: f64,
    pub gamma: f64,
    /// Self-training rounds: cells left unknown that the adapted model calls with a
    /// margin of at least `self_training_margin` join its training cells, and it is
    /// fitted again (default 0).
    pub rounds: usize,
    pub self_training_margin: f64,
    /// Positive-unlabelled learning: cells left unknown are negatives too, each with
    /// this weight on C (default 0: unknown cells are not learnt from). At 1 with no
    /// other negatives (`negative_margin` high, `geometric_negatives` false) the
    /// footprint is learnt against everything else, a biased SVM.
    pub unlabelled_weight: f64,
    /// A drive with fewer distinct footprint cells is refused (default 50).
    pub min_footprint_cells: usize,
    /// Self-labelled cells the SVM is fitted on at most, a seeded random subset,
    /// half of each label (default 10,000: a 60-frame drive adapts in seconds).
    pub max_cells: usize,
    /// The adapted model replaces the prior only where the drive's own evidence held
    /// out of the fit shows it better (default true); false adapts unchecked (the
    /// learner studies of docs/method.md).
    pub check: bool,
}

impl Default for AdaptConfig {
    fn default() -> Self {
        Self {
            horizon_m: 10.0,
            // The study's choice (docs/method.md "Adaptation"): the sum, on a plateau of
            // C 0.3-1, gamma 0.02-0.03, prior weight 0.5-1.
            learner: Learner::Sum,
            negative_margin: 2.0,
            geometric_negatives: true,
            prior_weight: 0.75,
            c: 1.0,
            gamma: 0.02,
            rounds: 0,
            self_training_margin: 1.0,
            unlabelled_weight: 0.0,
            min_footprint_cells: 50,
            max_cells: 10_000,
            check: true,
        }
    }
}

impl AdaptConfig {
    /// Checks what adaptation relies on.
    pub fn validate(&self, vehicle: &VehicleConfig) -> Result<(), String> {
        let positive = |name: &str, v: f64| match v.is_finite() && v > 0.0 {
            true => Ok(()),
            false => Err(format!("{name} must be > 0, got {v}")),
        };
        positive("vehicle.width_m", vehicle.width_m)?;
        positive("vehicle.length_m", vehicle.length_m)?;
        positive("vehicle.clearance_m", vehicle.clearance_m)?;
        positive("adapt.horizon_m", self.horizon_m)?;
        check_within("adapt.c", self.c, (0.0, MAX_SVM_C))?;
        check_within("adapt.gamma", self.gamma, (0.0, MAX_SVM_GAMMA))?;
        // Each round refits the model: past a few the cells left unknown are few.
        if self.rounds > MAX_ROUNDS {
            return Err(format!(
                "adapt.rounds must be at most {MAX_ROUNDS}, got {}",
                self.rounds
            ));
        }
        positive("adapt.self_training_margin", self.self_training_margin)?;
        if !(self.negative_margin.is_finite() && self.negative_margin >= 0.0) {
            return Err(format!(
                "adapt.negative_margin must be >= 0, got {}",
                self.negative_margin
            ));
        }
        for (name, weight) in [
            ("adapt.prior_weight", self.prior_weight),
            ("adapt.unlabelled_weight", self.unlabelled_weight),
        ] {
            if !(weight.is_finite() && weight >= 0.0) {
                return Err(format!("{name} must be >= 0, got {weight}"));
            }
        }
        if self.max_cells < 2 {
            return Err(format!(
                "adapt.max_cells must be >= 2, got {}",
                self.max_cells
            ));
        }
        Ok(())
    }
}
