//! The model file: a versioned JSON document holding the geometric SVM, its reduced
//! set and the hybrid model, plus the default model compiled into the binary.

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::{ReducedSet, SvmModel, TrainingSummary, appearance_feature_names};
use crate::features::feature_names;
use travmap_core::config::{Config, FeatureGroup, LabelRule, ModelChoice, written_before_groups};
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
                Ok((Self::from_json(&bytes, &name)?, name))
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
        })?;
        Self::from_model_file(file, &name)
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
            return Err(Error::ModelVersion {
                source_name: source_name.to_string(),
                format: format.unwrap_or("none").to_string(),
                version: version.map_or("none".into(), |v| v.to_string()),
                expected_format: MODEL_FORMAT,
                expected_version: MODEL_VERSION,
            });
        }
        let mut header = header;
        older_configs(&mut header);
        // The error names the field (`gamma`, `config.grid.size_m`) where serde's alone
        // would not.
        let file: ModelFile = serde_path_to_error::deserialize(header)
            .map_err(|e| fail(format!("malformed model: `{}`: {}", e.path(), e.inner())))?;
        Self::from_model_file(file, source_name)
    }

    /// The model of a file read, checked.
    fn from_model_file(file: ModelFile, source_name: &str) -> Result<Self> {
        let fail = |message: String| Error::Model {
            source_name: source_name.to_string(),
            message,
        };
        let names = feature_names(&file.config.features.groups);
        let model = Self::from_file(file, source_name, &names)?;
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
        let scalars = [
            ("gamma", file.gamma, true),
            ("rho", file.rho, false),
            ("threshold", file.threshold, false),
        ];
        let in_scalars = || {
            scalars.iter().find_map(|&(name, value, positive)| {
                (!value.is_finite() || (positive && value <= 0.0)).then(|| {
                    let expected = if positive {
                        "a positive number"
                    } else {
                        "a finite number"
                    };
                    format!("`{name}` is {value}, {expected} expected")
                })
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
                Some(Box::new(Self::from_file(*fallback, &source, &names)?))
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
                Some(Box::new(Self::from_file(*prior, &source, &names)?))
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
        Ok(model)
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
}
