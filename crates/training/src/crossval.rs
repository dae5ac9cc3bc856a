//! The cells training learns from, and spatially-blocked cross-validation: an honest
//! accuracy when the training and test frames overlap in space (as the shipped
//! frames do).

use serde::Serialize;

use super::train;
use travmap_core::config::{Config, FeatureGroup};
use travmap_core::error::{Error, Result};
use travmap_method::classifier::{PredictionScratch, SvmModel};
use travmap_method::filter::OutlierFilter;
use travmap_method::grid::CellClass;
use travmap_method::pipeline::FrameResult;
use travmap_method::training_set::{TrainingSet, spatial_folds};
use travmap_run::DriveRun;
use travmap_run::scoring::evaluation::{Evaluation, EvaluationReport};

/// Collects the labelled cells of the selected frames on the training grid
/// (`training.grid_size_m`).
pub fn collect_training_set<'a>(
    selections: impl IntoIterator<Item = &'a DriveRun>,
    config: &Config,
    on_frame: &mut dyn FnMut(),
) -> Result<TrainingSet> {
    let training_config = config.for_training_cells();
    let mut set = TrainingSet::for_features(config);
    for selection in selections {
        set.sources.push(selection.describe());
        let first_row = set.len();
        selection.run::<Error>(&training_config, None, |result| {
            if result.features.dimension != set.dimension {
                return Err(Error::Training(format!(
                    "{} frame {}: no usable remission (intensity), so no remission features to train on; train without them (--set features.groups=[\"context\"]) or on inputs with intensity",
                    selection.source.path().display(),
                    result.index
                )));
            }
            if let (Some(sha), true) = (&result.scan_sha256, result.ground_truth.is_some()) {
                set.frame_sha256.push(sha.clone());
            }
            for (cell, traversable) in result.labelled_cells() {
                set.push(
                    result.features.cell(cell),
                    result.features.appearance(cell),
                    traversable,
                    result.layout.cell_centre_in_world(cell),
                );
            }
            on_frame();
            Ok(())
        })?;
        set.input_rows.push(first_row..set.len());
    }
    if set.is_empty() {
        return Err(Error::Training(
            "no labelled cells in the selected frames (SemanticKITTI labels/ are needed)".into(),
        ));
    }
    Ok(set)
}

/// One outer fold of the cross-validation.
#[derive(Clone, Debug, Serialize)]
pub struct FoldReport {
    pub fold: usize,
    pub training_cells: usize,
    pub test_cells: usize,
    pub c: f64,
    pub gamma: f64,
    pub support_vectors: usize,
    pub training_ms: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct CrossValidationReport {
    pub block_size_m: f64,
    pub folds: Vec<FoldReport>,
    /// The held-out scores; its figures stand beside the folds in JSON.
    #[serde(flatten)]
    pub evaluation: EvaluationReport,
    /// When a camera saw cells: the paper's ablation on those cells alone.
    pub camera_ablation: Vec<AblationRow>,
}

/// One row of the camera ablation: the same blocked cross-validation with some
/// features, scored on the cells a camera saw.
#[derive(Clone, Debug, Serialize)]
pub struct AblationRow {
    /// G: the paper's 20 geometric features; R: remission; C: colour (appearance).
    pub features: &'static str,
    pub evaluation: EvaluationReport,
}

/// The ablation's feature sets: name, remission, colour.
const ABLATION: [(&str, bool, bool); 4] = [
    ("G", false, false),
    ("G+R", true, false),
    ("G+C", false, true),
    ("G+R+C", true, true),
];

/// Spatially-blocked cross-validation: the world plane is cut into blocks of
/// `training.block_size_m`, blocks are dealt into `training.folds` folds, and each
/// evaluation cell is predicted by a model (with its own inner grid search) trained
/// only on cells of the other folds. The out-of-fold predictions of each frame are
/// then filtered and scored like a normal run, so no test cell's world position is
/// ever a training cell.
pub fn cross_validate(
    selections: &[DriveRun],
    config: &Config,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<CrossValidationReport> {
    let (folds, frames) = out_of_fold(selections, config, progress)?;
    let mut evaluation = Evaluation::default();
    frames.iter().for_each(|result| evaluation.add(result));
    let seen = seen_cells(&frames);
    let camera_ablation = match seen.iter().flatten().any(|s| *s) {
        true => camera_ablation(selections, config, &seen, progress)?,
        false => Vec::new(),
    };
    Ok(CrossValidationReport {
        block_size_m: config.training.block_size_m,
        folds,
        evaluation: evaluation.report(),
        camera_ablation,
    })
}

/// Per frame, the cells a camera saw.
fn seen_cells(frames: &[FrameResult]) -> Vec<Vec<bool>> {
    frames
        .iter()
        .map(|result| {
            let features = &result.features;
            (0..features.predictable.len())
                .map(|cell| features.appearance(cell).is_some())
                .collect()
        })
        .collect()
}

/// The cross-validation again with each feature set of [`ABLATION`], scored on the
/// cells of `seen` (per frame, as the full run saw them).
fn camera_ablation(
    selections: &[DriveRun],
    config: &Config,
    seen: &[Vec<bool>],
    progress: &(dyn Fn(&str) + Sync),
) -> Result<Vec<AblationRow>> {
    let mut rows = Vec::new();
    for (name, remission, colour) in ABLATION {
        progress(&format!("camera ablation: {name}"));
        let mut variant = config.clone();
        variant.appearance.enabled = colour;
        variant.features.groups = match remission {
            true => vec![FeatureGroup::Remission],
            false => Vec::new(),
        };
        let (_, frames) = out_of_fold(selections, &variant, progress)?;
        let mut evaluation = Evaluation::default();
        for (mut result, seen) in frames.into_iter().zip(seen) {
            // Only the cells a camera saw are scored.
            if let Some(truth) = result.ground_truth.as_mut() {
                truth
                    .iter_mut()
                    .zip(seen)
                    .filter(|(_, seen)| !**seen)
                    .for_each(|(t, _)| *t = CellClass::Unknown);
            }
            evaluation.add(&result);
        }
        rows.push(AblationRow {
            features: name,
            evaluation: evaluation.report(),
        });
    }
    Ok(rows)
}

/// The folds' models and every labelled frame predicted by the model of the fold
/// each of its cells is in (filtered as a run filters).
fn out_of_fold(
    selections: &[DriveRun],
    config: &Config,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<(Vec<FoldReport>, Vec<FrameResult>)> {
    let pool = collect_training_set(selections, config, &mut || {})?;
    let mut frames: Vec<FrameResult> = Vec::new();
    for selection in selections {
        selection.run::<Error>(config, None, |result| {
            if result.ground_truth.is_some() {
                frames.push(result);
            }
            Ok(())
        })?;
    }
    // One block -> fold map over the pool's and the evaluation cells' centres.
    let mut centres = pool.centre_in_world.clone();
    for result in &frames {
        centres
            .extend((0..result.layout.cell_count()).map(|c| result.layout.cell_centre_in_world(c)));
    }
    let t = &config.training;
    let fold_of = spatial_folds(&centres, t.block_size_m, t.folds, t.seed);
    let (pool_folds, mut frame_folds) = fold_of.split_at(pool.len());

    let mut models: Vec<Option<SvmModel>> = Vec::new();
    let mut fold_reports = Vec::new();
    for fold in 0..t.folds {
        let training: Vec<usize> = (0..pool.len()).filter(|&i| pool_folds[i] != fold).collect();
        let test_cells = pool_folds.iter().filter(|&&f| f == fold).count();
        if test_cells == 0 || training.is_empty() {
            models.push(None);
            continue;
        }
        progress(&format!(
            "fold {}/{}: training on {} cells",
            fold + 1,
            t.folds,
            training.len()
        ));
        let model = train(&pool.subset(&training), config, &|_, _| {})?;
        fold_reports.push(FoldReport {
            fold,
            training_cells: training.len(),
            test_cells,
            c: model.c,
            gamma: model.gamma,
            support_vectors: model.support_vector_count(),
            training_ms: model.training.seconds * 1e3,
        });
        models.push(Some(model));
    }

    let filter = OutlierFilter {
        config: config.filter.clone(),
    };
    let mut scratch = PredictionScratch::default();
    let mut predicted_frames = Vec::with_capacity(frames.len());
    for mut result in frames {
        let (folds_here, rest) = frame_folds.split_at(result.layout.cell_count());
        frame_folds = rest;
        // Margins as a run keeps them (NaN where no fold's model predicts), so that
        // the report's fit is the held-out cells'.
        let margins: Vec<f32> = (0..result.layout.cell_count())
            .map(|cell| match &models[folds_here[cell]] {
                Some(model) if result.features.predictable[cell] => model.cell_margin(
                    result.features.cell(cell),
                    result.features.appearance(cell),
                    &mut scratch,
                    config.classifier.use_reduced_set,
                ),
                _ => f32::NAN,
            })
            .collect();
        let predicted: Vec<CellClass> = margins.iter().map(|&m| CellClass::of_margin(m)).collect();
        result.filtered = Some(filter.apply(&predicted, result.layout.cells_per_side));
        result.predicted = Some(predicted);
        result.margins = Some(margins);
        predicted_frames.push(result);
    }
    Ok((fold_reports, predicted_frames))
}

/// One input held out: trained on the others, scored on it.
#[derive(Clone, Debug, Serialize)]
pub struct HeldOutReport {
    /// The held-out input and its frames.
    pub input: String,
    pub training_cells: usize,
    pub c: f64,
    pub gamma: f64,
    pub support_vectors: usize,
    #[serde(flatten)]
    pub evaluation: EvaluationReport,
}

#[derive(Clone, Debug, Serialize)]
pub struct LeaveOneOutReport {
    pub held_out: Vec<HeldOutReport>,
    /// Every held-out frame scored together; its figures stand at the top in JSON.
    #[serde(flatten)]
    pub pooled: EvaluationReport,
}

/// Leave-one-input-out cross-validation: each input (a scene) in turn is scored by
/// a model trained, with its own grid search, on the cells of all the others. No
/// spatial blocks are needed: different inputs are different places. This is how
/// the model fares on a scene it has never seen.
pub fn leave_one_input_out(
    selections: &[DriveRun],
    config: &Config,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<LeaveOneOutReport> {
    if selections.len() < 2 {
        return Err(Error::Training(
            "leave-one-input-out needs at least two inputs".into(),
        ));
    }
    let mut pooled = Evaluation::default();
    let mut held_out = Vec::new();
    for (i, test) in selections.iter().enumerate() {
        let others = selections
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != i)
            .map(|(_, s)| s);
        progress(&format!("holding out {}", test.describe()));
        let set = collect_training_set(others, config, &mut || {})?;
        let model = train(&set, config, &|_, _| {})?;
        let mut evaluation = Evaluation::default();
        test.run::<Error>(config, Some(&model), |result| {
            evaluation.add(&result);
            pooled.add(&result);
            Ok(())
        })?;
        held_out.push(HeldOutReport {
            input: test.describe(),
            training_cells: set.len(),
            c: model.c,
            gamma: model.gamma,
            support_vectors: model.support_vector_count(),
            evaluation: evaluation.report(),
        });
    }
    Ok(LeaveOneOutReport {
        held_out,
        pooled: pooled.report(),
    })
}
