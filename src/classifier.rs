//! Stage 4, classification (METHOD.md section 6): an RBF-kernel SVM on standardised
//! features, and its versioned model file.
//!
//! Input: a [`FeatureGrid`]. Output: one [`CellClass`] per cell. Prediction runs over
//! a flat f32 support-vector matrix with precomputed squared norms and one reused
//! buffer per grid, no allocation per cell. Training lives in [`training`], the
//! solver in [`smo`].

pub mod kernel;
pub mod smo;
pub mod training;

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::config::Config;
use crate::error::{Error, Result};
use crate::features::{FEATURE_NAMES, FeatureGrid};
use crate::grid::CellClass;

/// The format tag and version of model files this build reads and writes.
pub const MODEL_FORMAT: &str = "travmap-svm";
pub const MODEL_VERSION: u32 = 1;

/// The default geometry-only model, trained on the shipped labelled SemanticKITTI
/// frames (see README, "The embedded model").
pub const DEFAULT_MODEL_JSON: &[u8] = include_bytes!("classifier/default_model.json");

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
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SearchResult {
    pub c: f64,
    pub gamma: f64,
    pub accuracy: f64,
}

/// The model file: a JSON document, versioned.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ModelFile {
    format: String,
    version: u32,
    feature_names: Vec<String>,
    feature_mean: Vec<f32>,
    feature_std: Vec<f32>,
    c: f64,
    gamma: f64,
    rho: f64,
    /// `alpha_i * y_i` per support vector.
    dual_coefficients: Vec<f32>,
    /// Standardised support vectors, one row each.
    support_vectors: Vec<Vec<f32>>,
    /// The effective configuration the training cells were made with.
    config: Config,
    training: TrainingSummary,
    #[serde(default)]
    reduced_set: Option<ReducedSetFile>,
    /// The hybrid model (geometric + appearance features) for cells a camera has seen.
    #[serde(default)]
    hybrid: Option<Box<ModelFile>>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ReducedSetFile {
    /// Standardised kernel centres, one row each.
    centres: Vec<Vec<f32>>,
    weights: Vec<f32>,
    bias: f32,
    training_agreement: f64,
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
    /// 1 / standard deviation per feature (1 for constant features).
    pub feature_inverse_std: Vec<f32>,
    pub c: f64,
    pub gamma: f64,
    pub rho: f32,
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
            dual_coefficients,
            support_vectors,
            blocks,
            config,
            training,
            reduced_set: None,
            hybrid: None,
        }
    }

    /// The model compiled into the binary.
    pub fn embedded_default() -> Result<Self> {
        Self::from_json(DEFAULT_MODEL_JSON, "embedded default model")
    }

    pub fn dimension(&self) -> usize {
        self.feature_mean.len()
    }

    pub fn support_vector_count(&self) -> usize {
        self.dual_coefficients.len()
    }

    /// Reads a model file, checking format, version, shapes and finiteness.
    pub fn from_json(bytes: &[u8], source_name: &str) -> Result<Self> {
        let fail = |message: String| Error::Model {
            source_name: source_name.to_string(),
            message,
        };
        let header: serde_json::Value = serde_json::from_slice(bytes)
            .map_err(|e| fail(format!("not a JSON model file: {e}")))?;
        let format = header.get("format").and_then(|f| f.as_str());
        let version = header.get("version").and_then(|v| v.as_u64());
        if format != Some(MODEL_FORMAT) || version != Some(MODEL_VERSION as u64) {
            return Err(fail(format!(
                "format {format:?} version {version:?}; this travmap reads \"{MODEL_FORMAT}\" version {MODEL_VERSION}"
            )));
        }
        let file: ModelFile =
            serde_json::from_value(header).map_err(|e| fail(format!("malformed model: {e}")))?;
        let names: Vec<String> = FEATURE_NAMES.iter().map(|n| n.to_string()).collect();
        Self::from_file(file, source_name, &names)
    }

    /// Checks and loads one model of a file; `expected_names` are its features.
    fn from_file(file: ModelFile, source_name: &str, expected_names: &[String]) -> Result<Self> {
        let fail = |message: String| Error::Model {
            source_name: source_name.to_string(),
            message,
        };
        let d = expected_names.len();
        if file.feature_names != expected_names {
            return Err(fail(format!(
                "features {:?}; this travmap computes {:?}",
                file.feature_names, expected_names
            )));
        }
        if file.feature_mean.len() != d || file.feature_std.len() != d {
            return Err(fail(format!("{d} means and deviations expected")));
        }
        if file.support_vectors.len() != file.dual_coefficients.len() {
            return Err(fail(format!(
                "{} support vectors but {} coefficients",
                file.support_vectors.len(),
                file.dual_coefficients.len()
            )));
        }
        if let Some((i, sv)) = file
            .support_vectors
            .iter()
            .enumerate()
            .find(|(_, sv)| sv.len() != d)
        {
            return Err(fail(format!(
                "support vector {i} has {} values, expected {d}",
                sv.len()
            )));
        }
        let numbers = file
            .feature_mean
            .iter()
            .chain(&file.feature_std)
            .chain(&file.dual_coefficients)
            .chain(file.support_vectors.iter().flatten());
        if numbers.clone().any(|v| !v.is_finite())
            || !(file.gamma.is_finite() && file.gamma > 0.0 && file.rho.is_finite())
            || file.feature_std.iter().any(|s| *s <= 0.0)
        {
            return Err(fail("non-finite or non-positive parameters".into()));
        }
        file.config.validate()?;
        let hybrid = match file.hybrid {
            Some(hybrid) => {
                let mut names = expected_names.to_vec();
                names.extend(appearance_feature_names(&file.config.appearance));
                Some(Box::new(Self::from_file(
                    *hybrid,
                    &format!("{source_name} (hybrid model)"),
                    &names,
                )?))
            }
            None => None,
        };
        let reduced_set = match file.reduced_set {
            None => None,
            Some(r) => {
                if r.centres.len() != r.weights.len() || r.centres.iter().any(|c| c.len() != d) {
                    return Err(fail(format!(
                        "reduced set: {} centres, {} weights, {d} values per centre expected",
                        r.centres.len(),
                        r.weights.len()
                    )));
                }
                if r.centres
                    .iter()
                    .flatten()
                    .chain(&r.weights)
                    .any(|v| !v.is_finite())
                    || !r.bias.is_finite()
                {
                    return Err(fail("reduced set: non-finite parameters".into()));
                }
                Some(ReducedSet::new(
                    r.centres.concat(),
                    r.weights,
                    r.bias,
                    r.training_agreement,
                ))
            }
        };
        let mut model = Self::new(
            file.feature_mean,
            file.feature_std.iter().map(|s| 1.0 / s).collect(),
            file.c,
            file.gamma,
            file.rho as f32,
            file.dual_coefficients,
            file.support_vectors.concat(),
            file.config,
            file.training,
        );
        model.reduced_set = reduced_set;
        model.hybrid = hybrid;
        Ok(model)
    }

    /// Feature names: the geometric ones, plus the appearance ones for a hybrid model.
    pub fn feature_names(&self) -> Vec<String> {
        let mut names: Vec<String> = FEATURE_NAMES.iter().map(|n| n.to_string()).collect();
        if self.dimension() > FEATURE_NAMES.len() {
            names.extend(appearance_feature_names(&self.config.appearance));
        }
        names
    }

    fn to_file(&self) -> ModelFile {
        let d = self.dimension();
        ModelFile {
            format: MODEL_FORMAT.into(),
            version: MODEL_VERSION,
            feature_names: self.feature_names(),
            feature_mean: self.feature_mean.clone(),
            feature_std: self.feature_inverse_std.iter().map(|s| 1.0 / s).collect(),
            c: self.c,
            gamma: self.gamma,
            rho: self.rho as f64,
            dual_coefficients: self.dual_coefficients.clone(),
            support_vectors: self
                .support_vectors
                .chunks_exact(d)
                .map(<[f32]>::to_vec)
                .collect(),
            config: self.config.clone(),
            training: self.training.clone(),
            reduced_set: self.reduced_set.as_ref().map(|r| ReducedSetFile {
                centres: r.centres.chunks_exact(d).map(<[f32]>::to_vec).collect(),
                weights: r.weights.clone(),
                bias: r.bias,
                training_agreement: r.training_agreement,
            }),
            hybrid: self.hybrid.as_ref().map(|h| Box::new(h.to_file())),
        }
    }

    pub fn to_json(&self) -> Vec<u8> {
        let mut bytes = serde_json::to_vec(&self.to_file()).expect("model serialises");
        bytes.push(b'\n');
        bytes
    }

    /// SHA-256 of the model file, to name exactly which model produced a result.
    pub fn sha256_hex(&self) -> String {
        Sha256::digest(self.to_json())
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect()
    }

    /// Errors when `config` would compute features differently from the training cells.
    pub fn check_compatible(&self, config: &Config) -> Result<()> {
        let trained = &self.config;
        let mismatch = if trained.grid.cell_size_m != config.grid.cell_size_m {
            Some(format!(
                "grid.cell_size_m = {} (model) vs {}",
                trained.grid.cell_size_m, config.grid.cell_size_m
            ))
        } else if self.hybrid.is_some()
            && trained.appearance != config.appearance
            && config.appearance.enabled
        {
            Some(format!(
                "appearance = {:?} (model) vs {:?}",
                trained.appearance, config.appearance
            ))
        } else if trained.features != config.features {
            Some(format!(
                "features = {:?} (model) vs {:?}",
                trained.features, config.features
            ))
        } else {
            None
        };
        match mismatch {
            Some(m) => Err(Error::Model {
                source_name: "model".into(),
                message: format!("trained with different feature settings: {m}"),
            }),
            None => Ok(()),
        }
    }

    pub fn scratch(&self) -> PredictionScratch {
        PredictionScratch::default()
    }

    pub(crate) fn standardise<'s>(
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

    /// The class of one predictable cell: by the hybrid model when the cell has
    /// appearance values and the model has one, else by the geometric model.
    pub fn classify_cell(
        &self,
        geometric: &[f32],
        appearance: Option<&[f32]>,
        scratch: &mut PredictionScratch,
    ) -> CellClass {
        let value = match (&self.hybrid, appearance) {
            (Some(hybrid), Some(appearance)) => {
                let mut row = std::mem::take(&mut scratch.row);
                row.clear();
                row.extend_from_slice(geometric);
                row.extend_from_slice(appearance);
                let value = hybrid.decision_value(&row, scratch);
                scratch.row = row;
                value
            }
            _ => self.decision_value(geometric, scratch),
        };
        if value > 0.0 {
            CellClass::Traversable
        } else {
            CellClass::NonTraversable
        }
    }

    /// Classifies every predictable cell of a grid; the others stay unknown.
    pub fn classify(&self, grid: &FeatureGrid) -> Vec<CellClass> {
        let mut scratch = self.scratch();
        (0..grid.predictable.len())
            .map(|cell| {
                if grid.predictable[cell] {
                    self.classify_cell(grid.cell(cell), grid.appearance(cell), &mut scratch)
                } else {
                    CellClass::Unknown
                }
            })
            .collect()
    }
}

/// Names of the appearance values: hue, saturation and value buckets.
pub fn appearance_feature_names(config: &crate::config::AppearanceConfig) -> Vec<String> {
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
    fn embedded_model_loads_and_round_trips() {
        let model = SvmModel::embedded_default().expect("the shipped model must load");
        assert!(model.support_vector_count() > 0);
        assert_eq!(model.dimension(), FEATURE_NAMES.len());
        model.check_compatible(&Config::default()).unwrap();
        let again = SvmModel::from_json(&model.to_json(), "round trip").unwrap();
        assert_eq!(again.to_json(), model.to_json());
    }

    #[test]
    fn wrong_version_and_shapes_are_clear_errors() {
        let model = SvmModel::embedded_default().unwrap();
        let mut json: serde_json::Value = serde_json::from_slice(&model.to_json()).unwrap();
        json["version"] = 99.into();
        let err = SvmModel::from_json(json.to_string().as_bytes(), "m.json")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("m.json") && err.contains("version Some(99)"),
            "{err}"
        );
        json["version"] = MODEL_VERSION.into();
        json["dual_coefficients"] = serde_json::json!([1.0]);
        let err = SvmModel::from_json(json.to_string().as_bytes(), "m.json")
            .unwrap_err()
            .to_string();
        assert!(err.contains("coefficients"), "{err}");
        assert!(SvmModel::from_json(b"{", "m.json").is_err());
    }

    #[test]
    fn a_model_for_other_cell_sizes_is_refused() {
        let model = SvmModel::embedded_default().unwrap();
        let mut config = Config::default();
        config.grid.cell_size_m = 0.5;
        config.features.subcell_size_m = 0.25;
        assert!(model.check_compatible(&config).is_err());
    }
}
