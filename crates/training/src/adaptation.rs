//! Self-supervised adaptation (`travmap adapt`): a model learnt from drives without
//! annotations. Each drive is run with a prior model along its trajectory; the
//! footprint and self-label stages (`method/footprint.rs`, `method/self_labels.rs`)
//! label its cells; an SVM is fitted to them as `adapt.learner` says, with
//! `adapt.rounds` of self-training. The drives' labels, if they have any, are never
//! read (`Source::set_read_labels`).
//!
//! The adapted model replaces the prior only where the drives show it is better
//! (`check_against_prior`): on the cells the vehicle drove over and the cells over
//! its clearance, evidence that owes nothing to the prior, held out of the fit a
//! block of the world at a time. Otherwise the prior is kept, and the model file says
//! why.

use std::collections::HashSet;

use serde::Serialize;

use super::reduced_set::fit_folded_reduced_set;
use super::{REMISSION_COLUMNS, Reduce, Search, config_without_remission, train_by};
use travmap_core::config::{Config, FeatureGroup, Learner};
use travmap_core::error::{Error, Result};
use travmap_core::random::SplitMix64;
use travmap_method::classifier::{AdaptationCheck, AdaptationSummary, AdaptedInput, SvmModel};
use travmap_method::features::feature_count;
use travmap_method::footprint::PathKind;
use travmap_method::grid::CellClass;
use travmap_method::self_labels::over_clearance;
use travmap_method::training_set::TrainingSet;
use travmap_run::scoring::metrics::Confusion;
use travmap_run::{DriveRun, Fingerprints};

/// One self-labelled (or unknown) cell of a drive.
#[derive(Clone)]
struct DriveCell {
    features: Vec<f32>,
    appearance: Option<Vec<f32>>,
    /// None: unknown.
    label: Option<bool>,
    /// Its label is the drive's own evidence, owing nothing to the prior: the
    /// vehicle drove over it, or it is over the vehicle's clearance.
    evidence: bool,
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
    /// Whether the adapted model replaced the prior (false: the prior is kept, its
    /// file says why).
    pub fn replaced_prior(&self) -> bool {
        let check = self
            .model
            .training
            .adaptation
            .as_ref()
            .and_then(|a| a.check.as_ref());
        check.is_none_or(|check| check.adapted)
    }

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
    selections: &mut [DriveRun],
    config: &Config,
    prior: &SvmModel,
    prior_name: &str,
    on_frame: &mut dyn FnMut(),
) -> Result<Adapted> {
    let grid_config = config.for_training_cells();
    let (a, vehicle) = (&config.adapt, &config.vehicle);
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
                let cell_of = || {
                    let features = result.features.cell(cell).to_vec();
                    let evidence = match label {
                        Some(true) => true,
                        Some(false) => a.geometric_negatives && over_clearance(&features, vehicle),
                        None => false,
                    };
                    DriveCell {
                        appearance: result.features.appearance(cell).map(<[f32]>::to_vec),
                        label: *label,
                        evidence,
                        centre_in_world: result.layout.cell_centre_in_world(cell),
                        features,
                    }
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
    // A drive that shows too little of its ground, or no obstacle, cannot show that
    // an adapted model is better: the prior is kept, and the file says why.
    let unlabelled_learnt = a.unlabelled_weight > 0.0 && counts.unknown_cells > 0;
    let too_little = if counts.footprint_cells < a.min_footprint_cells {
        Some(format!(
            "the prior is kept: the drive shows {} footprint cells (cells the vehicle drove over that hold points), at least {} needed (adapt.min_footprint_cells): the vehicle moved {trajectory_m:.1} m; a vehicle standing still or a drive this short shows too little of its ground to adapt to",
            counts.footprint_cells, a.min_footprint_cells
        ))
    } else if counts.negative_cells == 0 && !unlabelled_learnt {
        Some(format!(
            "the prior is kept: no cell is an obstacle (over vehicle.clearance_m = {} m) or rejected by the prior with a margin of -{} or less, so every self-label says traversable; lower adapt.negative_margin, learn the unknown cells as negatives (adapt.unlabelled_weight) or adapt on a drive with obstacles",
            config.vehicle.clearance_m, a.negative_margin
        ))
    } else {
        None
    };

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
    // `reduced`: with the reduced set that classifies (the checks' fits need none).
    let fit = |set: &TrainingSet, reduced: bool| -> Result<SvmModel> {
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
        let none = |_: &SvmModel, _: &TrainingSet| None;
        let reduce = match (reduced, a.learner) {
            (false, _) => Some(&none as &Reduce),
            (true, Learner::Sum) => Some(&folded as &Reduce),
            (true, _) => None,
        };
        let mut model = train_by(cells, config, search, reduce, false, &|_, _| {})?;
        model.fallback = prior.fallback.clone();
        if a.learner == Learner::Sum {
            model.prior = Some(Box::new(prior.clone()));
            model.prior_weight = weight;
            model.reduced_set_includes_prior = model.reduced_set.is_some();
        }
        Ok(model)
    };
    // What the model file says of the adaptation: which parts were fitted and why.
    let summary = |model: &SvmModel, fitted_cells: usize, check: AdaptationCheck| {
        let hybrid = match (&model.hybrid, check.adapted) {
            (_, false) => "the prior's: the prior is kept".into(),
            (Some(hybrid), true) => format!(
                "fitted on the {} cells cameras saw",
                hybrid.training.samples
            ),
            (None, true) => "none: no camera saw the drives' cells".into(),
        };
        let fallback = match (uses_remission, without_remission, check.adapted) {
            (false, _, _) => "none: the model has no remission features".into(),
            (true, _, false) => "the prior's: the prior is kept".into(),
            (true, true, true) => format!(
                "fitted to the drives, whose {frames_without_remission} frames had no usable remission (the model with remission is the prior's)"
            ),
            (true, false, true) => {
                "the prior's: every frame had usable remission, so the drives use none".into()
            }
        };
        AdaptationSummary {
            self_supervised: true,
            learner: a.learner,
            prior: prior_name.to_string(),
            prior_sha256: original_prior.sha256_hex(),
            inputs: inputs.clone(),
            footprint_cells: counts.footprint_cells,
            negative_cells: counts.negative_cells,
            unknown_cells: counts.unknown_cells,
            fitted_cells,
            straight_path_frames: counts.straight_path_frames,
            hybrid,
            fallback,
            check: Some(check),
        }
    };
    let unchecked = |adapted: bool, why: String| AdaptationCheck {
        adapted,
        why,
        footprint_samples: 0,
        clearance_samples: 0,
        blocks: 0,
        prior_miou: None,
        adapted_miou: None,
        confident_unknown: 0,
        flipped_unknown: 0,
    };
    let check = match (too_little, a.check) {
        (Some(why), _) => unchecked(false, why),
        (None, true) => check_against_prior(
            &labelled,
            &unknown,
            counts.straight_path_frames == counts.frames,
            &|cells| fit(&to_set(cells, &unknown), false),
            prior,
            config.training.seed,
        )?,
        (None, false) => unchecked(
            true,
            "the adapted model replaces the prior unchecked (adapt.check = false)".into(),
        ),
    };
    notices.push(format!("{}: {}", path.display(), check.why));
    if !check.adapted {
        let mut kept = original_prior.clone();
        kept.training.adaptation = Some(summary(&kept, 0, check));
        // What it is, named as this run named it.
        kept.config.classifier.model = original_config.classifier.model.clone();
        return Ok(Adapted {
            model: kept,
            counts,
            notices,
            fallback_fitted: false,
        });
    }
    let mut model = fit(&drive, true)?;
    // Self-training: the unknown cells the adapted model is sure of join its cells.
    for _ in 0..a.rounds {
        let (confident, unsure) = confident_cells(&model, &unknown, a.self_training_margin as f32);
        if confident.is_empty() {
            break;
        }
        drive = to_set(&[labelled.clone(), confident].concat(), &unsure);
        model = fit(&drive, true)?;
    }
    if without_remission {
        // The drives' model classifies what they show, clouds without remission: it
        // is the prior's fallback; clouds with remission keep the prior's model.
        let mut outer = original_prior.clone();
        outer.fallback = Some(Box::new(model));
        model = outer;
    }
    model.training.adaptation = Some(summary(&model, drive.len(), check));
    model.training.sources = selections.iter().map(DriveRun::describe).collect();
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

/// Blocks of the world the check holds out of the fit one fold at a time, metres:
/// wider than the features' neighbourhoods, so that a held-out cell's neighbours are
/// not among the cells fitted.
const CHECK_BLOCK_M: f64 = 8.0;
const CHECK_FOLDS: usize = 3;
/// Held-out cells of each class (footprint, clearance) the check needs at least.
const MIN_CHECK_CELLS: usize = 30;
/// How much better (mIoU on the held-out evidence) the adapted model must be than
/// its prior to replace it: less is within what a few hundred cells can tell apart.
const MIN_CHECK_GAIN: f64 = 0.01;
/// A margin the prior is sure of (the fit report's).
const CONFIDENT_MARGIN: f32 = 1.0;
/// The share of the cells the drive says nothing of and the prior was sure were
/// traversable that the adapted model may call not traversable: more, and it learnt
/// what the evidence cannot check. Where adaptation helped on the shipped drives it
/// turned at most 0.2 % of them (docs/method.md).
const MAX_FLIPPED_SHARE: f64 = 0.02;

/// Whether the model `fit` makes of `labelled` may replace `prior`. The evidence is
/// what the drive shows without the prior: the cells the vehicle drove over
/// (traversable) and those over its clearance (not). The world is cut into blocks
/// of [`CHECK_BLOCK_M`] dealt into [`CHECK_FOLDS`] folds; each fold's evidence is
/// classified by a model fitted to the cells of the other folds (exact, without its
/// reduced set) and by the prior, and the two are scored by mIoU. A drive whose
/// footprint was guessed (no trajectory), or with too little evidence to tell the
/// two apart, keeps the prior.
fn check_against_prior(
    labelled: &[DriveCell],
    unknown: &[DriveCell],
    path_guessed: bool,
    fit: &dyn Fn(&[DriveCell]) -> Result<SvmModel>,
    prior: &SvmModel,
    seed: u64,
) -> Result<AdaptationCheck> {
    let block = |cell: &DriveCell| {
        cell.centre_in_world
            .map(|v| (v / CHECK_BLOCK_M).floor() as i64)
    };
    let evidence: Vec<&DriveCell> = labelled.iter().filter(|c| c.evidence).collect();
    let footprint_samples = evidence.iter().filter(|c| c.label == Some(true)).count();
    let clearance_samples = evidence.len() - footprint_samples;
    let mut blocks: Vec<[i64; 2]> = evidence.iter().map(|c| block(c)).collect();
    blocks.sort_unstable();
    blocks.dedup();
    let mut check = AdaptationCheck {
        adapted: false,
        why: String::new(),
        footprint_samples,
        clearance_samples,
        blocks: blocks.len(),
        prior_miou: None,
        adapted_miou: None,
        confident_unknown: 0,
        flipped_unknown: 0,
    };
    let held = format!(
        "{footprint_samples} samples of cells driven over and {clearance_samples} over the clearance, a world cell once for every frame that saw it, in {} blocks of {CHECK_BLOCK_M} m",
        blocks.len()
    );
    if path_guessed {
        check.why = "the prior is kept: the footprint was guessed (no trajectory beyond one pose), so the drive cannot show that an adapted model is better".into();
        return Ok(check);
    }
    if footprint_samples.min(clearance_samples) < MIN_CHECK_CELLS || blocks.len() < CHECK_FOLDS {
        check.why = format!(
            "the prior is kept: too little of the drive's own evidence to tell an adapted model from it ({held}; at least {MIN_CHECK_CELLS} of each in {CHECK_FOLDS} blocks)"
        );
        return Ok(check);
    }
    // The evidence's blocks dealt into folds in a seeded order; cells of other
    // blocks are fitted in every fold.
    SplitMix64(seed).shuffle(&mut blocks);
    let fold_of: std::collections::HashMap<[i64; 2], usize> = (blocks.iter().enumerate())
        .map(|(i, b)| (*b, i % CHECK_FOLDS))
        .collect();
    let fold = |cell: &DriveCell| fold_of.get(&block(cell)).copied();
    // An unknown cell in a block without evidence is held out with the fold its
    // block's coordinates deal it to.
    let unknown_fold = |cell: &DriveCell| {
        fold(cell).unwrap_or_else(|| {
            let [x, y] = block(cell);
            (x.wrapping_mul(73_856_093) ^ y.wrapping_mul(19_349_663)).rem_euclid(CHECK_FOLDS as i64)
                as usize
        })
    };
    let (mut by_prior, mut by_adapted) = (Confusion::default(), Confusion::default());
    for k in 0..CHECK_FOLDS {
        let fitted: Vec<DriveCell> = (labelled.iter())
            .filter(|c| fold(c) != Some(k))
            .cloned()
            .collect();
        let held_out = evidence.iter().filter(|c| fold(c) == Some(k));
        let adapted = match fit(&fitted) {
            Ok(model) => model,
            // A fold whose fitted cells hold one class only cannot be compared.
            Err(Error::Training(_)) => continue,
            Err(e) => return Err(e),
        };
        for cell in held_out {
            let truth = class_of(cell.label == Some(true));
            by_prior.add(class_of(margin(prior, &cell.features) > 0.0), truth);
            by_adapted.add(class_of(margin(&adapted, &cell.features) > 0.0), truth);
        }
        // What the drive cannot show: the cells it says nothing of that the prior
        // was sure were traversable. A footprint shows where the vehicle went, never
        // that ground it did not drive over is not traversable: a car's footprint of
        // road alone teaches that grass is not, which the evidence cannot see.
        for cell in unknown.iter().filter(|c| unknown_fold(c) == k) {
            if margin(prior, &cell.features) < CONFIDENT_MARGIN {
                continue;
            }
            check.confident_unknown += 1;
            check.flipped_unknown += usize::from(margin(&adapted, &cell.features) <= 0.0);
        }
    }
    let (prior_miou, adapted_miou) = (by_prior.scores().miou, by_adapted.scores().miou);
    (check.prior_miou, check.adapted_miou) = (Some(prior_miou), Some(adapted_miou));
    let better = adapted_miou >= prior_miou + MIN_CHECK_GAIN;
    let flipped_share = match check.confident_unknown {
        0 => 0.0,
        n => check.flipped_unknown as f64 / n as f64,
    };
    let flips_too_many = flipped_share > MAX_FLIPPED_SHARE;
    check.adapted = better && !flips_too_many;
    let verdict = match check.adapted {
        true => "the adapted model replaces the prior",
        false => "the prior is kept",
    };
    check.why = format!(
        "{verdict}: on the drive's own evidence held out of the fit ({held}) the adapted model scores mIoU {:.1}, the prior {:.1}",
        100.0 * adapted_miou,
        100.0 * prior_miou
    );
    if better && flips_too_many {
        check.why += &format!(
            ", but of the {} held-out cells the drive says nothing of and the prior was sure were traversable, it calls {:.1} % not traversable (at most {:.0} %: beyond, it has learnt what the drive cannot show, as a road footprint teaches that grass is not traversable)",
            check.confident_unknown,
            100.0 * flipped_share,
            100.0 * MAX_FLIPPED_SHARE
        );
    }
    Ok(check)
}

fn class_of(traversable: bool) -> CellClass {
    match traversable {
        true => CellClass::Traversable,
        false => CellClass::NonTraversable,
    }
}

/// A model's margin of a cell's geometric features, its prior's added (the `sum`
/// learner's models), each by its reduced set where it has one.
fn margin(model: &SvmModel, features: &[f32]) -> f32 {
    let mut scratch = model.scratch();
    let own = model.cell_margin(features, None, &mut scratch, true);
    match &model.prior {
        Some(prior) => own + model.prior_weight * margin(prior, features),
        None => own,
    }
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
    let (mut confident, mut unsure) = (Vec::new(), Vec::new());
    for cell in unknown {
        let value = self::margin(model, &cell.features);
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

#[cfg(test)]
mod tests {
    use super::*;
    use travmap_method::classifier::TrainingSummary;

    /// A one-feature model: `sum_i w_i exp(-(x - c_i)^2)`, no offset.
    fn model(terms: &[(f32, f32)]) -> SvmModel {
        let training = TrainingSummary {
            sources: Vec::new(),
            samples: 0,
            traversable_samples: 0,
            search: Vec::new(),
            solver_iterations: 0,
            solver_converged: true,
            seconds: 0.0,
            frame_sha256: Vec::new(),
            adaptation: None,
        };
        let (centres, weights): (Vec<f32>, Vec<f32>) = terms.iter().map(|&(c, w)| (c, w)).unzip();
        SvmModel::new(
            vec![0.0],
            vec![1.0],
            1.0,
            1.0,
            0.0,
            weights,
            centres,
            Config::default(),
            training,
        )
    }

    fn cell(x: f32, label: Option<bool>, evidence: bool, i: usize) -> DriveCell {
        DriveCell {
            features: vec![x],
            appearance: None,
            label,
            evidence,
            // Cells spread over many blocks of the world.
            centre_in_world: [i as f64 * CHECK_BLOCK_M + 1.0, 0.0],
        }
    }

    /// Regression (issue "teach it your robot", 5): an adaptation that turned the
    /// prior's sure calls off the evidence (a road footprint teaching that grass is
    /// not traversable) replaced the prior, because the evidence cannot see them.
    #[test]
    fn an_adaptation_that_turns_what_the_drive_cannot_show_keeps_the_prior() {
        // Footprint at 0 and 2.5 (the prior misreads 2.5), obstacles at 10, and
        // ground the drive says nothing of at 5, which the prior is sure is traversable.
        let prior = model(&[(0.0, 3.0), (5.0, 3.0), (2.5, -3.0), (10.0, -3.0)]);
        let mut labelled = Vec::new();
        let mut unknown = Vec::new();
        for i in 0..40 {
            labelled.push(cell(
                if i % 2 == 0 { 0.0 } else { 2.5 },
                Some(true),
                true,
                i,
            ));
            labelled.push(cell(10.0, Some(false), true, i));
            unknown.push(cell(5.0, None, false, i));
        }
        // Right on all the evidence, and turning the unknown ground.
        let turning = model(&[(0.0, 3.0), (2.5, 3.0), (5.0, -3.0), (10.0, -3.0)]);
        let check = check_against_prior(
            &labelled,
            &unknown,
            false,
            &|_| Ok(turning.clone()),
            &prior,
            0,
        )
        .unwrap();
        assert!(check.adapted_miou > check.prior_miou, "{check:?}");
        assert!(!check.adapted, "{check:?}");
        assert_eq!(check.flipped_unknown, check.confident_unknown);
        assert!(
            check.why.contains("it calls 100.0 % not traversable"),
            "{}",
            check.why
        );
        // The same evidence won without turning it: replaced.
        let keeping = model(&[(0.0, 3.0), (2.5, 3.0), (5.0, 3.0), (10.0, -3.0)]);
        let check = check_against_prior(
            &labelled,
            &unknown,
            false,
            &|_| Ok(keeping.clone()),
            &prior,
            0,
        )
        .unwrap();
        assert!(check.adapted && check.flipped_unknown == 0, "{check:?}");
    }
}
