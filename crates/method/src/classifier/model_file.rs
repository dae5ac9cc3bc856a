//! The model file: a versioned JSON document holding the geometric SVM, its reduced
//! set and the hybrid model, plus the default model compiled into the binary.

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::{CheckCells, ReducedSet, SvmModel, TrainingSummary, appearance_feature_names};
use crate::features::feature_names;
use travmap_core::config::{
    Config, FeatureGroup, LabelRule, MAX_SVM_C, MAX_SVM_GAMMA, ModelChoice, check_within,
    written_before_groups,
};
use travmap_core::error::{Error, Result};
use travmap_core::option_files::{MODEL_MAX_BYTES, read_option_file};

/// The format tag and version of model files this build reads and writes.
pub const MODEL_FORMAT: &str = "travmap-svm";
pub const MODEL_VERSION: u32 = 1;

/// The models compiled into the binary, one per rule of what is traversable, trained
/// on every labelled scan shipped (docs/method.md, "The embedded models").
const ROAD_MODEL_JSON: &[u8] = include_bytes!("road_model.json");
const OFFROAD_MODEL_JSON: &[u8] = include_bytes!("offroad_model.json");

/// The model file: a JSON document, versioned.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ModelFile {
    format: String,
    version: u32,
    feature_names: Vec<String>,
    feature_mean: Vec<f32>,
    /// 1 for a left-out feature.
    feature_std: Vec<f32>,
    /// Features the model does not look at: their standardised values are 0.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    left_out_features: Vec<String>,
    c: f64,
    gamma: f64,
    rho: f64,
    /// The decision threshold (0 in models from before it existed).
    #[serde(default)]
    threshold: f64,
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
    /// The model without remission features, for clouds without usable intensity;
    /// present exactly when this one uses remission.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    fallback: Option<Box<ModelFile>>,
    /// The model this one adapts, whose margins add to its own times `prior_weight`
    /// (adaptation's `sum` learner).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    prior: Option<Box<ModelFile>>,
    #[serde(default, skip_serializing_if = "is_zero")]
    prior_weight: f32,
    /// The reduced set is fitted to this model's margin plus the prior's.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    reduced_set_includes_prior: bool,
    /// A few cells and the decisions this model made of them when it was written: a
    /// file whose parameters were changed since (by hand, or by a broken copy)
    /// decides them otherwise, and is refused (absent in files from before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    check_cells: Option<CheckCells>,
    /// The margin as P(traversable) (absent: the uncalibrated sigmoid).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    calibration: Option<super::calibration::Calibration>,
}

/// Cells a model file stores to check it by ([`CheckCells`]): its support vectors
/// spread over the list, which lie near the boundary, where a changed parameter
/// moves the decision most.
const CHECK_CELL_COUNT: usize = 8;

/// How far a margin recomputed from a file may lie from the stored one: another
/// CPU's `exp` may differ in the last bit; a changed parameter moves margins by
/// hundredths or more.
fn reproduces(stored: f32, computed: f32) -> bool {
    (stored - computed).abs() <= 1e-3 * (1.0 + stored.abs())
}

fn is_zero(value: &f32) -> bool {
    *value == 0.0
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

/// What a compiled-in model is called in reports.
pub fn embedded_name(rule: LabelRule) -> String {
    format!("embedded {} model", rule.name())
}

/// Every configuration in a model file (the model's, its hybrid's and fallback's),
/// read as [`written_before_groups`] says.
fn older_configs(model: &mut serde_json::Value) {
    if let Some(config) = model.get_mut("config") {
        written_before_groups(config);
    }
    for part in ["hybrid", "fallback", "prior"] {
        if let Some(inner) = model.get_mut(part).filter(|p| p.is_object()) {
            older_configs(inner);
        }
    }
}

/// A model file's bytes: its JSON on one line.
fn file_bytes(file: &ModelFile) -> Vec<u8> {
    let mut bytes = serde_json::to_vec(file).expect("model serialises");
    bytes.push(b'\n');
    bytes
}

/// Whether a model's stored decisions are recomputed when it is read: a file's are;
/// the compiled-in models' are checked by the unit tests instead.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Decisions {
    Checked,
    Trusted,
}

/// The first number of a JSON document beyond what an f32 holds, with its path
/// (`support_vectors[3][2]`) and its value as written.
fn beyond_f32(value: &serde_json::Value, path: String) -> Option<(String, String)> {
    use serde_json::Value;
    match value {
        Value::Number(n) => {
            let v = n.as_f64()?;
            (v.abs() > f64::from(f32::MAX)).then(|| (path, format!("{v:e}")))
        }
        Value::Array(items) => (items.iter().enumerate())
            .find_map(|(i, item)| beyond_f32(item, format!("{path}[{i}]"))),
        Value::Object(fields) => fields.iter().find_map(|(key, item)| {
            let inner = match path.is_empty() {
                true => key.clone(),
                false => format!("{path}.{key}"),
            };
            beyond_f32(item, inner)
        }),
        _ => None,
    }
}

/// Why a model file's decision could not depend on the cell, if it could not: no
/// support vectors, or offsets beyond what every kernel term together can outweigh
/// (every cell would get one class).
fn constant_decision(file: &ModelFile) -> Option<String> {
    if file.support_vectors.is_empty() {
        return Some("no support vectors: a model decides by at least one (was it trained on cells of one class?)".into());
    }
    let weights: f64 = file
        .dual_coefficients
        .iter()
        .map(|a| f64::from(a.abs()))
        .sum();
    let offset = file.rho + file.threshold;
    if offset.abs() >= weights {
        return Some(format!(
            "`rho` {} and `threshold` {} outweigh every support vector together (their coefficients' magnitudes sum to {weights:.4}): every cell would be called {}",
            file.rho,
            file.threshold,
            if offset > 0.0 {
                "not traversable"
            } else {
                "traversable"
            }
        ));
    }
    let reduced = file.reduced_set.as_ref()?;
    if reduced.weights.is_empty() {
        return Some("a reduced set of no centres: it would decide every cell alike".into());
    }
    let weights: f64 = reduced.weights.iter().map(|w| f64::from(w.abs())).sum();
    let offset = f64::from(reduced.bias) - file.threshold;
    (offset.abs() >= weights).then(|| {
        format!(
            "the reduced set's `bias` {} outweighs its centres together (their weights' magnitudes sum to {weights:.4}): every cell would be called {}",
            reduced.bias,
            if offset > 0.0 { "traversable" } else { "not traversable" }
        )
    })
}

impl SvmModel {
    /// The chosen model, compiled in or a file, checked against `config`; with the
    /// name to report it by.
    pub fn load(choice: &ModelChoice, config: &Config) -> Result<(Self, String)> {
        let (model, name) = Self::read(choice)?;
        model.check_compatible(config, &name)?;
        Ok((model, name))
    }

    /// The chosen model as stored, not yet checked against a configuration; with
    /// the name to report it by.
    pub fn read(choice: &ModelChoice) -> Result<(Self, String)> {
        match choice {
            ModelChoice::File(path) => {
                let bytes = read_option_file(path, MODEL_MAX_BYTES)?;
                let name = path.display().to_string();
                let model = Self::from_json(&bytes, &name).map_err(|e| e.of_model_file(path))?;
                Ok((model, name))
            }
            ModelChoice::Embedded(rule) => Ok((Self::embedded(*rule)?, embedded_name(*rule))),
        }
    }

    /// The model compiled into the binary that learnt `rule`.
    pub fn embedded(rule: LabelRule) -> Result<Self> {
        let json = match rule {
            LabelRule::Road => ROAD_MODEL_JSON,
            LabelRule::Offroad => OFFROAD_MODEL_JSON,
        };
        let name = embedded_name(rule);
        // Written by this travmap, a compiled-in model needs neither a file's
        // migrations nor its errors that name the field: read straight into its types,
        // not through a JSON tree (a fifth of a one-frame run).
        let file: ModelFile = serde_json::from_slice(json).map_err(|e| Error::Model {
            source_name: name.clone(),
            message: format!("malformed model: {e}"),
            file: None,
        })?;
        // Its stored decisions are checked by the unit tests, not at every start.
        Self::from_model_file(file, &name, Decisions::Trusted)
    }

    /// Reads a model file, checking format, version, shapes and finiteness.
    pub fn from_json(bytes: &[u8], source_name: &str) -> Result<Self> {
        let fail = |message: String| Error::Model {
            source_name: source_name.to_string(),
            message,
            file: None,
        };
        let header: serde_json::Value = serde_json::from_slice(bytes)
            .map_err(|e| fail(format!("not a JSON model file: {e}")))?;
        let format = header.get("format").and_then(|f| f.as_str());
        let version = header.get("version").and_then(|v| v.as_u64());
        if format != Some(MODEL_FORMAT) || version != Some(MODEL_VERSION as u64) {
            return Err(Error::ModelVersion {
                source_name: source_name.to_string(),
                file: None,
                format: format.unwrap_or("none").to_string(),
                version: version.map_or("none".into(), |v| v.to_string()),
                expected_format: MODEL_FORMAT,
                expected_version: MODEL_VERSION,
            });
        }
        if let Some((path, value)) = beyond_f32(&header, String::new()) {
            return Err(fail(format!(
                "`{path}` is {value}, beyond the range of the 32-bit numbers a model computes with (magnitude at most {:e})",
                f32::MAX
            )));
        }
        let mut header = header;
        older_configs(&mut header);
        // The error names the field (`gamma`, `config.grid.size_m`) where serde's alone
        // would not.
        let file: ModelFile = serde_path_to_error::deserialize(header)
            .map_err(|e| fail(format!("malformed model: `{}`: {}", e.path(), e.inner())))?;
        Self::from_model_file(file, source_name, Decisions::Checked)
    }

    /// The model of a file read, checked.
    fn from_model_file(file: ModelFile, source_name: &str, decisions: Decisions) -> Result<Self> {
        let fail = |message: String| Error::Model {
            source_name: source_name.to_string(),
            message,
            file: None,
        };
        let names = feature_names(&file.config.features.groups);
        let model = Self::from_file(file, source_name, &names, decisions)?;
        let uses_remission = model
            .config
            .features
            .groups
            .contains(&FeatureGroup::Remission);
        if uses_remission != model.fallback.is_some() {
            return Err(fail(
                "a model with remission features carries a fallback model without them, and only such a model does".into(),
            ));
        }
        Ok(model)
    }

    /// Checks and loads one model of a file; `expected_names` are its features.
    fn from_file(
        file: ModelFile,
        source_name: &str,
        expected_names: &[String],
        decisions: Decisions,
    ) -> Result<Self> {
        let fail = |message: String| Error::Model {
            source_name: source_name.to_string(),
            message,
            file: None,
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
        // The first parameter out of range, named as the file names it.
        let lists: [(&str, &[f32]); 3] = [
            ("feature_mean", &file.feature_mean),
            ("feature_std", &file.feature_std),
            ("dual_coefficients", &file.dual_coefficients),
        ];
        let in_lists = lists.iter().find_map(|(name, values)| {
            let at = values.iter().position(|v| !v.is_finite())?;
            Some(format!(
                "`{name}[{at}]` is {}, a finite number expected",
                values[at]
            ))
        });
        let in_vectors = || {
            let (i, sv) = (file.support_vectors.iter().enumerate())
                .find(|(_, sv)| sv.iter().any(|v| !v.is_finite()))?;
            let at = sv.iter().position(|v| !v.is_finite())?;
            Some(format!(
                "`support_vectors[{i}][{at}]` is {}, a finite number expected",
                sv[at]
            ))
        };
        // C and gamma as training searches and fits them; a decision's offsets as
        // 32-bit numbers hold them.
        let largest = f64::from(f32::MAX);
        let scalars = [
            ("c", file.c, (0.0, MAX_SVM_C)),
            ("gamma", file.gamma, (0.0, MAX_SVM_GAMMA)),
            ("rho", file.rho, (-largest, largest)),
            ("threshold", file.threshold, (-largest, largest)),
        ];
        let in_scalars = || {
            scalars.iter().find_map(|&(name, value, range)| {
                check_within(&format!("`{name}`"), value, range).err()
            })
        };
        let in_std = || {
            let at = file.feature_std.iter().position(|s| *s <= 0.0)?;
            Some(format!(
                "`feature_std[{at}]` is {}, a positive deviation expected (a left-out feature is written 1)",
                file.feature_std[at]
            ))
        };
        if let Some(problem) = in_lists
            .or_else(in_vectors)
            .or_else(in_scalars)
            .or_else(in_std)
            .or_else(|| constant_decision(&file))
        {
            return Err(fail(problem));
        }
        if let Some(name) = file
            .left_out_features
            .iter()
            .find(|name| !expected_names.contains(name))
        {
            return Err(fail(format!(
                "left out feature {name:?} is not one of its features"
            )));
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
                    decisions,
                )?))
            }
            None => None,
        };
        let fallback = match file.fallback {
            Some(fallback) => {
                let features = file.config.features.without_remission();
                if fallback.config.features != features {
                    return Err(fail(format!(
                        "fallback model: features {:?}, expected {features:?}",
                        fallback.config.features
                    )));
                }
                let names = feature_names(&features.groups);
                let source = format!("{source_name} (fallback model)");
                Some(Box::new(Self::from_file(
                    *fallback, &source, &names, decisions,
                )?))
            }
            None => None,
        };
        let prior = match file.prior {
            Some(prior) => {
                let source = format!("{source_name} (prior model)");
                let names = feature_names(&prior.config.features.groups);
                if names != expected_names {
                    return Err(fail(format!(
                        "prior model: features {names:?}, expected {expected_names:?}"
                    )));
                }
                Some(Box::new(Self::from_file(
                    *prior, &source, &names, decisions,
                )?))
            }
            None => None,
        };
        if !(file.prior_weight.is_finite() && file.prior_weight >= 0.0) {
            return Err(fail(format!("prior_weight {}", file.prior_weight)));
        }
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
        let inverse_std = expected_names
            .iter()
            .zip(&file.feature_std)
            .map(|(name, s)| match file.left_out_features.contains(name) {
                true => 0.0,
                false => 1.0 / s,
            })
            .collect();
        let mut model = Self::new(
            file.feature_mean,
            inverse_std,
            file.c,
            file.gamma,
            file.rho as f32,
            file.dual_coefficients,
            file.support_vectors.concat(),
            file.config,
            file.training,
        );
        model.threshold = file.threshold as f32;
        model.reduced_set = reduced_set;
        model.hybrid = hybrid;
        model.fallback = fallback;
        if file.reduced_set_includes_prior && prior.is_none() {
            return Err(fail(
                "a reduced set that includes a prior, without the prior".into(),
            ));
        }
        model.prior = prior;
        model.prior_weight = file.prior_weight;
        model.reduced_set_includes_prior = file.reduced_set_includes_prior;
        if let (Some(cells), Decisions::Checked) = (&file.check_cells, decisions) {
            model.decides_as_written(cells).map_err(fail)?;
        }
        model.check_cells = file.check_cells;
        if let Some(calibration) = file.calibration {
            if !calibration.is_plausible() {
                return Err(fail(format!(
                    "`calibration` a {} b {}: a finite sigmoid rising with the margin (a < 0) expected",
                    calibration.a, calibration.b
                )));
            }
            model.calibration = Some(calibration);
        }
        Ok(model)
    }

    /// The cells a file of this model stores to check it by, and their margins
    /// ([`CheckCells`]); none without support vectors.
    fn new_check_cells(&self) -> Option<CheckCells> {
        let count = self.support_vector_count();
        if count == 0 {
            return None;
        }
        let raw = self.support_vectors_raw();
        let d = self.dimension();
        let taken = CHECK_CELL_COUNT.min(count);
        let features: Vec<Vec<f32>> = (0..taken)
            .map(|k| k * count / taken)
            .map(|i| raw[i * d..(i + 1) * d].to_vec())
            .collect();
        let (exact, reduced) = features
            .iter()
            .map(|row| self.slow_margins(row))
            .unzip::<_, _, Vec<_>, Vec<_>>();
        Some(CheckCells {
            features,
            exact,
            reduced: reduced.into_iter().flatten().collect(),
        })
    }

    /// A cell's margin over every support vector, and by the reduced set when there
    /// is one: the obvious sums in f64, the same on every CPU (the fast kernel's
    /// order and fused steps differ between CPUs; a file's bytes must not).
    fn slow_margins(&self, row: &[f32]) -> (f32, Option<f32>) {
        let z: Vec<f64> = (row
            .iter()
            .zip(&self.feature_mean)
            .zip(&self.feature_inverse_std))
        .map(|((&x, &m), &s)| f64::from((x - m) * s))
        .collect();
        let gamma = self.gamma;
        let expansion = |centres: &[f32], weights: &[f32]| -> f64 {
            (centres.chunks_exact(z.len()).zip(weights))
                .map(|(centre, &w)| {
                    let squared: f64 = (centre.iter().zip(&z))
                        .map(|(&c, &v)| (f64::from(c) - v).powi(2))
                        .sum();
                    f64::from(w) * (-gamma * squared).exp()
                })
                .sum()
        };
        let threshold = f64::from(self.threshold);
        let exact = expansion(&self.support_vectors, &self.dual_coefficients)
            - f64::from(self.rho)
            - threshold;
        let reduced = (self.reduced_set.as_ref())
            .map(|r| expansion(&r.centres, &r.weights) + f64::from(r.bias) - threshold);
        (exact as f32, reduced.map(|m| m as f32))
    }

    /// Whether this model, as read, decides the file's check cells as the model that
    /// wrote it did; the first that differs, said, if not.
    fn decides_as_written(&self, cells: &CheckCells) -> std::result::Result<(), String> {
        let d = self.dimension();
        let n = cells.features.len();
        let reduced_count = if self.reduced_set.is_some() { n } else { 0 };
        if cells.features.iter().any(|row| row.len() != d)
            || cells.exact.len() != n
            || cells.reduced.len() != reduced_count
        {
            return Err(format!(
                "`check_cells`: rows of {d} values, and a margin per row ({reduced_count} by the reduced set) expected"
            ));
        }
        for (i, row) in cells.features.iter().enumerate() {
            let (exact, reduced) = self.slow_margins(row);
            let stored = [Some(cells.exact[i]), cells.reduced.get(i).copied()];
            let names = ["the margin", "the reduced set's margin"];
            for ((name, stored), computed) in names.iter().zip(stored).zip([Some(exact), reduced]) {
                if let (Some(stored), Some(computed)) = (stored, computed)
                    && !reproduces(stored, computed)
                {
                    return Err(format!(
                        "its parameters do not decide the cells stored with it as when it was written ({name} of check cell {i}: the file says {stored}, these parameters give {computed}); the file was changed after it was written: train or adapt it again"
                    ));
                }
            }
        }
        Ok(())
    }

    fn to_file(&self) -> ModelFile {
        let d = self.dimension();
        ModelFile {
            format: MODEL_FORMAT.into(),
            version: MODEL_VERSION,
            feature_names: self.feature_names(),
            feature_mean: self.feature_mean.clone(),
            feature_std: self
                .feature_inverse_std
                .iter()
                .map(|&s| if s == 0.0 { 1.0 } else { 1.0 / s })
                .collect(),
            left_out_features: self.left_out_features(),
            c: self.c,
            gamma: self.gamma,
            rho: self.rho as f64,
            threshold: self.threshold as f64,
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
            fallback: self.fallback.as_ref().map(|f| Box::new(f.to_file())),
            prior: self.prior.as_ref().map(|p| Box::new(p.to_file())),
            prior_weight: self.prior_weight,
            reduced_set_includes_prior: self.reduced_set_includes_prior,
            check_cells: self.check_cells.clone().or_else(|| self.new_check_cells()),
            calibration: self.calibration,
        }
    }

    pub fn to_json(&self) -> Vec<u8> {
        file_bytes(&self.to_file())
    }

    /// SHA-256 of the model file with its training times left out (`seconds` as 0
    /// at every level), to name exactly which model produced a result: the same
    /// cells and settings give the same hash, however long training took.
    pub fn sha256_hex(&self) -> String {
        fn untimed(file: &mut ModelFile) {
            file.training.seconds = 0.0;
            for inner in [&mut file.hybrid, &mut file.fallback, &mut file.prior]
                .into_iter()
                .flatten()
            {
                untimed(inner);
            }
        }
        let mut file = self.to_file();
        untimed(&mut file);
        Sha256::digest(file_bytes(&file))
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::feature_count;

    #[test]
    fn embedded_models_load_and_round_trip() {
        for rule in LabelRule::ALL {
            let model = SvmModel::embedded(rule).expect("the shipped models must load");
            assert!(model.support_vector_count() > 0);
            assert_eq!(
                model.dimension(),
                feature_count(&Config::default().features.groups)
            );
            model
                .check_compatible(&Config::default(), "embedded")
                .unwrap();
            // Each learnt its rule.
            assert_eq!(model.config.ground_truth.rule, rule);
            let again = SvmModel::from_json(&model.to_json(), "round trip").unwrap();
            assert_eq!(again.to_json(), model.to_json());
            // Read straight into its types, as a file of it reads.
            let stored = match rule {
                LabelRule::Road => ROAD_MODEL_JSON,
                LabelRule::Offroad => OFFROAD_MODEL_JSON,
            };
            assert_eq!(
                SvmModel::from_json(stored, &embedded_name(rule)).unwrap(),
                model
            );
            // It looks at no feature the default training leaves out, and the file
            // says so.
            let left_out = Config::default().training.left_out_features;
            assert_eq!(model.left_out_features(), left_out);
            assert_eq!(again.feature_inverse_std, model.feature_inverse_std);
        }
    }

    #[test]
    fn a_left_out_feature_must_be_one_of_the_models() {
        let model = SvmModel::embedded(LabelRule::Road).unwrap();
        let mut json: serde_json::Value = serde_json::from_slice(&model.to_json()).unwrap();
        json["left_out_features"] = serde_json::json!(["wheel_count"]);
        let err = SvmModel::from_json(json.to_string().as_bytes(), "m.json")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("m.json") && err.contains("\"wheel_count\""),
            "{err}"
        );
    }

    #[test]
    fn wrong_version_and_shapes_are_clear_errors() {
        let model = SvmModel::embedded(LabelRule::Road).unwrap();
        let mut json: serde_json::Value = serde_json::from_slice(&model.to_json()).unwrap();
        json["version"] = 99.into();
        let err = SvmModel::from_json(json.to_string().as_bytes(), "m.json")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("m.json") && err.contains("version 99;"),
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

    /// The road model's file with `edit` applied, read back: the error, if refused.
    fn refusal(edit: impl Fn(&mut serde_json::Value)) -> Option<String> {
        let model = SvmModel::embedded(LabelRule::Road).unwrap();
        let mut json: serde_json::Value = serde_json::from_slice(&model.to_json()).unwrap();
        edit(&mut json);
        SvmModel::from_json(json.to_string().as_bytes(), "m.json")
            .err()
            .map(|e| e.to_string())
    }

    #[test]
    fn numbers_beyond_f32_are_said_as_written() {
        let err = refusal(|m| m["gamma"] = serde_json::json!(1e300)).unwrap();
        assert!(err.contains("`gamma` is 1e300, beyond the range"), "{err}");
        let err = refusal(|m| m["rho"] = serde_json::json!(-1e300)).unwrap();
        assert!(err.contains("`rho` is -1e300"), "{err}");
        let err = refusal(|m| m["support_vectors"][3][2] = serde_json::json!(1e39)).unwrap();
        assert!(err.contains("`support_vectors[3][2]` is 1e39"), "{err}");
    }

    #[test]
    fn implausible_parameters_are_refused() {
        let err = refusal(|m| m["gamma"] = serde_json::json!(5e4)).unwrap();
        assert!(
            err.contains("`gamma` must be in (0.0, 10000.0], got 50000.0"),
            "{err}"
        );
        let err = refusal(|m| m["c"] = serde_json::json!(0.0)).unwrap();
        assert!(err.contains("`c` must be in"), "{err}");
        // An offset no kernel sum can outweigh: one class for every cell.
        let err = refusal(|m| m["rho"] = serde_json::json!(1e30)).unwrap();
        assert!(
            err.contains("every cell would be called not traversable"),
            "{err}"
        );
        let err = refusal(|m| m["reduced_set"]["bias"] = serde_json::json!(1e6)).unwrap();
        assert!(
            err.contains("every cell would be called traversable"),
            "{err}"
        );
    }

    #[test]
    fn a_model_without_support_vectors_is_refused() {
        let empty = |m: &mut serde_json::Value| {
            m["support_vectors"] = serde_json::json!([]);
            m["dual_coefficients"] = serde_json::json!([]);
            m["check_cells"] = serde_json::Value::Null;
        };
        // With its reduced set (which stood in for the support vectors it lost) and
        // without.
        let err = refusal(empty).unwrap();
        assert!(err.contains("no support vectors"), "{err}");
        let err = refusal(|m| {
            empty(m);
            m["reduced_set"] = serde_json::Value::Null;
        })
        .unwrap();
        assert!(err.contains("no support vectors"), "{err}");
        let err = refusal(|m| {
            m["reduced_set"]["centres"] = serde_json::json!([]);
            m["reduced_set"]["weights"] = serde_json::json!([]);
        })
        .unwrap();
        assert!(err.contains("a reduced set of no centres"), "{err}");
    }

    #[test]
    fn a_file_changed_after_writing_is_refused_by_its_check_cells() {
        // Plausible values each, but not the model's: its stored margins say so.
        for (field, value) in [("gamma", 0.5), ("rho", 2.0), ("threshold", 0.3)] {
            let err = refusal(|m| m[field] = serde_json::json!(value)).unwrap();
            assert!(
                err.contains("do not decide the cells stored with it") && err.contains("m.json"),
                "{field}: {err}"
            );
        }
        let err = refusal(|m| m["reduced_set"]["bias"] = serde_json::json!(0.0)).unwrap();
        assert!(
            err.contains("the reduced set's margin of check cell"),
            "{err}"
        );
        let err = refusal(|m| m["dual_coefficients"][0] = serde_json::json!(0.0)).unwrap();
        assert!(err.contains("check cell 0"), "{err}");
        // A model file written before check cells existed is read as before.
        assert_eq!(
            refusal(|m| m["check_cells"] = serde_json::Value::Null),
            None
        );
    }

    #[test]
    fn the_fast_kernel_gives_the_check_cells_slow_margins() {
        for rule in LabelRule::ALL {
            let model = SvmModel::embedded(rule).unwrap();
            let cells = model.new_check_cells().unwrap();
            let mut scratch = model.scratch();
            for (row, slow) in cells.features.iter().zip(&cells.exact) {
                let fast = model.exact_decision_value(row, &mut scratch) - model.threshold;
                assert!(
                    (fast - slow).abs() < 1e-3,
                    "{rule:?}: fast {fast}, slow {slow}"
                );
            }
            for (row, slow) in cells.features.iter().zip(&cells.reduced) {
                let fast = model.decision_value(row, &mut scratch) - model.threshold;
                assert!(
                    (fast - slow).abs() < 1e-3,
                    "{rule:?}: fast {fast}, slow {slow}"
                );
            }
        }
    }

    #[test]
    fn a_model_files_error_names_its_file() {
        let dir = std::env::temp_dir().join(format!("travmap-model-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("m.json");
        std::fs::write(&path, b"{\"format\": \"travmap-svm\", \"version\": 1}").unwrap();
        let err = SvmModel::read(&ModelChoice::File(path.clone())).unwrap_err();
        assert_eq!(err.path(), Some(path.as_path()));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
