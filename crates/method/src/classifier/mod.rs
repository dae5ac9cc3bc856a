//! Stage 4, classification (METHOD.md section 6): an RBF-kernel SVM on standardised
//! features, and its versioned model file.
//!
//! Input: a [`FeatureGrid`]. Output: one [`CellClass`] per cell. Prediction runs over
//! a flat f32 support-vector matrix with precomputed squared norms and one reused
//! buffer per grid, no allocation per cell. Training lives in `training`, the
//! solver in `smo`.

pub mod calibration;
pub mod kernel;
pub mod model_file;

use serde::{Deserialize, Serialize};

use crate::features::{FeatureGrid, feature_names};
use crate::grid::CellClass;
use travmap_core::config::{ClassifierConfig, Config, FeatureGroup, ForeignRemissionPolicy};
use travmap_core::error::{Error, Result};

/// How a model was trained, kept in the model file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainingSummary {
    /// The inputs and frames the cells came from.
    pub sources: Vec<String>,
    pub samples: usize,
    pub traversable_samples: usize,
    /// Spatially-blocked cross-validated accuracy (cells, before filtering) of
    /// every (C, gamma) tried.
    pub search: Vec<SearchResult>,
    pub solver_iterations: usize,
    pub solver_converged: bool,
    pub seconds: f64,
    /// SHA-256 of each labelled scan the cells came from (none for cells read from
    /// datasets, or in models trained before it was recorded): lets `eval` tell
    /// training frames from unseen ones by content.
    #[serde(default)]
    pub frame_sha256: Vec<String>,
    /// For a model adapted to drives (`travmap adapt`): how, and from what.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adaptation: Option<AdaptationSummary>,
}

/// How a model was adapted to drives without annotations, kept in its file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AdaptationSummary {
    /// Its labels came from the drives themselves (footprint, obstacles, the
    /// prior's confident rejections), never from annotations.
    pub self_supervised: bool,
    pub learner: travmap_core::config::Learner,
    /// The model adapted from, and the SHA-256 of its file.
    pub prior: String,
    pub prior_sha256: String,
    pub inputs: Vec<AdaptedInput>,
    /// Distinct world cells of each self-label, over every frame.
    pub footprint_cells: usize,
    pub negative_cells: usize,
    pub unknown_cells: usize,
    /// Self-labelled cells the SVM was fitted on (a seeded subset when many),
    /// self-training's included.
    pub fitted_cells: usize,
    /// Frames whose footprint ran straight along the sensor's x axis (no
    /// trajectory beyond one pose).
    pub straight_path_frames: usize,
    /// Which parts besides the geometric model were fitted to the drives, and why:
    /// adaptation fits only what the drives use.
    #[serde(default)]
    pub hybrid: String,
    #[serde(default)]
    pub fallback: String,
    /// The check against the prior that decided whether the adapted model replaces
    /// it (absent in files from before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub check: Option<AdaptationCheck>,
}

/// How an adapted model fared against its prior on what the drives themselves
/// show, and whether it replaced the prior: cells the vehicle drove over
/// (traversable) and cells over its clearance (not), held out of the fit a block of
/// the world at a time (`crates/training/src/adaptation.rs`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AdaptationCheck {
    /// The adapted model replaces the prior (false: the prior is kept as it was).
    pub adapted: bool,
    /// Why, as a person reads it.
    pub why: String,
    /// The held-out evidence: samples of cells driven over and of cells over the
    /// clearance (a world cell once for every frame that saw it; the summary's
    /// `footprint_cells` counts distinct world cells), and the blocks of the world
    /// they lie in.
    #[serde(alias = "footprint_cells")]
    pub footprint_samples: usize,
    #[serde(alias = "clearance_cells")]
    pub clearance_samples: usize,
    pub blocks: usize,
    /// mIoU (0..1) of the prior and of the adapted model on the held-out evidence,
    /// when there was enough of it to compare.
    pub prior_miou: Option<f64>,
    pub adapted_miou: Option<f64>,
    /// Held-out cells the drive says nothing of (neither driven over nor an
    /// obstacle) that the prior was sure were traversable (a margin of 1 or more),
    /// and those of them the adapted model calls not traversable.
    #[serde(default)]
    pub confident_unknown: usize,
    #[serde(default)]
    pub flipped_unknown: usize,
}

/// A drive a model was adapted to.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AdaptedInput {
    /// The input and the frames of it, as a person reads them.
    pub input: String,
    pub frames: usize,
    /// SHA-256 of its scans' contents in order (each scan's points, as
    /// `Frame::content_sha256`): the same drive however stored.
    pub scans_sha256: String,
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SearchResult {
    pub c: f64,
    pub gamma: f64,
    pub accuracy: f64,
    /// Mean IoU of the two classes over the held-out folds (0 in models trained
    /// before it was recorded).
    #[serde(default)]
    pub miou: f64,
}

/// A smaller expansion `sum_j w_j K(c_j, x) + b` fitted by least squares to the exact
/// decision function on training cells: prediction costs the centres' count instead
/// of the support vectors'.
#[derive(Clone, Debug, PartialEq)]
pub struct ReducedSet {
    /// Row-major `centres x dimension`, standardised.
    pub centres: Vec<f32>,
    pub weights: Vec<f32>,
    pub bias: f32,
    /// Share of the fitting cells on which its sign equals the exact model's.
    pub training_agreement: f64,
    blocks: kernel::SupportVectorBlocks,
}

impl ReducedSet {
    pub fn new(centres: Vec<f32>, weights: Vec<f32>, bias: f32, training_agreement: f64) -> Self {
        let d = if weights.is_empty() {
            1
        } else {
            centres.len() / weights.len()
        };
        let blocks = kernel::SupportVectorBlocks::new(&centres, &weights, d);
        Self {
            centres,
            weights,
            bias,
            training_agreement,
            blocks,
        }
    }

    pub fn len(&self) -> usize {
        self.weights.len()
    }

    pub fn is_empty(&self) -> bool {
        self.weights.is_empty()
    }
}

/// Cells a model file decides as it did when written (its `check_cells`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CheckCells {
    /// Raw (unstandardised) feature rows, one per cell.
    features: Vec<Vec<f32>>,
    /// The margin (decision value minus threshold) over every support vector, per cell.
    exact: Vec<f32>,
    /// The margin by the reduced set, per cell (empty without one).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    reduced: Vec<f32>,
}

/// Reusable buffers of prediction, one per thread.
#[derive(Default)]
pub struct PredictionScratch {
    standardised: Vec<f32>,
    /// Geometric and appearance values side by side, for the hybrid model.
    row: Vec<f32>,
}

/// A trained RBF SVM, ready to predict.
#[derive(Clone, Debug, PartialEq)]
pub struct SvmModel {
    pub feature_mean: Vec<f32>,
    /// 1 / standard deviation per feature (1 for constant features, 0 for those
    /// left out: `training.left_out_features`).
    pub feature_inverse_std: Vec<f32>,
    pub c: f64,
    pub gamma: f64,
    pub rho: f32,
    /// A cell is traversable when its decision value exceeds this (0 unless the
    /// cross-validation chose another, `training.tune_threshold`).
    pub threshold: f32,
    pub dual_coefficients: Vec<f32>,
    /// Row-major `support_vector_count x dimension`.
    pub support_vectors: Vec<f32>,
    /// The support vectors again, laid out for fast prediction.
    blocks: kernel::SupportVectorBlocks,
    pub config: Config,
    pub training: TrainingSummary,
    /// Used by [`SvmModel::decision_value`] when present.
    pub reduced_set: Option<ReducedSet>,
    /// Classifies the cells that have appearance features (METHOD.md section 5's
    /// Decision); this model classifies the others.
    pub hybrid: Option<Box<SvmModel>>,
    /// The same model without remission features, for clouds without usable
    /// intensity; present exactly when this model uses remission.
    pub fallback: Option<Box<SvmModel>>,
    /// A model this one adapts (`adapt.learner = "sum"`): its margins, times
    /// `prior_weight`, add to this one's.
    pub prior: Option<Box<SvmModel>>,
    pub prior_weight: f32,
    /// The reduced set stands for this model's margin plus the prior's (fitted to
    /// their sum), so the prior is not asked again where it is used.
    pub reduced_set_includes_prior: bool,
    /// The check cells of the file this model was read from (None for a model made
    /// here): written again as they were, so that a model read and written keeps its
    /// bytes (its check cells' features, recomputed from standardised support
    /// vectors, could differ in the last bit).
    pub(crate) check_cells: Option<CheckCells>,
    /// Its margin as P(traversable), fitted to held-out margins when it was trained
    /// (None for a model adapted or taught, and for files from before it existed).
    pub calibration: Option<calibration::Calibration>,
}

impl SvmModel {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        feature_mean: Vec<f32>,
        feature_inverse_std: Vec<f32>,
        c: f64,
        gamma: f64,
        rho: f32,
        dual_coefficients: Vec<f32>,
        support_vectors: Vec<f32>,
        config: Config,
        training: TrainingSummary,
    ) -> Self {
        let d = feature_mean.len();
        let blocks = kernel::SupportVectorBlocks::new(&support_vectors, &dual_coefficients, d);
        Self {
            feature_mean,
            feature_inverse_std,
            c,
            gamma,
            rho,
            threshold: 0.0,
            dual_coefficients,
            support_vectors,
            blocks,
            config,
            training,
            reduced_set: None,
            hybrid: None,
            fallback: None,
            prior: None,
            prior_weight: 0.0,
            reduced_set_includes_prior: false,
            check_cells: None,
            calibration: None,
        }
    }

    /// P(traversable) of a margin: by the model's calibration, or by
    /// [`calibration::UNCALIBRATED`] when it has none; NaN for an unpredictable cell.
    pub fn probability(&self, margin: f32) -> f32 {
        self.calibration
            .unwrap_or(calibration::UNCALIBRATED)
            .probability(margin)
    }

    /// The support vectors with their standardisation undone: the cells (or their
    /// like) the model was fitted on, row-major.
    pub fn support_vectors_raw(&self) -> Vec<f32> {
        let d = self.dimension();
        self.support_vectors
            .chunks_exact(d)
            .flat_map(|z| {
                z.iter()
                    .zip(&self.feature_mean)
                    .zip(&self.feature_inverse_std)
                    // A left-out feature's value is lost: its mean stands in.
                    .map(|((&z, &m), &s)| if s == 0.0 { m } else { z / s + m })
            })
            .collect()
    }

    pub fn dimension(&self) -> usize {
        self.feature_mean.len()
    }

    pub fn support_vector_count(&self) -> usize {
        self.dual_coefficients.len()
    }

    /// Feature names: the geometric ones, plus the appearance ones for a hybrid model.
    pub fn feature_names(&self) -> Vec<String> {
        model_feature_names(&self.config, self.dimension())
    }

    /// The features this model does not look at (`training.left_out_features`):
    /// those whose standardised values are all 0.
    pub fn left_out_features(&self) -> Vec<String> {
        self.feature_names()
            .into_iter()
            .zip(&self.feature_inverse_std)
            .filter(|(_, s)| **s == 0.0)
            .map(|(name, _)| name)
            .collect()
    }

    /// Whether any cell's margin can depend on appearance features: a hybrid model
    /// here, in the remission-less fallback or in the prior. Without, camera images
    /// change nothing this model decides.
    pub fn uses_appearance(&self) -> bool {
        self.hybrid.is_some()
            || [&self.fallback, &self.prior]
                .into_iter()
                .flatten()
                .any(|model| model.uses_appearance())
    }

    /// Whether classifying under `config` needs the frames' camera images: only when
    /// appearance is on and the model reads it; decoding them costs more than the
    /// rest of the method.
    pub fn reads_images(&self, config: &Config) -> bool {
        config.appearance.enabled && self.uses_appearance()
    }

    /// Errors when `config` would compute features differently from the training
    /// cells; the error names the first setting that differs, both values, and the
    /// `--set` that runs the model as trained. `model_name` names the model file.
    pub fn check_compatible(&self, config: &Config, model_name: &str) -> Result<()> {
        let mut trained = serde_json::to_value(&self.config).unwrap_or_default();
        let mut wanted = serde_json::to_value(config).unwrap_or_default();
        // The remission scale means nothing to a model without remission features.
        if !self
            .config
            .features
            .groups
            .contains(&FeatureGroup::Remission)
        {
            for value in [&mut trained, &mut wanted] {
                if let Some(scale) = value.pointer_mut("/features/remission_scale") {
                    *scale = serde_json::Value::Null;
                }
            }
        }
        let mut sections = vec!["grid.cell_size_m", "features"];
        // The appearance settings matter only where the hybrid model is used.
        if self.hybrid.is_some() && config.appearance.enabled {
            sections.push("appearance");
        }
        for section in sections {
            let pointer = format!("/{}", section.replace('.', "/"));
            let (model_value, value) = (trained.pointer(&pointer), wanted.pointer(&pointer));
            if model_value == value {
                continue;
            }
            let (setting, model_value, value) = first_difference(section, model_value, value);
            return Err(Error::ModelSettings {
                model: model_name.to_string(),
                setting,
                model_value,
                value,
            });
        }
        Ok(())
    }

    pub fn scratch(&self) -> PredictionScratch {
        PredictionScratch::default()
    }

    pub fn standardise<'s>(
        &self,
        features: &[f32],
        scratch: &'s mut PredictionScratch,
    ) -> &'s [f32] {
        scratch.standardised.resize(self.dimension(), 0.0);
        for (((z, &x), &m), &s) in scratch
            .standardised
            .iter_mut()
            .zip(features)
            .zip(&self.feature_mean)
            .zip(&self.feature_inverse_std)
        {
            *z = (x - m) * s;
        }
        &scratch.standardised
    }

    /// Decision value of one raw (unstandardised) feature row; > 0 is traversable.
    /// Uses the reduced set when the model has one.
    pub fn decision_value(&self, features: &[f32], scratch: &mut PredictionScratch) -> f32 {
        let gamma = self.gamma as f32;
        let z = self.standardise(features, scratch);
        match &self.reduced_set {
            Some(reduced) => reduced.blocks.rbf_sum(z, gamma) + reduced.bias,
            None => self.blocks.rbf_sum(z, gamma) - self.rho,
        }
    }

    /// The decision value over every support vector, reduced set or not.
    pub fn exact_decision_value(&self, features: &[f32], scratch: &mut PredictionScratch) -> f32 {
        let z = self.standardise(features, scratch);
        self.blocks.rbf_sum(z, self.gamma as f32) - self.rho
    }

    /// The decision value with or without the reduced set (`classifier.use_reduced_set`).
    fn decision_value_using(
        &self,
        features: &[f32],
        scratch: &mut PredictionScratch,
        use_reduced_set: bool,
    ) -> f32 {
        if use_reduced_set {
            self.decision_value(features, scratch)
        } else {
            self.exact_decision_value(features, scratch)
        }
    }

    /// The margin of one predictable cell, its decision value minus the model's
    /// threshold (positive: traversable): by the hybrid model when the cell has
    /// appearance values and the model has one, else by the geometric model; each by
    /// its reduced set when it has one and `use_reduced_set` says so.
    pub fn cell_margin(
        &self,
        geometric: &[f32],
        appearance: Option<&[f32]>,
        scratch: &mut PredictionScratch,
        use_reduced_set: bool,
    ) -> f32 {
        match (&self.hybrid, appearance) {
            (Some(hybrid), Some(appearance)) => {
                let mut row = std::mem::take(&mut scratch.row);
                row.clear();
                row.extend_from_slice(geometric);
                row.extend_from_slice(appearance);
                let value = hybrid.decision_value_using(&row, scratch, use_reduced_set);
                scratch.row = row;
                value - hybrid.threshold
            }
            _ => self.decision_value_using(geometric, scratch, use_reduced_set) - self.threshold,
        }
    }

    /// The class of one predictable cell (see [`Self::cell_margin`]).
    pub fn classify_cell(
        &self,
        geometric: &[f32],
        appearance: Option<&[f32]>,
        scratch: &mut PredictionScratch,
        use_reduced_set: bool,
    ) -> CellClass {
        CellClass::of_margin(self.cell_margin(geometric, appearance, scratch, use_reduced_set))
    }

    /// The model for features computed with `groups`: this one, or its fallback
    /// when the cloud had no usable remission.
    pub fn model_for(&self, groups: &[FeatureGroup]) -> &SvmModel {
        match &self.fallback {
            Some(fallback) if fallback.config.features.groups == groups => fallback,
            _ => self,
        }
    }

    /// The grid's remission when it lies far outside this model's training range
    /// ([`FOREIGN_REMISSION_DEVIATIONS`]): the model then classifies the grid without
    /// remission, by its fallback.
    pub fn foreign_remission(&self, grid: &FeatureGrid) -> Option<ForeignRemission> {
        if !grid.groups.contains(&FeatureGroup::Remission) {
            return None;
        }
        let column = crate::features::FEATURE_COUNT;
        let cells = (0..grid.predictable.len()).filter(|&cell| grid.predictable[cell]);
        self.foreign_remission_of(cells.map(|cell| grid.cell(cell)[column]).collect())
    }

    /// [`Self::foreign_remission`] of cells' `remission_mean` values.
    pub fn foreign_remission_of(&self, mut values: Vec<f32>) -> Option<ForeignRemission> {
        let column = crate::features::FEATURE_COUNT;
        if self.fallback.is_none() || values.is_empty() {
            return None;
        }
        let middle = values.len() / 2;
        let median = *values.select_nth_unstable_by(middle, f32::total_cmp).1;
        let (mean, std) = (
            *self.feature_mean.get(column)?,
            1.0 / *self.feature_inverse_std.get(column)?,
        );
        ((median - mean).abs() > FOREIGN_REMISSION_DEVIATIONS * std).then_some(ForeignRemission {
            median,
            trained_mean: mean,
            trained_std: std,
        })
    }

    /// The margin of every predictable cell of a grid (see [`Self::cell_margin`]);
    /// NaN for the others. With `foreign_remission = "fallback"`, a grid whose
    /// remission is foreign to the model ([`Self::foreign_remission`]) is classified
    /// without it.
    pub fn margins(&self, grid: &FeatureGrid, settings: &ClassifierConfig) -> Vec<f32> {
        if settings.foreign_remission == ForeignRemissionPolicy::Fallback
            && self.foreign_remission(grid).is_some()
            && let Some(without) = grid.without_remission()
        {
            return self.margins(&without, settings);
        }
        // A fallback adapted to drives carries its own prior: it is the sum.
        let model = self.model_for(&grid.groups);
        if !std::ptr::eq(model, self) && model.prior.is_some() {
            return model.margins(grid, settings);
        }
        let use_reduced_set = settings.use_reduced_set;
        let mut margins = self.own_margins(grid, use_reduced_set);
        let Some(prior) = &self.prior else {
            return margins;
        };
        // Cells whose margin came from a reduced set fitted to the sum already hold
        // the prior's: this model's own (not its fallback's), outside the hybrid's cells.
        let folded = use_reduced_set
            && self.reduced_set_includes_prior
            && self.reduced_set.is_some()
            && std::ptr::eq(self.model_for(&grid.groups), self);
        let by_hybrid = |cell: usize| self.hybrid.is_some() && grid.appearance(cell).is_some();
        if folded && !(0..margins.len()).any(by_hybrid) {
            return margins;
        }
        let weight = self.prior_weight;
        for (cell, (m, p)) in margins
            .iter_mut()
            .zip(prior.margins(grid, settings))
            .enumerate()
        {
            if !folded || by_hybrid(cell) {
                *m += weight * p;
            }
        }
        margins
    }

    /// [`Self::margins`] of this model alone, without its prior's.
    fn own_margins(&self, grid: &FeatureGrid, use_reduced_set: bool) -> Vec<f32> {
        let model = self.model_for(&grid.groups);
        let mut scratch = model.scratch();
        (0..grid.predictable.len())
            .map(|cell| {
                if grid.predictable[cell] {
                    model.cell_margin(
                        grid.cell(cell),
                        grid.appearance(cell),
                        &mut scratch,
                        use_reduced_set,
                    )
                } else {
                    f32::NAN
                }
            })
            .collect()
    }

    /// Classifies every predictable cell of a grid; the others stay unknown.
    pub fn classify(&self, grid: &FeatureGrid, settings: &ClassifierConfig) -> Vec<CellClass> {
        self.margins(grid, settings)
            .into_iter()
            .map(CellClass::of_margin)
            .collect()
    }
}

/// Deviations (of its training cells' `remission_mean`) from a model's training mean
/// beyond which a frame's median cell says the sensor's remission is on a scale the
/// model never saw. KITTI frames sit within 0.3 of the embedded model's mean;
/// RELLIS-3D's Ouster scan at 2.8 below it.
pub const FOREIGN_REMISSION_DEVIATIONS: f32 = 2.0;

/// A grid's remission, far from what a model learnt from.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ForeignRemission {
    /// The median over predictable cells of `remission_mean`.
    pub median: f32,
    /// The model's training mean and deviation of `remission_mean`.
    pub trained_mean: f32,
    pub trained_std: f32,
}

/// The first key (dotted, below `prefix`) where two configuration values differ,
/// with both values as TOML-like text.
fn first_difference(
    prefix: &str,
    a: Option<&serde_json::Value>,
    b: Option<&serde_json::Value>,
) -> (String, String, String) {
    if let (Some(serde_json::Value::Object(a)), Some(serde_json::Value::Object(b))) = (a, b)
        && let Some(key) = a.keys().find(|k| a.get(*k) != b.get(*k))
    {
        return first_difference(&format!("{prefix}.{key}"), a.get(key), b.get(key));
    }
    let text = |v: Option<&serde_json::Value>| v.map_or("nothing".into(), ToString::to_string);
    (prefix.to_string(), text(a), text(b))
}

/// The names of a model's `dimension` values under `config`: the geometric ones,
/// then the appearance ones when there are more (a hybrid model's).
pub fn model_feature_names(config: &Config, dimension: usize) -> Vec<String> {
    let mut names = feature_names(&config.features.groups);
    if dimension > names.len() {
        names.extend(appearance_feature_names(&config.appearance));
    }
    names
}

/// Names of the appearance values: hue, saturation and value buckets.
pub fn appearance_feature_names(config: &travmap_core::config::AppearanceConfig) -> Vec<String> {
    [
        ("hue", config.hue_bins),
        ("saturation", config.saturation_bins),
        ("value", config.value_bins),
    ]
    .iter()
    .flat_map(|&(prefix, n)| (0..n).map(move |i| format!("{prefix}_{i:02}")))
    .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_model_for_other_cell_sizes_is_refused() {
        let model = SvmModel::embedded(travmap_core::config::LabelRule::Road).unwrap();
        let mut config = Config::default();
        config.grid.cell_size_m = 0.5;
        config.features.subcell_size_m = 0.25;
        let err = model
            .check_compatible(&config, "m.json")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("m.json")
                && err.contains("grid.cell_size_m = 0.4")
                && err.contains("--set grid.cell_size_m=0.4"),
            "{err}"
        );
        config.grid.cell_size_m = 0.4;
        config.features.curvity_bins = 7;
        let err = model
            .check_compatible(&config, "m.json")
            .unwrap_err()
            .to_string();
        assert!(err.contains("--set features.curvity_bins=160"), "{err}");
    }
}
