//! Self-supervised adaptation (`travmap adapt`): a model learnt from drives without
//! annotations. Each drive is run with a prior model along its trajectory; the
//! footprint and self-label stages (`method/footprint.rs`, `method/self_labels.rs`)
//! label its cells; an SVM is fitted to them as `adapt.learner` says, with
//! `adapt.rounds` of self-training. The drives' labels, if they have any, are never
//! read (`Source::set_read_labels`).

use std::collections::HashSet;

use serde::Serialize;

use super::reduced_set::fit_folded_reduced_set;
use super::{REMISSION_COLUMNS, Reduce, Search, config_without_remission, train_by};
use travmap_core::config::{Config, FeatureGroup, Learner};
use travmap_core::error::{Error, Result};
use travmap_core::random::SplitMix64;
use travmap_drive::{Fingerprints, Selection};
use travmap_method::classifier::{AdaptationSummary, AdaptedInput, SvmModel};
use travmap_method::features::feature_count;
use travmap_method::footprint::PathKind;
use travmap_method::training_set::TrainingSet;

/// One self-labelled (or unknown) cell of a drive.
#[derive(Clone)]
struct DriveCell {
    features: Vec<f32>,
    appearance: Option<Vec<f32>>,
    /// None: unknown.
    label: Option<bool>,
    centre_in_world: [f64; 2],
}

/// A seeded reservoir sample of at most `capacity` cells: memory stays bounded on
/// drives of any length, and every cell seen has the same chance to be kept.
struct Reservoir {
    cells: Vec<DriveCell>,
    seen: usize,
    capacity: usize,
    random: SplitMix64,
}

impl Reservoir {
    fn new(capacity: usize, seed: u64) -> Self {
        Self {
            cells: Vec::new(),
            seen: 0,
            capacity,
            random: SplitMix64(seed),
        }
    }

    fn offer(&mut self, cell: impl FnOnce() -> DriveCell) {
        self.seen += 1;
        if self.cells.len() < self.capacity {
            self.cells.push(cell());
        } else {
            let slot = (self.random.next_u64() % self.seen as u64) as usize;
            if slot < self.capacity {
                self.cells[slot] = cell();
            }
        }
    }
}

/// What the drives said of their cells, and the cells kept to learn from.
#[derive(Clone, Debug, Default, Serialize)]
pub struct SelfLabelCounts {
    pub frames: usize,
    /// Distinct world cells of each self-label.
    pub footprint_cells: usize,
    pub negative_cells: usize,
    pub unknown_cells: usize,
    pub straight_path_frames: usize,
}

/// A model adapted to drives, with what it learnt from.
pub struct Adapted {
    pub model: SvmModel,
    pub counts: SelfLabelCounts,
    /// What the user should hear (straight footprints, ...).
    pub notices: Vec<String>,
    /// The drives had no usable remission: what was fitted is the model's fallback.
    pub fallback_fitted: bool,
}

impl Adapted {
    /// The part of the model fitted to the drives.
    pub fn fitted(&self) -> &SvmModel {
        match (&self.model.fallback, self.fallback_fitted) {
            (Some(fallback), true) => fallback,
            _ => &self.model,
        }
    }
}

/// Adapts `prior` (named `prior_name`) to the drives of `selections`: see the
/// module documentation. `on_frame` is called after each frame read.
pub fn adapt(
    selections: &mut [Selection],
    config: &Config,
    prior: &SvmModel,
    prior_name: &str,
    on_frame: &mut dyn FnMut(),
) -> Result<Adapted> {
    let grid_config = config.for_training_cells();
    let a = &config.adapt;
    // Each label keeps half the cells: footprint cells are few on a long drive, and
    // a sample of all labelled cells would keep fewer still.
    let seed = config.training.seed;
    let mut positives = Reservoir::new(a.max_cells / 2, seed);
    let mut negatives = Reservoir::new(a.max_cells / 2, seed.wrapping_add(1));
    let mut unknown = Reservoir::new(a.max_cells, seed.wrapping_add(2));
    let mut counts = SelfLabelCounts::default();
    let (mut footprint, mut negative, mut neither) =
        (HashSet::new(), HashSet::new(), HashSet::new());
    let mut inputs = Vec::new();
    let mut notices = Vec::new();
    let mut trajectory_m = 0.0;
    let mut frames_without_remission = 0;
    for selection in selections.iter_mut() {
        selection.source.set_read_labels(false);
        selection.fingerprint_scans = Fingerprints::All;
        let trajectory = selection.follow_trajectory(&grid_config)?;
        trajectory_m += trajectory.length_m();
        let mut scans = Vec::new();
        let mut straight = 0;
        selection.run::<Error>(&grid_config, Some(prior), |result| {
            counts.frames += 1;
            frames_without_remission += usize::from(result.without_remission);
            scans.extend(result.scan_sha256.clone());
            if matches!(result.footprint, Some((_, PathKind::Straight))) {
                straight += 1;
            }
            let labels = result.self_labels.as_deref().unwrap_or(&[]);
            for (cell, label) in labels.iter().enumerate() {
                if !result.features.predictable[cell] {
                    continue;
                }
                let key = result.layout.cell_key(cell);
                match label {
                    Some(true) => footprint.insert(key),
                    Some(false) => negative.insert(key),
                    None => neither.insert(key),
                };
                let cell_of = || DriveCell {
                    features: result.features.cell(cell).to_vec(),
                    appearance: result.features.appearance(cell).map(<[f32]>::to_vec),
                    label: *label,
                    centre_in_world: result.layout.cell_centre_in_world(cell),
                };
                match label {
                    Some(true) => positives.offer(cell_of),
                    Some(false) => negatives.offer(cell_of),
                    None => unknown.offer(cell_of),
                }
            }
            on_frame();
            Ok(())
        })?;
        if straight > 0 {
            notices.push(format!(
                "{}: no trajectory beyond one pose: the footprint of {straight} frames runs straight along the sensor's x axis, {} m either way",
                selection.source.path().display(),
                a.horizon_m
            ));
        }
        counts.straight_path_frames += straight;
        inputs.push(AdaptedInput {
            input: selection.describe(),
            frames: scans.len(),
            scans_sha256: sha256_hex(scans.concat().as_bytes()),
        });
    }
    counts.footprint_cells = footprint.len();
    counts.negative_cells = negative.len();
    counts.unknown_cells = neither
        .difference(&footprint)
        .filter(|k| !negative.contains(*k))
        .count();
    let path = selections
        .first()
        .map(|s| s.source.path().to_path_buf())
        .unwrap_or_default();
    let refuse = |problem: String| Error::Adaptation {
        path: path.clone(),
        problem,
    };
    if counts.footprint_cells < a.min_footprint_cells {
        return Err(refuse(format!(
            "{} footprint cells (cells the vehicle drove over that hold points), at least {} needed (adapt.min_footprint_cells): the vehicle moved {trajectory_m:.1} m over the drive; a vehicle standing still or a drive this short shows too little of its ground. Adapt on a longer drive",
            counts.footprint_cells, a.min_footprint_cells
        )));
    }
    let unlabelled_learnt = a.unlabelled_weight > 0.0 && counts.unknown_cells > 0;
    if counts.negative_cells == 0 && !unlabelled_learnt {
        return Err(refuse(format!(
            "no cell is an obstacle (over vehicle.clearance_m = {} m) or rejected by the prior with a margin of -{} or less, so every self-label says traversable; lower adapt.negative_margin, learn the unknown cells as negatives (adapt.unlabelled_weight) or adapt on a drive with obstacles",
            config.vehicle.clearance_m, a.negative_margin
        )));
    }

    // Frames without usable remission give cells without its columns, and are
    // classified by the model's fallback: then the prior's fallback is what is
    // adapted (the cells' remission columns dropped). Otherwise no fallback is
    // fitted: the prior's is kept.
    let uses_remission = config.features.groups.contains(&FeatureGroup::Remission);
    let without_remission = uses_remission && frames_without_remission > 0;
    let (fit_config, fit_prior) = match (without_remission, prior.fallback.as_deref()) {
        (true, Some(fallback)) => (config_without_remission(config), fallback),
        (true, None) => {
            return Err(refuse(format!(
                "{frames_without_remission} frames have no usable remission and the prior has no model without it"
            )));
        }
        (false, _) => (config.clone(), prior),
    };
    let (original_config, original_prior) = (config, prior);
    let (config, prior) = (&fit_config, fit_prior);
    let mut labelled = [positives.cells, negatives.cells].concat();
    let mut unknown = unknown.cells;
    if without_remission {
        notices.push(format!(
            "{}: {frames_without_remission} of {} frames have no usable remission: the prior's model without remission is adapted to the drives (frames with remission keep the prior's)",
            path.display(),
            counts.frames
        ));
        let full = feature_count(&original_config.features.groups);
        for cell in labelled.iter_mut().chain(unknown.iter_mut()) {
            if cell.features.len() == full {
                cell.features.drain(REMISSION_COLUMNS);
            }
        }
    }
    // Positive-unlabelled learning: the unknown cells are negatives of their own
    // weight.
    let unlabelled_weight = a.unlabelled_weight as f32;
    let to_set = |labelled: &[DriveCell], unlabelled: &[DriveCell]| {
        let mut set = cells_to_set(labelled, config);
        for cell in unlabelled.iter().filter(|_| unlabelled_weight > 0.0) {
            let appearance = cell.appearance.as_deref();
            let centre = cell.centre_in_world;
            set.push_weighted(&cell.features, appearance, false, centre, unlabelled_weight);
        }
        set
    };
    let mut drive = to_set(&labelled, &unknown);
    let unknown_features: Vec<f32> = unknown
        .iter()
        .flat_map(|c| c.features.iter().copied())
        .collect();
    let fit = |set: &TrainingSet| -> Result<SvmModel> {
        let cells = match a.learner {
            Learner::DriveAndPrior => &with_prior_cells(set, prior, a.prior_weight),
            Learner::Drive | Learner::Sum => set,
        };
        let search = Search::Fixed {
            c: a.c,
            gamma: a.gamma,
        };
        // The sum's expansion folds in the prior: classifying costs about what the
        // prior's does.
        let weight = a.prior_weight as f32;
        let folded = |model: &SvmModel, _: &TrainingSet| {
            let rows = [&set.features[..], &unknown_features].concat();
            fit_folded_reduced_set(model, prior, weight, &rows, config)
        };
        let reduce = (a.learner == Learner::Sum).then_some(&folded as &Reduce);
        let mut model = train_by(cells, config, search, reduce, false, &|_, _| {})?;
        model.fallback = prior.fallback.clone();
        if a.learner == Learner::Sum {
            model.prior = Some(Box::new(prior.clone()));
            model.prior_weight = weight;
            model.reduced_set_includes_prior = model.reduced_set.is_some();
        }
        Ok(model)
    };
    let mut model = fit(&drive)?;
    // Self-training: the unknown cells the adapted model is sure of join its cells.
    for _ in 0..a.rounds {
        let (confident, unsure) = confident_cells(&model, &unknown, a.self_training_margin as f32);
        if confident.is_empty() {
            break;
        }
        drive = to_set(&[labelled.clone(), confident].concat(), &unsure);
        model = fit(&drive)?;
    }
    if without_remission {
        // The drives' model classifies what they show, clouds without remission: it
        // is the prior's fallback; clouds with remission keep the prior's model.
        let mut outer = original_prior.clone();
        outer.fallback = Some(Box::new(model));
        model = outer;
    }
    model.training.adaptation = Some(AdaptationSummary {
        self_supervised: true,
        learner: a.learner,
        prior: prior_name.to_string(),
        prior_sha256: original_prior.sha256_hex(),
        inputs,
        footprint_cells: counts.footprint_cells,
        negative_cells: counts.negative_cells,
        unknown_cells: counts.unknown_cells,
        fitted_cells: drive.len(),
        straight_path_frames: counts.straight_path_frames,
        hybrid: match &model.hybrid {
            Some(hybrid) => format!(
                "fitted on the {} cells cameras saw",
                hybrid.training.samples
            ),
            None => "none: no camera saw the drives' cells".into(),
        },
        fallback: match (uses_remission, without_remission) {
            (false, _) => "none: the model has no remission features".into(),
            (true, true) => format!(
                "fitted to the drives, whose {frames_without_remission} frames had no usable remission (the model with remission is the prior's)"
            ),
            (true, false) => {
                "the prior's: every frame had usable remission, so the drives use none".into()
            }
        },
    });
    model.training.sources = selections.iter().map(Selection::describe).collect();
    // It read no labels: what it knows of labelled scans is the prior's, so eval
    // still tells the prior's training scans from held-out ones.
    model.training.frame_sha256 = original_prior.training.frame_sha256.clone();
    Ok(Adapted {
        model,
        counts,
        notices,
        fallback_fitted: without_remission,
    })
}

/// The labelled cells as a training set.
fn cells_to_set(cells: &[DriveCell], config: &Config) -> TrainingSet {
    let mut set = TrainingSet::for_features(config);
    for cell in cells.iter() {
        if let Some(label) = cell.label {
            set.push(
                &cell.features,
                cell.appearance.as_deref(),
                label,
                cell.centre_in_world,
            );
        }
    }
    set
}

/// `set` and the prior's support vectors, each labelled by the side of the
/// boundary it holds up and weighted so that together they count `prior_weight`
/// times the drive's cells. The prior's support vectors stand for what it learnt
/// from its own (annotated) cells.
fn with_prior_cells(set: &TrainingSet, prior: &SvmModel, prior_weight: f64) -> TrainingSet {
    let mut out = set.clone();
    let d = prior.dimension();
    let count = prior.support_vector_count();
    if count == 0 || d != set.dimension {
        return out;
    }
    let weight = (prior_weight * set.len() as f64 / count as f64) as f32;
    // Prior cells have no world position: they go to folds by their own index.
    let raw = prior.support_vectors_raw();
    for (i, (row, &coefficient)) in raw
        .chunks_exact(d)
        .zip(&prior.dual_coefficients)
        .enumerate()
    {
        let far_away = [1e7 + i as f64, 1e7];
        out.push_weighted(row, None, coefficient > 0.0, far_away, weight);
    }
    out
}

/// The unknown cells `model` classifies with a margin of at least `margin`, now
/// labelled by it, and the others.
fn confident_cells(
    model: &SvmModel,
    unknown: &[DriveCell],
    margin: f32,
) -> (Vec<DriveCell>, Vec<DriveCell>) {
    let geometric = model;
    let mut scratch = geometric.scratch();
    let (mut confident, mut unsure) = (Vec::new(), Vec::new());
    for cell in unknown {
        let mut value = geometric.cell_margin(&cell.features, None, &mut scratch, true);
        if let Some(prior) = &model.prior {
            let mut prior_scratch = prior.scratch();
            value += model.prior_weight
                * prior.cell_margin(&cell.features, None, &mut prior_scratch, true);
        }
        if value.abs() >= margin {
            confident.push(DriveCell {
                label: Some(value > 0.0),
                ..cell.clone()
            });
        } else {
            unsure.push(cell.clone());
        }
    }
    (confident, unsure)
}

fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}
