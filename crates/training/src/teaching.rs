//! A model for a team's robot from a few answers (`travmap train LABELS --prior
//! MODEL`): the cells a person labelled (`travmap label`) learnt together with the
//! prior's support vectors, which stand for the annotated cells the prior learnt
//! from, so that a team needs none of travmap's data. The person's cells each weigh
//! `training.taught_weight` (the labelling study's choice, docs/method.md); C and
//! gamma are the prior's (a hundred cells cannot choose them). The hybrid and
//! fallback parts are the prior's: the answers teach the geometric model.
//!
//! Checked on the person's own cells, held out a block of the world at a time: each
//! fold's cells are classified by a model taught without them and by the prior.

use serde::Serialize;

use super::{Reduce, Search, train_by};
use travmap_core::config::Config;
use travmap_core::error::{Error, Result};
use travmap_core::random::SplitMix64;
use travmap_method::classifier::SvmModel;
use travmap_method::grid::CellClass;
use travmap_method::training_set::TrainingSet;
use travmap_run::scoring::metrics::Confusion;

/// Blocks of the world the check holds out at a time, metres: wider than a
/// feature's neighbourhood; the folds it deals them into.
const CHECK_BLOCK_M: f64 = 8.0;
const CHECK_FOLDS: usize = 3;

/// How a taught model fared against its prior on the person's own cells, held out.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TeachingCheck {
    /// The labelled cells, and the blocks of the world they lie in.
    pub cells: usize,
    pub blocks: usize,
    /// mIoU and accuracy (0..1) of the prior and of the taught model on the held-out
    /// cells; None when the cells were too few (or of one class) to compare.
    pub prior_miou: Option<f64>,
    pub taught_miou: Option<f64>,
    pub prior_accuracy: Option<f64>,
    pub taught_accuracy: Option<f64>,
}

impl TeachingCheck {
    /// The check in a line, as a person reads it.
    pub fn said(&self) -> String {
        match (self.prior_miou, self.taught_miou) {
            (Some(prior), Some(taught)) => format!(
                "on your {} labelled cells, each held out of the fit a block of {CHECK_BLOCK_M} m at a time ({} blocks): the prior scores mIoU {:.1} (accuracy {:.1}), the taught model {:.1} ({:.1})",
                self.cells,
                self.blocks,
                100.0 * prior,
                100.0 * self.prior_accuracy.unwrap_or_default(),
                100.0 * taught,
                100.0 * self.taught_accuracy.unwrap_or_default()
            ),
            _ => format!(
                "your {} labelled cells lie in {} blocks of {CHECK_BLOCK_M} m, or hold one class: too few to check the taught model against the prior ({CHECK_FOLDS} blocks and both classes needed)",
                self.cells, self.blocks
            ),
        }
    }
}

/// `cells` (a person's answers) learnt with `prior`'s support vectors, under
/// `config`; and the check of the result on `cells` held out. `progress(done,
/// total)` counts the fits.
pub fn teach(
    cells: &TrainingSet,
    prior: &SvmModel,
    config: &Config,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<(SvmModel, TeachingCheck)> {
    if cells.dimension != prior.dimension() {
        return Err(Error::Training(format!(
            "the labelled cells have {} features, the prior {}: label with the prior's feature settings",
            cells.dimension,
            prior.dimension()
        )));
    }
    if prior.prior.is_some() {
        return Err(Error::Training(
            "the prior is a model adapted by the `sum` learner, whose support vectors are not all it knows: teach the model it was adapted from".into(),
        ));
    }
    let weight = config.training.taught_weight as f32;
    // `reduced`: with the reduced set that classifies (the check's fits need none).
    let fit = |taught: &TrainingSet, reduced: bool| -> Result<SvmModel> {
        let set = with_prior_cells(taught, prior, weight);
        let search = Search::Fixed {
            c: prior.c,
            gamma: prior.gamma,
        };
        let none = |_: &SvmModel, _: &TrainingSet| None;
        let reduce = (!reduced).then_some(&none as &Reduce);
        let mut model = train_by(&set, config, search, reduce, false, &|_, _| {})?;
        model.hybrid = prior.hybrid.clone();
        model.fallback = prior.fallback.clone();
        Ok(model)
    };
    // The folds of the check first, then the model of every cell.
    let (folds, blocks) = folds_of(cells, config.training.seed);
    let total = CHECK_FOLDS + 1;
    let mut check = TeachingCheck {
        cells: cells.len(),
        blocks,
        ..Default::default()
    };
    let both_classes =
        cells.traversable.iter().any(|&t| t) && cells.traversable.iter().any(|&t| !t);
    if blocks >= CHECK_FOLDS && both_classes {
        let (mut by_prior, mut by_taught) = (Confusion::default(), Confusion::default());
        for k in 0..CHECK_FOLDS {
            progress(k, total);
            let fitted: Vec<usize> = (0..cells.len()).filter(|&i| folds[i] != k).collect();
            let taught = fit(&cells.subset(&fitted), false)?;
            let d = cells.dimension;
            for i in (0..cells.len()).filter(|&i| folds[i] == k) {
                let row = &cells.features[i * d..(i + 1) * d];
                let truth = class_of(cells.traversable[i]);
                by_prior.add(class_of(margin(prior, row) > 0.0), truth);
                by_taught.add(class_of(margin(&taught, row) > 0.0), truth);
            }
        }
        let (prior_scores, taught_scores) = (by_prior.scores(), by_taught.scores());
        check.prior_miou = Some(prior_scores.miou);
        check.taught_miou = Some(taught_scores.miou);
        check.prior_accuracy = Some(prior_scores.accuracy);
        check.taught_accuracy = Some(taught_scores.accuracy);
    }
    progress(CHECK_FOLDS, total);
    let mut model = fit(cells, true)?;
    model.training.sources = [
        cells.sources.clone(),
        vec![format!(
            "{} support vectors of the prior (sha256 {})",
            prior.support_vector_count(),
            &prior.sha256_hex()[..12]
        )],
    ]
    .concat();
    progress(total, total);
    Ok((model, check))
}

/// Each cell's fold of the check (by its block of the world, blocks dealt in a
/// seeded order), and the number of blocks.
fn folds_of(cells: &TrainingSet, seed: u64) -> (Vec<usize>, usize) {
    let block = |p: &[f64; 2]| p.map(|v| (v / CHECK_BLOCK_M).floor() as i64);
    let mut blocks: Vec<[i64; 2]> = cells.centre_in_world.iter().map(block).collect();
    blocks.sort_unstable();
    blocks.dedup();
    SplitMix64(seed).shuffle(&mut blocks);
    let fold_of: std::collections::HashMap<[i64; 2], usize> = (blocks.iter().enumerate())
        .map(|(i, b)| (*b, i % CHECK_FOLDS))
        .collect();
    let folds = cells
        .centre_in_world
        .iter()
        .map(|p| fold_of[&block(p)])
        .collect();
    (folds, blocks.len())
}

/// A model's margin of a cell's geometric features (by its reduced set where it
/// has one, as it classifies).
fn margin(model: &SvmModel, features: &[f32]) -> f32 {
    let mut scratch = model.scratch();
    model.cell_margin(features, None, &mut scratch, true)
}

fn class_of(traversable: bool) -> CellClass {
    match traversable {
        true => CellClass::Traversable,
        false => CellClass::NonTraversable,
    }
}

/// `taught` (weighing `weight` each, without appearance: the hybrid part is the
/// prior's) and the prior's support vectors, each labelled by the side of the
/// boundary it holds up and weighing 1. Prior cells have no world position: they lie
/// far from every taught cell.
pub(crate) fn with_prior_cells(taught: &TrainingSet, prior: &SvmModel, weight: f32) -> TrainingSet {
    let d = taught.dimension;
    let mut set = TrainingSet {
        dimension: d,
        sources: taught.sources.clone(),
        frame_sha256: taught.frame_sha256.clone(),
        ..Default::default()
    };
    // Each weighing 1, the classes balanced: bounds on C at the prior's own
    // coefficients (its solution again, moved only where the person's cells say so)
    // scored lower on every held-out dataset of the study (docs/method.md).
    let raw = prior.support_vectors_raw();
    for (i, (row, &coefficient)) in raw
        .chunks_exact(d)
        .zip(&prior.dual_coefficients)
        .enumerate()
    {
        set.push_weighted(row, None, coefficient > 0.0, [1e7 + i as f64, 1e7], 1.0);
    }
    for i in 0..taught.len() {
        let row = &taught.features[i * d..(i + 1) * d];
        let cell_weight = weight * taught.weight[i];
        set.push_weighted(
            row,
            None,
            taught.traversable[i],
            taught.centre_in_world[i],
            cell_weight,
        );
    }
    set
}
