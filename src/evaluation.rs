//! Evaluation: metrics accumulated over frames, and the spatially-blocked
//! cross-validation that gives an honest accuracy when the training and test
//! frames overlap in space (as the shipped frames do).

use std::ops::Range;

use serde::Serialize;

use crate::classifier::training::{TrainingSet, spatial_folds, train};
use crate::classifier::{PredictionScratch, SvmModel};
use crate::config::Config;
use crate::error::{Error, Result};
use crate::features::FEATURE_COUNT;
use crate::filter::OutlierFilter;
use crate::grid::CellClass;
use crate::metrics::{Confusion, Scores};
use crate::pipeline::{FrameResult, StageTimings, run_sequence};
use crate::reading::Source;

/// Median and 95th percentile of a sample.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Spread {
    pub median: f64,
    pub p95: f64,
}

impl Spread {
    pub fn of(values: &[f64]) -> Self {
        if values.is_empty() {
            return Self::default();
        }
        let mut sorted = values.to_vec();
        sorted.sort_by(f64::total_cmp);
        let at = |q: f64| sorted[((sorted.len() - 1) as f64 * q).round() as usize];
        Self {
            median: at(0.5),
            p95: at(0.95),
        }
    }
}

/// Per-stage spreads of the frame timings, milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct TimingReport {
    pub read: Spread,
    pub integrate: Spread,
    pub grid: Spread,
    pub features: Spread,
    pub appearance: Spread,
    pub classify: Spread,
    pub filter: Spread,
    pub latency: Spread,
}

impl TimingReport {
    pub fn of(timings: &[StageTimings]) -> Self {
        let spread =
            |f: fn(&StageTimings) -> f64| Spread::of(&timings.iter().map(f).collect::<Vec<_>>());
        Self {
            read: spread(|t| t.read_ms),
            integrate: spread(|t| t.integrate_ms),
            grid: spread(|t| t.grid_ms),
            features: spread(|t| t.features_ms),
            appearance: spread(|t| t.appearance_ms),
            classify: spread(|t| t.classify_ms),
            filter: spread(|t| t.filter_ms),
            latency: spread(|t| t.latency_ms),
        }
    }
}

/// Metrics of predictions against ground truth over a set of frames.
#[derive(Clone, Debug, Serialize)]
pub struct EvaluationReport {
    /// Frames with ground truth that were scored.
    pub frames: usize,
    /// After the outlier filter: the method's output.
    pub confusion: Confusion,
    pub scores: Scores,
    /// The classifier alone, before the filter.
    pub unfiltered_scores: Scores,
    /// Frames with a camera image, and their predictable cells that some image covered.
    pub frames_with_images: usize,
    pub cells_with_appearance: u64,
    /// Points the readers dropped for a non-finite coordinate, over all frames.
    pub dropped_points: u64,
    pub timings_ms: TimingReport,
}

/// Accumulates frame results into an [`EvaluationReport`].
#[derive(Clone, Debug, Default)]
pub struct Evaluation {
    frames: usize,
    frames_with_images: usize,
    cells_with_appearance: u64,
    dropped_points: u64,
    filtered: Confusion,
    unfiltered: Confusion,
    timings: Vec<StageTimings>,
}

impl Evaluation {
    /// Adds a frame; frames without ground truth or predictions only add timings.
    pub fn add(&mut self, result: &FrameResult) {
        self.timings.push(result.timings);
        self.dropped_points += result.dropped_points as u64;
        let features = &result.features;
        let seen = (0..features.predictable.len())
            .filter(|&c| features.predictable[c] && features.appearance(c).is_some())
            .count();
        if seen > 0 {
            self.frames_with_images += 1;
            self.cells_with_appearance += seen as u64;
        }
        if let (Some(truth), Some(filtered), Some(predicted)) =
            (&result.ground_truth, &result.filtered, &result.predicted)
        {
            self.frames += 1;
            self.filtered.merge(&Confusion::of_grids(filtered, truth));
            self.unfiltered
                .merge(&Confusion::of_grids(predicted, truth));
        }
    }

    pub fn report(&self) -> EvaluationReport {
        EvaluationReport {
            frames: self.frames,
            confusion: self.filtered,
            scores: self.filtered.scores(),
            unfiltered_scores: self.unfiltered.scores(),
            frames_with_images: self.frames_with_images,
            cells_with_appearance: self.cells_with_appearance,
            dropped_points: self.dropped_points,
            timings_ms: TimingReport::of(&self.timings),
        }
    }
}

/// A sequence and the frames of it to use.
pub struct Selection {
    pub source: Source,
    pub frames: Range<usize>,
}

impl Selection {
    /// Runs the pipeline over the selected frames (see [`run_sequence`]).
    pub fn run<E: From<Error>>(
        &self,
        config: &Config,
        model: Option<&SvmModel>,
        on_frame: impl FnMut(FrameResult) -> Result<(), E>,
    ) -> Result<(), E> {
        run_sequence(&self.source, &self.frames, config, model, on_frame)
    }

    pub fn describe(&self) -> String {
        let last = self.source.frames_in(&self.frames).last().copied();
        match last {
            Some(last) => format!(
                "{} frames {}..={}",
                self.source.path().display(),
                self.frames.start,
                last
            ),
            None => format!("{} (no frames in range)", self.source.path().display()),
        }
    }
}

/// Collects the labelled cells of the selected frames on the training grid
/// (`training.grid_size_m`).
pub fn collect_training_set(
    selections: &[Selection],
    config: &Config,
    on_frame: &mut dyn FnMut(),
) -> Result<TrainingSet> {
    let mut training_config = config.clone();
    training_config.grid.size_m = config.training.grid_size_m;
    let mut set = TrainingSet {
        dimension: FEATURE_COUNT,
        ..Default::default()
    };
    for selection in selections {
        set.sources.push(selection.describe());
        selection.run::<Error>(&training_config, None, |result| {
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
    pub training_seconds: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct CrossValidationReport {
    pub block_size_m: f64,
    pub folds: Vec<FoldReport>,
    pub evaluation: EvaluationReport,
}

/// Spatially-blocked cross-validation: the world plane is cut into blocks of
/// `training.block_size_m`, blocks are dealt into `training.folds` folds, and each
/// evaluation cell is predicted by a model (with its own inner grid search) trained
/// only on cells of the other folds. The out-of-fold predictions of each frame are
/// then filtered and scored like a normal run, so no test cell's world position is
/// ever a training cell.
pub fn cross_validate(
    selections: &[Selection],
    config: &Config,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<CrossValidationReport> {
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
        let mut model = train(&pool.subset(&training), config, &|_, _| {})?;
        if !config.classifier.use_reduced_set {
            model.reduced_set = None;
        }
        fold_reports.push(FoldReport {
            fold,
            training_cells: training.len(),
            test_cells,
            c: model.c,
            gamma: model.gamma,
            support_vectors: model.support_vector_count(),
            training_seconds: model.training.seconds,
        });
        models.push(Some(model));
    }

    let filter = OutlierFilter {
        config: config.filter.clone(),
    };
    let mut evaluation = Evaluation::default();
    let mut scratch = PredictionScratch::default();
    for mut result in frames {
        let (folds_here, rest) = frame_folds.split_at(result.layout.cell_count());
        frame_folds = rest;
        let predicted: Vec<CellClass> = (0..result.layout.cell_count())
            .map(|cell| match &models[folds_here[cell]] {
                Some(model) if result.features.predictable[cell] => model.classify_cell(
                    result.features.cell(cell),
                    result.features.appearance(cell),
                    &mut scratch,
                ),
                _ => CellClass::Unknown,
            })
            .collect();
        result.filtered = Some(filter.apply(&predicted, result.layout.cells_per_side));
        result.predicted = Some(predicted);
        evaluation.add(&result);
    }
    Ok(CrossValidationReport {
        block_size_m: t.block_size_m,
        folds: fold_reports,
        evaluation: evaluation.report(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_of_a_known_sample() {
        let s = Spread::of(&[5.0, 1.0, 3.0, 2.0, 4.0]);
        assert_eq!(s.median, 3.0);
        assert_eq!(s.p95, 5.0);
        assert_eq!(Spread::of(&[]), Spread::default());
    }
}
