//! The settings of training: the grid search, its spatially-blocked folds, the SMO
//! solver and the reduced set.

use serde::{Deserialize, Serialize};

/// The largest SVM C and gamma searched or fitted: beyond them the solver's steps
/// lose all precision and it never converges (C 1e300 ran without end).
pub const MAX_SVM_C: f64 = 1e6;
pub const MAX_SVM_GAMMA: f64 = 1e4;

/// Checks `low < v <= high` (a finite `v`), naming the setting.
pub fn check_within(
    name: &str,
    v: f64,
    (low, high): (f64, f64),
) -> std::result::Result<(), String> {
    match v.is_finite() && v > low && v <= high {
        true => Ok(()),
        false => Err(format!("{name} must be in ({low:?}, {high:?}], got {v:?}")),
    }
}

/// METHOD.md section 6, and the spatially-blocked validation of this project.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainingConfig {
    /// Grid side used to collect training cells, metres (default 36). Features do not
    /// depend on the grid size, so a larger grid only adds cells.
    pub grid_size_m: f64,
    /// Candidate SVM penalties C of the grid search.
    pub c_values: Vec<f64>,
    /// Candidate RBF widths gamma of the grid search (on standardised features).
    pub gamma_values: Vec<f64>,
    /// Folds of the cross-validation (default 5).
    pub folds: usize,
    /// Side of the square world blocks that make up the folds, metres (default 4):
    /// a world cell and its copies in other frames are always in one fold.
    pub block_size_m: f64,
    /// The grid search uses a seeded random subset of at most this many cells
    /// (default 6000).
    pub max_search_samples: usize,
    /// The final model is fitted on a seeded random subset of at most this many
    /// cells (default 50,000), a superset of the search's: the solver's time grows
    /// faster than the cell count, and a training set gathered from a fleet's logs
    /// can hold millions.
    pub max_fit_samples: usize,
    /// Stopping tolerance of the SMO solver on the KKT gap (default 1e-3, libsvm's).
    pub tolerance: f64,
    /// Kernel row cache per solver, MiB (default 200).
    pub cache_mib: usize,
    /// Seed of the fold assignment, the search subset and the reduced set.
    pub seed: u64,
    /// Kernel centres of the reduced set fitted after training (default 384); 0: none.
    pub reduced_set_size: usize,
    /// Training cells the reduced set is fitted on, at most (default 20,000).
    pub reduced_set_samples: usize,
    /// Steps that move the reduced set's centres down the gradient of its fitting
    /// error, the weights re-solved at each (default 20: held out, SemanticKITTI rose
    /// by up to 9 points, docs/method.md).
    pub reduced_set_refinements: usize,
    /// Per-class weights on C (libsvm's `-w`): `"balanced"` (default), each class
    /// weighted by cells / (2 x its cells) so the rarer class counts as much, or
    /// `"none"` (the paper's).
    pub class_weights: ClassWeights,
    /// What the grid search maximises over the held-out folds: `"miou"` (default:
    /// accuracy rewards calling everything road) or `"accuracy"`.
    pub criterion: Criterion,
    /// Choose the decision threshold (0 otherwise) that maximises the criterion over
    /// the held-out folds' decision values of the chosen (C, gamma) (default false:
    /// on the shipped scenes it lowered every held-out score, docs/method.md "Features beyond
    /// the paper").
    pub tune_threshold: bool,
    /// How the inputs of one training weigh against each other: `"equally"`
    /// (default: each drive or dataset file counts as much in all, however many
    /// cells it gave, so that a long drive of one sensor does not drown the others)
    /// or `"by_cells"`.
    pub weigh_inputs: WeighInputs,
    /// Features the model does not look at (their standardised values are all 0, so
    /// they add nothing to the kernel's distances); default
    /// `SENSOR_DEPENDENT_FEATURES` (docs/method.md "Streets and sensors it has never
    /// seen"). `[]` is the paper's method.
    pub left_out_features: Vec<String>,
    /// With `train --prior`: the weight on C of each cell a person labelled (`travmap
    /// label`) against each of the prior's support vectors, which stand for what the
    /// prior learnt (default 20, docs/method.md "Teaching it a robot").
    pub taught_weight: f64,
}

/// What differs between drives over the same ground: the normal's horizontal
/// components follow the direction of travel, the range histogram's curvity the
/// sensor's beams (in the order of the features). Left out, the held-out scores of
/// docs/method.md rose.
pub const SENSOR_DEPENDENT_FEATURES: [&str; 3] = ["normal_x", "normal_y", "curvity"];

/// How several training inputs weigh against each other.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WeighInputs {
    Equally,
    ByCells,
}

/// Per-class weights on the SVM's C.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ClassWeights {
    None,
    Balanced,
}

/// The score the grid search maximises.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Criterion {
    Accuracy,
    Miou,
}

impl Default for TrainingConfig {
    fn default() -> Self {
        Self {
            grid_size_m: 36.0,
            c_values: vec![1.0, 10.0, 100.0],
            gamma_values: vec![0.01, 0.05, 0.2],
            folds: 5,
            block_size_m: 4.0,
            max_search_samples: 6000,
            max_fit_samples: 50_000,
            tolerance: 1e-3,
            cache_mib: 200,
            seed: 0,
            reduced_set_size: 384,
            reduced_set_samples: 20_000,
            reduced_set_refinements: 20,
            class_weights: ClassWeights::Balanced,
            criterion: Criterion::Miou,
            tune_threshold: false,
            weigh_inputs: WeighInputs::Equally,
            left_out_features: SENSOR_DEPENDENT_FEATURES.map(String::from).to_vec(),
            taught_weight: 20.0,
        }
    }
}
