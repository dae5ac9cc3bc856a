//! The one configuration of travmap, nested per pipeline stage.
//!
//! Defaults are METHOD.md's and live only in the `Default` impls below. A TOML file
//! overrides any subset (`--config`), `--set section.key=value` overrides single
//! fields, and `validate` checks the result once. The effective configuration is
//! printed with `--json` and stored in every model, so a result can be reproduced.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

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
    /// Predict with the model's reduced set (a few hundred kernel centres fitted to
    /// the exact decision function) when it has one; false: all support vectors
    /// (default true).
    pub use_reduced_set: bool,
}

/// METHOD.md section 2.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IntegrationConfig {
    /// Number of scans integrated per frame, the current one included (n, default 3).
    pub scans: usize,
    /// Where each scan's pose comes from (default `auto`).
    pub poses: PoseSource,
}

/// Where the scans' poses come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseSource {
    /// The input's recorded poses (KITTI `poses.txt`, a log's /tf or Odometry) when
    /// they reach the scans' frame, else registration, said in a notice.
    #[default]
    Auto,
    /// A log's /tf and /tf_static only (KITTI: `poses.txt`).
    Tf,
    /// A log's `nav_msgs/Odometry` (with /tf_static) only (KITTI: `poses.txt`).
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
        check(c.max_points_per_voxel > 0, "max_points_per_voxel > 0")?;
        check(positive(c.initial_threshold_m), "initial_threshold_m > 0")?;
        let motion = c.min_motion_m == 0.0 || positive(c.min_motion_m);
        check(motion, "min_motion_m >= 0")?;
        check(positive(c.convergence), "convergence > 0")?;
        check(c.max_iterations > 0, "max_iterations > 0")
    }
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
    /// Feature groups beyond the paper's 20 (README "Features beyond the paper"):
    /// `"remission"` and `"context"` (default `["remission"]`); `[]` is the paper's
    /// method.
    pub groups: Vec<FeatureGroup>,
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

/// METHOD.md section 8.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GroundTruthConfig {
    /// Cells with fewer voting points have no ground truth (m, default 2).
    pub min_points: usize,
    /// Non-traversable points that make a cell non-traversable (default 2).
    pub min_non_traversable_points: usize,
    /// SemanticKITTI classes that are traversable (default road, parking, sidewalk,
    /// other-ground, lane-marking).
    pub traversable_classes: Vec<u16>,
    /// Classes that do not vote (default unlabeled 0 and outlier 1).
    pub ignored_classes: Vec<u16>,
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
    /// Per-class weights on C (libsvm's `-w`): `"balanced"` (default), each class
    /// weighted by cells / (2 x its cells) so the rarer class counts as much, or
    /// `"none"` (the paper's).
    pub class_weights: ClassWeights,
    /// What the grid search maximises over the held-out folds: `"miou"` (default:
    /// accuracy rewards calling everything road) or `"accuracy"`.
    pub criterion: Criterion,
    /// Choose the decision threshold (0 otherwise) that maximises the criterion over
    /// the held-out folds' decision values of the chosen (C, gamma) (default false:
    /// on the shipped scenes it lowered every held-out score, README "Features beyond
    /// the paper").
    pub tune_threshold: bool,
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

impl Default for IntegrationConfig {
    fn default() -> Self {
        Self {
            scans: 3,
            poses: PoseSource::Auto,
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
            // Remission wins the cross-scene numbers (README "Features beyond the paper").
            groups: vec![FeatureGroup::Remission],
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
            use_reduced_set: true,
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
            traversable_classes: vec![40, 44, 48, 49, 60],
            ignored_classes: vec![0, 1],
        }
    }
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
            class_weights: ClassWeights::Balanced,
            criterion: Criterion::Miou,
            tune_threshold: false,
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

impl Config {
    /// The configuration training cells are computed with: this one on the training
    /// grid (`training.grid_size_m`), so `train`, `dataset` and `crossval` see the
    /// same cells.
    pub fn for_training_cells(&self) -> Config {
        let mut config = self.clone();
        config.grid.size_m = self.training.grid_size_m;
        config
    }

    /// Reads a TOML file; fields it does not name keep their defaults.
    pub fn from_toml_file(path: &std::path::Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        toml::from_str(&text).map_err(|e| Error::Config(format!("{}: {e}", path.display())))
    }

    /// Sets one field from `section.key=value`, the value in TOML syntax
    /// (`grid.size_m=24`, `training.c_values=[1, 10]`).
    pub fn set(&mut self, assignment: &str) -> Result<()> {
        let (key, value) = assignment
            .split_once('=')
            .ok_or_else(|| Error::Config(format!("`{assignment}`: expected section.key=value")))?;
        let (section, field) = key.trim().split_once('.').ok_or_else(|| {
            Error::Config(format!("`{key}`: expected section.key, e.g. grid.size_m"))
        })?;
        let parsed: toml::Table = toml::from_str(&format!("v = {}", value.trim()))
            .map_err(|e| Error::Config(format!("`{assignment}`: value is not TOML: {e}")))?;
        let mut table = toml::Table::try_from(&*self)
            .map_err(|e| Error::Config(format!("cannot serialise configuration: {e}")))?;
        let section_table = table
            .get_mut(section)
            .and_then(|s| s.as_table_mut())
            .ok_or_else(|| Error::Config(format!("`{key}`: no section `{section}`")))?;
        if !section_table.contains_key(field) {
            let known: Vec<&str> = section_table.keys().map(String::as_str).collect();
            return Err(Error::Config(format!(
                "`{key}`: section `{section}` has no field `{field}` (fields: {})",
                known.join(", ")
            )));
        }
        section_table.insert(field.to_string(), parsed["v"].clone());
        *self = table
            .try_into()
            .map_err(|e| Error::Config(format!("`{assignment}`: {e}")))?;
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
        self.registration.validate().map_err(Error::Config)?;
        positive("grid.size_m", self.grid.size_m)?;
        positive("grid.cell_size_m", self.grid.cell_size_m)?;
        positive("features.subcell_size_m", self.features.subcell_size_m)?;
        let groups = &self.features.groups;
        if (1..groups.len()).any(|i| groups[..i].contains(&groups[i])) {
            return fail(format!("features.groups names a group twice: {groups:?}"));
        }
        positive("training.grid_size_m", self.training.grid_size_m)?;
        positive("training.block_size_m", self.training.block_size_m)?;
        positive("training.tolerance", self.training.tolerance)?;
        let cells = self.grid.cells_per_side();
        if !(1..=4096).contains(&cells) {
            return fail(format!(
                "grid.size_m / grid.cell_size_m gives {cells} cells per side; expected 1..=4096"
            ));
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
        if self.features.curvity_bins == 0 {
            return fail("features.curvity_bins must be >= 1".into());
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
        for (name, values) in [
            ("training.c_values", &self.training.c_values),
            ("training.gamma_values", &self.training.gamma_values),
        ] {
            if values.is_empty() {
                return fail(format!("{name} must not be empty"));
            }
            for &v in values {
                positive(name, v)?;
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
    fn toml_file_overrides_a_subset() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.toml");
        std::fs::write(&path, "[grid]\nsize_m = 20.0\n").unwrap();
        let config = Config::from_toml_file(&path).unwrap();
        assert_eq!(config.grid.size_m, 20.0);
        assert_eq!(config.grid.cell_size_m, 0.4);
        std::fs::write(&path, "[grid]\nbogus = 1\n").unwrap();
        assert!(Config::from_toml_file(&path).is_err());
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
