//! The one configuration of travmap, nested per pipeline stage.
//!
//! Defaults are METHOD.md's and live only in the `Default` impls below. A TOML file
//! overrides any subset (`--config`), `--set section.key=value` overrides single
//! fields, and `validate` checks the result once. The effective configuration is
//! printed with `--json` and stored in every model, so a result can be reproduced.

mod adaptation;
mod labels;
mod registration;
mod training;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::option_files::{TEXT_MAX_BYTES, read_option_text};

pub use adaptation::{AdaptConfig, Learner, OwnPoints, VehicleConfig};
pub use labels::{ClassRule, LabelRule, LabelSet, parse_label_map};
pub use registration::{PoseSource, RegistrationConfig};
pub use training::{
    ClassWeights, Criterion, MAX_SVM_C, MAX_SVM_GAMMA, TrainingConfig, WeighInputs, check_within,
};

/// Every tunable of the method, one section per stage.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    pub integration: IntegrationConfig,
    pub grid: GridConfig,
    pub features: FeatureConfig,
    pub appearance: AppearanceConfig,
    pub classifier: ClassifierConfig,
    pub filter: FilterConfig,
    pub ground_truth: GroundTruthConfig,
    pub training: TrainingConfig,
    pub registration: RegistrationConfig,
    pub vehicle: VehicleConfig,
    pub adapt: AdaptConfig,
}

/// METHOD.md section 5.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AppearanceConfig {
    /// Use camera images when the input has them (default true).
    pub enabled: bool,
    /// Hue buckets over [0, 360) degrees (#H, default 32).
    pub hue_bins: u32,
    /// Saturation buckets over [0, 1] (#S, default 8).
    pub saturation_bins: u32,
    /// Value buckets over [0, 256) (#V, default 48).
    pub value_bins: u32,
}

/// METHOD.md section 6, prediction.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ClassifierConfig {
    /// Which model classifies: `"road"` (a car's road, default) or `"offroad"` (a
    /// robot that may drive on grass, dirt and low vegetation), the models compiled
    /// in, named by the rule of [`LabelRule`] they learnt; anything else is a model
    /// file's path (`--model` names one too).
    pub model: ModelChoice,
    /// Predict with the model's reduced set (a few hundred kernel centres fitted to
    /// the exact decision function) when it has one; false: all support vectors
    /// (default true).
    pub use_reduced_set: bool,
    /// A frame whose remission lies far outside a model's training range (another
    /// sensor's scale) is said in a notice and classified as read (`"notice"`,
    /// default: it won docs/method.md's study), or classified without remission by the
    /// model's fallback (`"fallback"`).
    #[serde(default)]
    pub foreign_remission: ForeignRemissionPolicy,
}

/// A model compiled into travmap, by the rule of what is traversable it learnt, or a
/// model file; written as the rule's name or the file's path.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ModelChoice {
    Embedded(LabelRule),
    File(std::path::PathBuf),
}

impl ModelChoice {
    /// A model named by a person (`--model`): as [`Self::parse`], but a name of
    /// nothing is refused rather than read as the path of no file.
    pub fn named(text: &str) -> std::result::Result<Self, String> {
        match text.trim().is_empty() {
            true => Err("road, offroad or a model file's path expected".into()),
            false => Ok(Self::parse(text)),
        }
    }

    /// `road` and `offroad` are the compiled-in models; anything else a path (a file
    /// called `road` is `./road`).
    pub fn parse(text: &str) -> Self {
        match text {
            "road" => ModelChoice::Embedded(LabelRule::Road),
            "offroad" => ModelChoice::Embedded(LabelRule::Offroad),
            path => ModelChoice::File(path.into()),
        }
    }
}

impl std::fmt::Display for ModelChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ModelChoice::Embedded(rule) => f.write_str(rule.name()),
            ModelChoice::File(path) => write!(f, "{}", path.display()),
        }
    }
}

impl Serialize for ModelChoice {
    fn serialize<S: serde::Serializer>(
        &self,
        serializer: S,
    ) -> std::result::Result<S::Ok, S::Error> {
        serializer.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for ModelChoice {
    fn deserialize<D: serde::Deserializer<'de>>(
        deserializer: D,
    ) -> std::result::Result<Self, D::Error> {
        Ok(Self::parse(&String::deserialize(deserializer)?))
    }
}

/// What a model does with remission far outside its training range.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ForeignRemissionPolicy {
    #[default]
    Notice,
    Fallback,
}

/// METHOD.md section 2.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IntegrationConfig {
    /// Number of scans integrated per frame, the current one included (n, default 3).
    pub scans: usize,
    /// Where each scan's pose comes from (default `auto`).
    pub poses: PoseSource,
    /// Whether recorded poses are refined by registering each scan to the window
    /// from its recorded pose (default `auto`: when consecutive scans lay the ground
    /// more than `pose_disagreement_m` apart under them).
    pub refine_poses: RefinePoses,
    /// The median ground height difference of consecutive scans above which `auto`
    /// refines the recorded poses, metres (default 0.05; SemanticKITTI's poses lay
    /// its scans' ground within 0.01-0.02 m).
    pub pose_disagreement_m: f64,
}

/// When recorded poses are refined by registration.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RefinePoses {
    /// When consecutive scans disagree under them.
    Auto,
    Always,
    Never,
}

/// METHOD.md section 3.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GridConfig {
    /// Side of the square grid around the sensor, metres (max_range, default 12).
    pub size_m: f64,
    /// Cell side, metres (r, default 0.4).
    pub cell_size_m: f64,
    /// Cells with fewer points are unpredictable (default 2).
    pub min_points: usize,
}

/// The most bins `features.curvity_bins` may ask for.
pub const MAX_CURVITY_BINS: usize = 4096;

/// METHOD.md section 4.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FeatureConfig {
    /// Side of the internal sub-cells, metres (r_i, default 0.2); must divide the cell size.
    pub subcell_size_m: f64,
    /// Bins of the curvity range histogram (n_b, default 160).
    pub curvity_bins: usize,
    /// Sub-cells with fewer points contribute no normal to unevenness (default 3).
    pub unevenness_min_points: usize,
    /// Feature groups beyond the paper's 20 (docs/method.md "Features beyond the paper"):
    /// `"remission"` and `"context"` (default `["remission"]`); `[]` is the paper's
    /// method.
    pub groups: Vec<FeatureGroup>,
    /// What remission features see: `"scan_rank"` (default: each point's rank
    /// among its scan's returns, the same on every sensor's scale), `"as_read"`
    /// (the reader's 0..1 scale) or `"scan_p95"` (each scan scaled so that its
    /// 95th percentile is KITTI's). A file that does not say was written as read.
    #[serde(default)]
    pub remission_scale: RemissionScaling,
}

/// How each scan's remission is scaled before the remission features.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RemissionScaling {
    /// Files written before the choice existed read as this.
    #[default]
    AsRead,
    /// Scaled so that the scan's 95th percentile is KITTI's.
    ScanP95,
    /// Each point's rank among its scan's returns, 0..1: the same on any sensor's
    /// scale, whatever its calibration.
    ScanRank,
}

/// A group of features beyond the paper's 20, in the order they follow them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FeatureGroup {
    /// Per-cell statistics of the points' remission (intensity) on a 0..1 scale.
    Remission,
    /// What a cell's neighbourhood says: height steps, occupancy, range.
    Context,
}

/// METHOD.md section 7.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FilterConfig {
    /// Apply the outlier filter (default true).
    pub enabled: bool,
    /// Vote weight of a cell's own label against its 8 neighbours' weight 1 (w, default 3).
    pub self_weight: u32,
}

/// METHOD.md section 8, with label presets for other datasets (docs/guide.md "Label
/// sets and label maps").
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GroundTruthConfig {
    /// Cells with fewer voting points have no ground truth (m, default 2).
    pub min_points: usize,
    /// Non-traversable points that make a cell non-traversable (default 2).
    pub min_non_traversable_points: usize,
    /// Whose label ids: `"semantickitti"` (default) or `"rellis3d"`.
    pub labels: LabelSet,
    /// `"road"` (the seed paper's classes, default) or `"offroad"` (also terrain,
    /// grass, dirt, mud, puddles).
    pub rule: LabelRule,
    /// A TOML file of `[ids]` id = "traversable" | "not_traversable" | "ignored",
    /// for any other ontology; replaces `labels` and `rule` (unset by default).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub label_map: Option<std::path::PathBuf>,
    /// The traversable classes, replacing the preset's (unset by default).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub traversable_classes: Option<Vec<u16>>,
    /// The classes that do not vote, replacing the preset's (unset by default).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ignored_classes: Option<Vec<u16>>,
    /// The label map's classes, once read ([`Config::load_label_map`]).
    #[serde(skip)]
    pub label_map_classes: Option<ClassRule>,
}

impl GroundTruthConfig {
    /// The classes in force: the preset of `labels` and `rule`, with the explicit
    /// lists in their place where given (a label map gives both, see
    /// [`Config::load_label_map`]).
    pub fn classes(&self) -> ClassRule {
        let mut rule = match &self.label_map_classes {
            Some(map) => map.clone(),
            None => self.labels.classes(self.rule),
        };
        if let Some(traversable) = &self.traversable_classes {
            rule.traversable = traversable.clone();
            rule.known = None;
        }
        if let Some(ignored) = &self.ignored_classes {
            rule.ignored = ignored.clone();
            rule.known = None;
        }
        rule
    }
}

impl Default for IntegrationConfig {
    fn default() -> Self {
        Self {
            scans: 3,
            poses: PoseSource::Auto,
            refine_poses: RefinePoses::Auto,
            pose_disagreement_m: 0.05,
        }
    }
}

impl Default for GridConfig {
    fn default() -> Self {
        Self {
            size_m: 12.0,
            cell_size_m: 0.4,
            min_points: 2,
        }
    }
}

impl Default for FeatureConfig {
    fn default() -> Self {
        Self {
            subcell_size_m: 0.2,
            curvity_bins: 160,
            unevenness_min_points: 3,
            // Remission wins the cross-scene numbers (docs/method.md "Features beyond the paper").
            groups: vec![FeatureGroup::Remission],
            remission_scale: RemissionScaling::ScanRank,
        }
    }
}

impl Default for AppearanceConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            hue_bins: 32,
            saturation_bins: 8,
            value_bins: 48,
        }
    }
}

impl Default for ClassifierConfig {
    fn default() -> Self {
        Self {
            model: ModelChoice::Embedded(LabelRule::Road),
            use_reduced_set: true,
            foreign_remission: ForeignRemissionPolicy::Notice,
        }
    }
}

impl Default for FilterConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            self_weight: 3,
        }
    }
}

impl Default for GroundTruthConfig {
    fn default() -> Self {
        Self {
            min_points: 2,
            min_non_traversable_points: 2,
            labels: LabelSet::Semantickitti,
            rule: LabelRule::Road,
            label_map: None,
            traversable_classes: None,
            ignored_classes: None,
            label_map_classes: None,
        }
    }
}

impl GridConfig {
    /// Cells per side, `l = max_range / r` rounded to the nearest integer.
    pub fn cells_per_side(&self) -> usize {
        (self.size_m / self.cell_size_m).round() as usize
    }
}

impl FeatureConfig {
    /// The groups without remission: what a cloud without usable intensity gets.
    pub fn without_remission(&self) -> FeatureConfig {
        FeatureConfig {
            groups: self
                .groups
                .iter()
                .copied()
                .filter(|g| *g != FeatureGroup::Remission)
                .collect(),
            ..self.clone()
        }
    }

    /// Internal sub-cells per cell side, `r / r_i`.
    pub fn subcells_per_side(&self, cell_size_m: f64) -> usize {
        (cell_size_m / self.subcell_size_m).round() as usize
    }
}

/// A configuration written before `features.groups` existed used the paper's 20
/// features only; reading one, a missing `groups` means `[]`, not today's default.
/// `config` is the JSON of a [`Config`] as a model or dataset file stores it.
pub fn written_before_groups(config: &mut serde_json::Value) {
    if let Some(features) = config.get_mut("features").and_then(|f| f.as_object_mut()) {
        features
            .entry("groups")
            .or_insert_with(|| serde_json::Value::Array(Vec::new()));
    }
}

/// Fields that are unset by default, so absent from a serialised configuration,
/// and whether each holds text (the rest hold lists).
const OPTIONAL_FIELDS: &[(&str, &str, bool)] = &[
    ("ground_truth", "label_map", true),
    ("ground_truth", "traversable_classes", false),
    ("ground_truth", "ignored_classes", false),
    ("vehicle", "own_points_box_m", false),
];

impl Config {
    /// The configuration training cells are computed with: this one on the training
    /// grid (`training.grid_size_m`), so `train`, `dataset` and `crossval` see the
    /// same cells.
    pub fn for_training_cells(&self) -> Config {
        let mut config = self.clone();
        config.grid.size_m = self.training.grid_size_m;
        config
    }

    /// Reads what the settings name (the label map) and checks every field: the
    /// configuration as the stages take it, once its file and settings are applied.
    pub fn ready(&mut self) -> Result<()> {
        self.load_label_map()?;
        self.validate()
    }

    /// Reads the label map `ground_truth.label_map` names, if any.
    pub fn load_label_map(&mut self) -> Result<()> {
        let Some(path) = &self.ground_truth.label_map else {
            return Ok(());
        };
        let text = read_option_text(path, TEXT_MAX_BYTES)?;
        let classes = parse_label_map(&text)
            .map_err(|problem| Error::Config(format!("label map {}: {problem}", path.display())))?;
        self.ground_truth.label_map_classes = Some(classes);
        Ok(())
    }

    /// Sets one field from `section.key=value`, the value in TOML syntax
    /// (`grid.size_m=24`, `training.c_values=[1, 10]`); a text field also takes its
    /// value bare (`integration.poses=tf`, `ground_truth.label_map=/p/map.toml`).
    pub fn set(&mut self, assignment: &str) -> Result<()> {
        let (key, value) = assignment
            .split_once('=')
            .ok_or_else(|| Error::Config(format!("`{assignment}`: expected section.key=value")))?;
        let (key, value) = (key.trim(), value.trim());
        let (section, field) = key.split_once('.').ok_or_else(|| {
            Error::Config(format!("`{key}`: expected section.key, e.g. grid.size_m"))
        })?;
        let mut table = toml::Table::try_from(&*self)
            .map_err(|e| Error::Config(format!("cannot serialise configuration: {e}")))?;
        let section_table = table
            .get_mut(section)
            .and_then(|s| s.as_table_mut())
            .ok_or_else(|| Error::Config(format!("`{key}`: no section `{section}`")))?;
        let current = section_table.get(field);
        let optional = OPTIONAL_FIELDS
            .iter()
            .find(|(s, f, _)| (*s, *f) == (section, field));
        if current.is_none() && optional.is_none() {
            let known: Vec<&str> = section_table.keys().map(String::as_str).collect();
            return Err(Error::Config(format!(
                "`{key}`: section `{section}` has no field `{field}` (fields: {})",
                known.join(", ")
            )));
        }
        let text_field = match current {
            Some(current) => current.is_str(),
            None => optional.is_some_and(|(_, _, text)| *text),
        };
        let list_field = current.is_none_or(toml::Value::is_array) && !text_field;
        let parsed = match toml::from_str::<toml::Table>(&format!("v = {value}")) {
            Ok(mut parsed) => parsed.remove("v").filter(|v| v.is_str() || !text_field),
            // A number or a switch is said as such, with the value it has now for an
            // example; TOML's own words help with lists and quoting.
            Err(_) if current.is_some_and(|c| c.is_float() || c.is_integer() || c.is_bool()) => {
                let current = current.expect("matched above");
                let wanted = match current {
                    toml::Value::Boolean(_) => "true or false",
                    toml::Value::Integer(_) => "a whole number",
                    _ => "a number",
                };
                return Err(Error::Config(format!(
                    "`{key}`: `{value}` is not {wanted} (e.g. {key}={current})"
                )));
            }
            Err(e) if !text_field => {
                return Err(Error::Config(format!(
                    "`{key}`: `{value}` is not a {} (TOML: {})",
                    current.map_or("value", toml::Value::type_str),
                    e.message()
                )));
            }
            Err(_) => None,
        };
        let parsed = match parsed.unwrap_or_else(|| toml::Value::String(value.to_string())) {
            // One value where a list is wanted is a list of one (`training.c_values=10`).
            one if list_field && !one.is_array() => toml::Value::Array(vec![one]),
            parsed => parsed,
        };
        section_table.insert(field.to_string(), parsed);
        *self = table.try_into().map_err(|e: toml::de::Error| {
            Error::Config(format!("`{key}` = `{value}`: {}", e.message().trim()))
        })?;
        Ok(())
    }

    /// Checks every field once; the stages rely on these invariants.
    pub fn validate(&self) -> Result<()> {
        let fail = |m: String| Err(Error::Config(m));
        let positive = |name: &str, v: f64| -> Result<()> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(Error::Config(format!("{name} must be > 0, got {v}")))
            }
        };
        if self.integration.scans == 0 || self.integration.scans > 255 {
            return fail(format!(
                "integration.scans must be in 1..=255, got {}",
                self.integration.scans
            ));
        }
        positive(
            "integration.pose_disagreement_m",
            self.integration.pose_disagreement_m,
        )?;
        self.vehicle.validate().map_err(Error::Config)?;
        self.registration.validate().map_err(Error::Config)?;
        self.adapt.validate(&self.vehicle).map_err(Error::Config)?;
        let ground_truth = &self.ground_truth;
        if ground_truth
            .traversable_classes
            .as_ref()
            .is_some_and(Vec::is_empty)
        {
            return fail("ground_truth.traversable_classes is empty: nothing could be traversable (leave it unset for the preset of ground_truth.labels and rule)".into());
        }
        if ground_truth.label_map.is_some() && ground_truth.label_map_classes.is_none() {
            return fail("ground_truth.label_map is set but was not read".into());
        }
        positive("grid.size_m", self.grid.size_m)?;
        positive("grid.cell_size_m", self.grid.cell_size_m)?;
        positive("features.subcell_size_m", self.features.subcell_size_m)?;
        let groups = &self.features.groups;
        if (1..groups.len()).any(|i| groups[..i].contains(&groups[i])) {
            return fail(format!("features.groups names a group twice: {groups:?}"));
        }
        positive("training.grid_size_m", self.training.grid_size_m)?;
        positive("training.block_size_m", self.training.block_size_m)?;
        check_within(
            "training.taught_weight",
            self.training.taught_weight,
            (0.0, 1e4),
        )
        .map_err(Error::Config)?;
        check_within("training.tolerance", self.training.tolerance, (1e-9, 1.0))
            .map_err(Error::Config)?;
        // The training grid is the grid's size set to training.grid_size_m: each is
        // checked by the setting that makes it.
        for (setting, size_m) in [
            ("grid.size_m", self.grid.size_m),
            ("training.grid_size_m", self.training.grid_size_m),
        ] {
            let cells = (size_m / self.grid.cell_size_m).round() as usize;
            if !(1..=4096).contains(&cells) {
                return fail(format!(
                    "{setting} / grid.cell_size_m gives {cells} cells per side; expected 1..=4096"
                ));
            }
        }
        let ratio = self.grid.cell_size_m / self.features.subcell_size_m;
        if (ratio - ratio.round()).abs() > 1e-6 || !(1.0..=16.0).contains(&ratio.round()) {
            return fail(format!(
                "features.subcell_size_m ({}) must divide grid.cell_size_m ({}) into 1 to 16 parts",
                self.features.subcell_size_m, self.grid.cell_size_m
            ));
        }
        if self.grid.min_points == 0 {
            return fail("grid.min_points must be >= 1".into());
        }
        // Each cell's histogram is as long as this: past a few thousand bins, most stay
        // empty at any point count, and 2^32 took minutes and 4 GB a frame.
        if !(1..=MAX_CURVITY_BINS).contains(&self.features.curvity_bins) {
            return fail(format!(
                "features.curvity_bins must be in 1..={MAX_CURVITY_BINS}, got {}",
                self.features.curvity_bins
            ));
        }
        let a = &self.appearance;
        if [a.hue_bins, a.saturation_bins, a.value_bins]
            .iter()
            .any(|&b| !(1..=256).contains(&b))
        {
            return fail(format!(
                "appearance bins must be in 1..=256, got {} / {} / {}",
                a.hue_bins, a.saturation_bins, a.value_bins
            ));
        }
        if self.training.folds < 2 {
            return fail(format!(
                "training.folds must be >= 2, got {}",
                self.training.folds
            ));
        }
        if self.training.max_fit_samples < self.training.max_search_samples {
            return fail(format!(
                "training.max_fit_samples ({}) must be >= training.max_search_samples ({})",
                self.training.max_fit_samples, self.training.max_search_samples
            ));
        }
        for (name, values, largest) in [
            ("training.c_values", &self.training.c_values, MAX_SVM_C),
            (
                "training.gamma_values",
                &self.training.gamma_values,
                MAX_SVM_GAMMA,
            ),
        ] {
            if values.is_empty() {
                return fail(format!("{name} must not be empty"));
            }
            for &v in values {
                check_within(name, v, (0.0, largest)).map_err(Error::Config)?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_methods_and_valid() {
        let config = Config::default();
        config.validate().unwrap();
        assert_eq!(config.grid.cells_per_side(), 30);
        assert_eq!(config.features.subcells_per_side(0.4), 2);
        assert_eq!(config.integration.scans, 3);
    }

    #[test]
    fn set_overrides_one_field_and_rejects_unknown_ones() {
        let mut config = Config::default();
        config.set("grid.size_m=24").unwrap();
        config.set("training.c_values=[2.0, 20.0]").unwrap();
        assert_eq!(config.grid.size_m, 24.0);
        assert_eq!(config.training.c_values, vec![2.0, 20.0]);
        let err = config.set("grid.sise_m=3").unwrap_err().to_string();
        assert!(
            err.contains("no field `sise_m`") && err.contains("size_m"),
            "{err}"
        );
        assert!(config.set("nonsense").is_err());
        assert!(config.set("grid.size_m=\"x\"").is_err());
    }

    #[test]
    fn set_takes_text_bare_and_one_value_for_a_list() {
        let mut config = Config::default();
        config.set("integration.poses=tf").unwrap();
        assert_eq!(config.integration.poses, PoseSource::Tf);
        config.set("ground_truth.labels=rellis3d").unwrap();
        config
            .set("ground_truth.label_map=/maps/labels.toml")
            .unwrap();
        assert_eq!(
            config.ground_truth.label_map.as_deref(),
            Some(std::path::Path::new("/maps/labels.toml"))
        );
        config.set("training.c_values=10").unwrap();
        assert_eq!(config.training.c_values, vec![10.0]);
        config
            .set("ground_truth.traversable_classes=[40, 44]")
            .unwrap();
        assert_eq!(config.ground_truth.traversable_classes, Some(vec![40, 44]));
        let err = config
            .set("integration.poses=bogus")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("integration.poses") && err.contains("`tf`"),
            "{err}"
        );
        let err = config.set("grid.size_m=abc").unwrap_err().to_string();
        assert!(
            err.contains("grid.size_m") && err.contains("not a number"),
            "{err}"
        );
    }

    #[test]
    fn toml_file_overrides_a_subset() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.toml");
        std::fs::write(&path, "[grid]\nsize_m = 20.0\n").unwrap();
        let config = crate::config_sources::read_toml_file(&path).unwrap().config;
        assert_eq!(config.grid.size_m, 20.0);
        assert_eq!(config.grid.cell_size_m, 0.4);
        std::fs::write(&path, "[grid]\nbogus = 1\n").unwrap();
        assert!(crate::config_sources::read_toml_file(&path).is_err());
    }

    #[test]
    fn the_training_grid_is_checked_by_its_own_setting() {
        let mut config = Config::default();
        config.set("training.grid_size_m=0.1").unwrap();
        let message = config.validate().unwrap_err().to_string();
        assert!(
            message.contains("training.grid_size_m / grid.cell_size_m gives 0 cells"),
            "{message}"
        );
    }

    #[test]
    fn every_field_unset_by_default_can_be_set() {
        let mut config = Config::default();
        config.set("ground_truth.label_map=/p/map.toml").unwrap();
        config
            .set("ground_truth.traversable_classes=[40, 44]")
            .unwrap();
        config.set("ground_truth.ignored_classes=[0]").unwrap();
        // As the survey's notice spells the box it found.
        config
            .set("vehicle.own_points_box_m=[-0.8, -1.4, -1, 0.8, 2, 0.2]")
            .unwrap();
        assert_eq!(
            config.vehicle.own_points_box_m,
            Some([-0.8, -1.4, -1.0, 0.8, 2.0, 0.2])
        );
        assert_eq!(config.ground_truth.traversable_classes, Some(vec![40, 44]));
        // Every field serialised with a value is one `set` knows of.
        let table = toml::Table::try_from(&config).unwrap();
        for (section, field, _) in OPTIONAL_FIELDS {
            assert!(table[*section].get(*field).is_some(), "{section}.{field}");
        }
    }

    #[test]
    fn curvity_bins_are_bounded() {
        let mut config = Config::default();
        config.set("features.curvity_bins=4294967295").unwrap();
        let message = config.validate().unwrap_err().to_string();
        assert!(
            message.contains("features.curvity_bins must be in 1..=4096, got 4294967295"),
            "{message}"
        );
        config.set("features.curvity_bins=4096").unwrap();
        assert!(config.validate().is_ok());
    }

    #[test]
    fn validate_rejects_subcells_that_do_not_divide_the_cell() {
        let mut config = Config::default();
        config.features.subcell_size_m = 0.3;
        assert!(config.validate().is_err());
    }

    #[test]
    fn validate_rejects_a_fit_subset_smaller_than_the_search_subset() {
        let mut config = Config::default();
        config
            .set("training.max_fit_samples=5000")
            .expect("a known key");
        let message = config.validate().unwrap_err().to_string();
        assert!(
            message.contains("training.max_fit_samples (5000)"),
            "{message}"
        );
    }
}
