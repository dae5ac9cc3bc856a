//! Evaluation: metrics and timings accumulated over frames, and a model scored on
//! drives ([`score_drives`]).

use std::collections::HashSet;

use serde::Serialize;
use travmap_core::Config;
use travmap_core::error::{Error, Result};
use travmap_method::classifier::SvmModel;

use crate::scoring::metrics::{Confusion, Scores};
use crate::{DriveRun, Fingerprints};
use travmap_method::classifier::ForeignRemission;
use travmap_method::grid::CellClass;
use travmap_method::ground_truth::UnknownLabels;
use travmap_method::pipeline::{FrameResult, StageTimings};

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

/// Per-stage spreads of the frame timings, milliseconds (named as [`StageTimings`]'
/// figures are, so that a frame record and a summary say one name per figure).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct TimingReport {
    pub read_ms: Spread,
    /// Scan registration (0 when the poses are recorded).
    pub register_ms: Spread,
    pub integrate_ms: Spread,
    pub grid_ms: Spread,
    pub features_ms: Spread,
    pub appearance_ms: Spread,
    pub classify_ms: Spread,
    pub filter_ms: Spread,
    pub latency_ms: Spread,
}

impl TimingReport {
    pub fn of(timings: &[StageTimings]) -> Self {
        let spread =
            |f: fn(&StageTimings) -> f64| Spread::of(&timings.iter().map(f).collect::<Vec<_>>());
        Self {
            read_ms: spread(|t| t.read_ms),
            register_ms: spread(|t| t.register_ms),
            integrate_ms: spread(|t| t.integrate_ms),
            grid_ms: spread(|t| t.grid_ms),
            features_ms: spread(|t| t.features_ms),
            appearance_ms: spread(|t| t.appearance_ms),
            classify_ms: spread(|t| t.classify_ms),
            filter_ms: spread(|t| t.filter_ms),
            latency_ms: spread(|t| t.latency_ms),
        }
    }
}

pub use travmap_method::layers::UNSURE_MARGIN;
/// A drive whose share of unsure cells exceeds this fits the model poorly: unlike the
/// drives it learnt from (docs/method.md, "Knowing when it is not sure": no
/// held-out pair of the cross-dataset study below 60 mIoU stayed under it, none
/// above 85 went over).
pub const POOR_FIT_UNSURE_SHARE: f64 = 0.30;

/// How well drives fit the model, without labels: the share of predictable cells
/// whose margin lies within [`UNSURE_MARGIN`] of the decision boundary. On the drives
/// a model learnt from about a fifth; on another sensor or another kind of ground it
/// rises, and the scores fall.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Fit {
    /// Predictable cells, and those the model was unsure of.
    pub cells: u64,
    pub unsure_cells: u64,
    /// `unsure_cells / cells` (0 without cells).
    pub unsure_share: f64,
    /// Over [`POOR_FIT_UNSURE_SHARE`].
    pub poor: bool,
}

impl Fit {
    fn of(cells: u64, unsure_cells: u64) -> Self {
        let unsure_share = match cells {
            0 => 0.0,
            n => unsure_cells as f64 / n as f64,
        };
        Self {
            cells,
            unsure_cells,
            unsure_share,
            poor: unsure_share > POOR_FIT_UNSURE_SHARE,
        }
    }

    /// The predictable cells of a frame's margins and those within the unsure margin.
    pub fn counts(margins: &[f32]) -> (u64, u64) {
        let predicted = margins.iter().filter(|m| !m.is_nan());
        let unsure = margins.iter().filter(|m| m.abs() < UNSURE_MARGIN).count();
        (predicted.count() as u64, unsure as u64)
    }
}

/// Metrics of predictions against ground truth over a set of frames.
#[derive(Clone, Debug, Serialize)]
pub struct EvaluationReport {
    /// Frames with ground truth that were scored.
    pub scored_frames: usize,
    /// After the outlier filter: the method's output.
    pub confusion: Confusion,
    /// None (`null` in JSON) without a scored frame: no score is 0.
    pub scores: Option<Scores>,
    /// The classifier alone, before the filter.
    pub unfiltered_scores: Option<Scores>,
    /// Frames with a camera image, and their predictable cells that some image covered.
    pub frames_with_images: usize,
    pub cells_with_appearance: u64,
    /// Points the readers dropped as no return, over all frames.
    pub dropped_points: u64,
    /// Labelled points whose id the label set does not define, over all frames,
    /// and how many frames held them.
    pub unknown_labels: UnknownLabels,
    pub frames_with_unknown_labels: usize,
    /// Frames classified by the fallback model: remission features configured, but
    /// the input had no usable remission (missing, on an unknown scale, or NaN).
    pub frames_without_remission: usize,
    /// Points whose remission was NaN or infinite, over all frames (their scans had
    /// no usable remission).
    pub non_finite_remission_points: u64,
    /// Frames whose remission lay far outside the model's training range (another
    /// sensor's scale), classified by the fallback model; the first one's figures.
    pub frames_foreign_remission: usize,
    pub foreign_remission: Option<ForeignRemission>,
    /// How well the frames fit the model (no labels needed).
    /// P(traversable) against the labels (None without labelled predicted cells).
    pub calibration: Option<CalibrationReport>,
    pub fit: Fit,
    pub timings: TimingReport,
}

/// Accumulates frame results into an [`EvaluationReport`].
#[derive(Clone, Debug, Default)]
pub struct Evaluation {
    frames: usize,
    frames_with_images: usize,
    cells_with_appearance: u64,
    dropped_points: u64,
    unknown_labels: UnknownLabels,
    frames_with_unknown_labels: usize,
    frames_without_remission: usize,
    non_finite_remission_points: u64,
    frames_foreign_remission: usize,
    foreign_remission: Option<ForeignRemission>,
    predicted_cells: u64,
    unsure_cells: u64,
    filtered: Confusion,
    unfiltered: Confusion,
    reliability: Reliability,
    timings: Vec<StageTimings>,
}

/// How far the classifier's P(traversable) is from the share of cells that are
/// traversable, by tenths of P: the reliability diagram's bins.
#[derive(Clone, Copy, Debug, Default)]
struct Reliability {
    /// Per bin: labelled cells, the sum of their P, and how many are traversable.
    bins: [(u64, f64, u64); RELIABILITY_BINS],
}

const RELIABILITY_BINS: usize = 10;

impl Reliability {
    fn add(&mut self, probability: f32, traversable: bool) {
        let bin = ((probability * RELIABILITY_BINS as f32) as usize).min(RELIABILITY_BINS - 1);
        let (cells, sum, positives) = &mut self.bins[bin];
        *cells += 1;
        *sum += probability as f64;
        *positives += u64::from(traversable);
    }

    fn report(&self) -> Option<CalibrationReport> {
        let total: u64 = self.bins.iter().map(|b| b.0).sum();
        if total == 0 {
            return None;
        }
        let bins: Vec<ReliabilityBin> = (self.bins.iter().enumerate())
            .filter(|(_, b)| b.0 > 0)
            .map(|(i, &(cells, sum, positives))| ReliabilityBin {
                low: i as f64 / RELIABILITY_BINS as f64,
                high: (i + 1) as f64 / RELIABILITY_BINS as f64,
                cells,
                mean_probability: sum / cells as f64,
                share_traversable: positives as f64 / cells as f64,
            })
            .collect();
        let ece = (bins.iter())
            .map(|b| {
                b.cells as f64 / total as f64 * (b.mean_probability - b.share_traversable).abs()
            })
            .sum();
        Some(CalibrationReport {
            cells: total,
            expected_calibration_error: ece,
            bins,
        })
    }
}

/// How well the classifier's P(traversable) matches what is so, over the labelled
/// cells it predicted (before the filter).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CalibrationReport {
    pub cells: u64,
    /// The share-weighted mean |P - share traversable| over the bins (0..1).
    pub expected_calibration_error: f64,
    pub bins: Vec<ReliabilityBin>,
}

/// A tenth of P: its cells, their mean P and the share of them traversable.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReliabilityBin {
    pub low: f64,
    pub high: f64,
    pub cells: u64,
    pub mean_probability: f64,
    pub share_traversable: f64,
}

impl Evaluation {
    /// Adds a frame; frames without ground truth or predictions only add timings.
    pub fn add(&mut self, result: &FrameResult) {
        self.timings.push(result.timings);
        self.dropped_points += result.dropped_points as u64;
        if result.unknown_labels.points > 0 {
            self.unknown_labels.merge(&result.unknown_labels);
            self.frames_with_unknown_labels += 1;
        }
        self.frames_without_remission += result.without_remission as usize;
        self.non_finite_remission_points += result.non_finite_remission as u64;
        if let Some(margins) = &result.margins {
            let (cells, unsure) = Fit::counts(margins);
            self.predicted_cells += cells;
            self.unsure_cells += unsure;
        }
        if let Some(foreign) = result.foreign_remission {
            self.frames_foreign_remission += 1;
            self.foreign_remission.get_or_insert(foreign);
        }
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
            if let Some(probabilities) = &result.probabilities {
                for (&p, &t) in probabilities.iter().zip(truth.iter()) {
                    if !p.is_nan() && t != CellClass::Unknown {
                        self.reliability.add(p, t == CellClass::Traversable);
                    }
                }
            }
            self.filtered.merge(&Confusion::of_grids(filtered, truth));
            self.unfiltered
                .merge(&Confusion::of_grids(predicted, truth));
        }
    }

    pub fn report(&self) -> EvaluationReport {
        EvaluationReport {
            scored_frames: self.frames,
            confusion: self.filtered,
            scores: (self.frames > 0).then(|| self.filtered.scores()),
            unfiltered_scores: (self.frames > 0).then(|| self.unfiltered.scores()),
            frames_with_images: self.frames_with_images,
            cells_with_appearance: self.cells_with_appearance,
            dropped_points: self.dropped_points,
            unknown_labels: self.unknown_labels.clone(),
            frames_with_unknown_labels: self.frames_with_unknown_labels,
            frames_without_remission: self.frames_without_remission,
            non_finite_remission_points: self.non_finite_remission_points,
            frames_foreign_remission: self.frames_foreign_remission,
            foreign_remission: self.foreign_remission,
            fit: Fit::of(self.predicted_cells, self.unsure_cells),
            calibration: self.reliability.report(),
            timings: TimingReport::of(&self.timings),
        }
    }
}

/// A model scored on drives: its frames' report, the drives' fused maps against
/// their fused ground truth (each world cell once), and how many scored frames are
/// scans it was trained on.
#[derive(Clone, Debug)]
pub struct DriveScores {
    pub report: EvaluationReport,
    pub fused: Confusion,
    /// None when the model does not record the scans it learnt from.
    pub training_frames: Option<usize>,
}

/// Runs `model` over `selections` and scores every frame with ground truth;
/// `on_frame` hears each frame done. Training scans are recognised by content, not
/// by their path as typed: the labelled scans are fingerprinted when the model
/// records its own.
pub fn score_drives(
    selections: &mut [DriveRun],
    config: &Config,
    model: &SvmModel,
    mut on_frame: impl FnMut(),
) -> Result<DriveScores> {
    let trained_on: HashSet<&str> = (model.training.frame_sha256.iter())
        .map(String::as_str)
        .collect();
    if !trained_on.is_empty() {
        for selection in selections.iter_mut() {
            selection.fingerprint_scans = Fingerprints::Labelled;
        }
    }
    let mut evaluation = Evaluation::default();
    let mut fused = Confusion::default();
    let mut training_frames = 0;
    for selection in selections.iter() {
        let drive_map = selection.run_mapped::<Error>(config, Some(model), |result, _| {
            on_frame();
            let seen = (result.scan_sha256.as_deref()).is_some_and(|s| trained_on.contains(s));
            training_frames += usize::from(seen && result.ground_truth.is_some());
            evaluation.add(&result);
            Ok(())
        })?;
        fused.merge(&Confusion::of_drive_map(&drive_map.cells()));
    }
    Ok(DriveScores {
        report: evaluation.report(),
        fused,
        training_frames: (!trained_on.is_empty()).then_some(training_frames),
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
