//! The method in order. [`Pipeline::process_frame`] calls every stage, one comment
//! per step; the scan window and the colour memory are the only state carried from
//! frame to frame. [`run_sequence`] feeds it the frames of an input.
//!
//! A frame's work splits in two: [`Pipeline::observe`] (grid, geometric features,
//! the image's votes) needs no state, so frames can run in parallel
//! ([`process_in_parallel`]); [`Pipeline::decide`] (classification, filter) takes the
//! appearance features that the colour memory has accumulated up to that frame.

use std::collections::VecDeque;
use std::ops::Range;
use std::time::Instant;

use nalgebra::Isometry3;
use rayon::prelude::*;
use serde::Serialize;

use crate::appearance::{AppearanceVoter, CameraImage, ColourMemory, FrameVotes};
use crate::classifier::SvmModel;
use crate::config::Config;
use crate::error::{Error, Result};
use crate::features::{FeatureExtractor, FeatureGrid};
use crate::filter::OutlierFilter;
use crate::grid::{CellClass, CellPoints, GridLayout, grid_points};
use crate::ground_truth::GroundTruth;
use crate::integration::{WorldScan, ground_normal, scan_to_world};
use crate::reading::{Frame, Source};

/// Wall time of each stage for one frame, milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct StageTimings {
    pub read_ms: f64,
    pub integrate_ms: f64,
    pub grid_ms: f64,
    pub features_ms: f64,
    /// Projection and pixel voting, plus the colour memory's update (0 without images).
    pub appearance_ms: f64,
    pub classify_ms: f64,
    pub filter_ms: f64,
    /// Scan in to filtered grid out: integrate + grid + features + appearance +
    /// classify + filter.
    pub latency_ms: f64,
}

/// Everything the method produced for one frame.
#[derive(Clone, Debug)]
pub struct FrameResult {
    pub index: usize,
    pub stamp_ns: u64,
    pub layout: GridLayout,
    /// The sensor's position in the world.
    pub sensor_in_world: [f64; 3],
    /// The integrated points inside the grid, by cell.
    pub cells: CellPoints,
    /// Points of this frame's scan that the reader dropped (non-finite coordinates).
    pub dropped_points: usize,
    pub features: FeatureGrid,
    /// The classifier's labels before filtering (None without a model).
    pub predicted: Option<Vec<CellClass>>,
    /// The labels after the outlier filter (None without a model).
    pub filtered: Option<Vec<CellClass>>,
    /// Ground truth, when every scan of the window has labels.
    pub ground_truth: Option<Vec<CellClass>>,
    pub timings: StageTimings,
}

impl FrameResult {
    /// Cells with features and ground truth: (cell, traversable).
    pub fn labelled_cells(&self) -> impl Iterator<Item = (usize, bool)> + '_ {
        let truth = self.ground_truth.as_deref().unwrap_or(&[]);
        truth.iter().enumerate().filter_map(|(cell, &t)| {
            (self.features.predictable[cell] && t != CellClass::Unknown)
                .then_some((cell, t == CellClass::Traversable))
        })
    }
}

/// What one frame shows before any cross-frame state is used.
pub struct Observation {
    result: FrameResult,
    votes: FrameVotes,
}

fn elapsed_ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}

/// The stages, built once from a validated configuration, and the state carried
/// from frame to frame: the scan window and the colour memory.
pub struct Pipeline {
    config: Config,
    window: VecDeque<WorldScan>,
    colours: ColourMemory,
    features: FeatureExtractor,
    appearance: Option<AppearanceVoter>,
    filter: OutlierFilter,
    ground_truth: GroundTruth,
}

impl Pipeline {
    pub fn new(config: &Config) -> Result<Self> {
        config.validate()?;
        Ok(Self {
            config: config.clone(),
            window: VecDeque::new(),
            colours: ColourMemory::default(),
            features: FeatureExtractor {
                config: config.features.clone(),
                min_points: config.grid.min_points,
            },
            appearance: config.appearance.enabled.then(|| AppearanceVoter {
                config: config.appearance.clone(),
                min_points: config.grid.min_points,
            }),
            filter: OutlierFilter {
                config: config.filter.clone(),
            },
            ground_truth: GroundTruth {
                config: config.ground_truth.clone(),
            },
        })
    }

    /// Stage 1 alone: moves a scan into the world and into the window of the last n.
    /// Returns the time it took, ms.
    pub fn integrate(&mut self, frame: Frame) -> f64 {
        let started = Instant::now();
        let index = frame.index;
        let n = self.config.integration.scans;
        // A frame from the past (a new pass over the sequence) starts afresh.
        if self.window.back().is_some_and(|last| last.index >= index) {
            self.window.clear();
            self.colours = ColourMemory::default();
        }
        self.window.push_back(scan_to_world(frame));
        while self.window.front().is_some_and(|s| s.index + n <= index) {
            self.window.pop_front();
        }
        elapsed_ms(started)
    }

    /// Runs the method on one frame; `model` None skips classification and filter.
    pub fn process_frame(&mut self, mut frame: Frame, model: Option<&SvmModel>) -> FrameResult {
        let camera = frame.camera.take();
        let world_from_velodyne = frame.world_from_velodyne;
        let dropped_points = frame.dropped_points;

        // 1. Integration: this scan into the world, joined with the previous n - 1.
        let integrate_ms = self.integrate(frame);
        let window: Vec<&WorldScan> = self.window.iter().collect();

        // 2. Grid, 3. geometric features, and this frame's pixel votes.
        let observation = self.observe(&window, &world_from_velodyne, camera.as_ref());

        // 3b. Appearance: the votes join the colour memory, which gives the features.
        let started = Instant::now();
        let appearance =
            remember_colours(&mut self.colours, self.appearance.as_ref(), &observation);
        let remember_ms = elapsed_ms(started);

        // 4. Classification, 5. outlier filter.
        let mut result = self.decide(observation, appearance, model);
        result.dropped_points = dropped_points;
        result.timings.integrate_ms = integrate_ms;
        result.timings.appearance_ms += remember_ms;
        result.timings.latency_ms += integrate_ms + remember_ms;
        result
    }

    /// Stages 2, 3 and the voting of 3b on an integrated window whose last scan is the
    /// current frame; needs no state.
    pub fn observe(
        &self,
        window: &[&WorldScan],
        world_from_velodyne: &Isometry3<f64>,
        camera: Option<&CameraImage>,
    ) -> Observation {
        let current = window[window.len() - 1];
        let mut timings = StageTimings::default();

        // 2. Grid: the in-grid points, sorted by cell, around the sensor.
        let started = Instant::now();
        let layout = GridLayout::centred_on(
            [current.origin_in_world[0], current.origin_in_world[1]],
            self.config.grid.cell_size_m,
            self.config.grid.cells_per_side(),
        );
        let cells = grid_points(window, layout);
        timings.grid_ms = elapsed_ms(started);

        // 3. Geometric features of every cell with enough points.
        let started = Instant::now();
        let features = self.features.compute(&cells, ground_normal(window));
        timings.features_ms = elapsed_ms(started);

        // 3b. Appearance, first half: the image's pixels vote for the cells they show.
        let started = Instant::now();
        let votes = match (&self.appearance, camera) {
            (Some(voter), Some(camera)) => voter.vote(&cells, world_from_velodyne, camera),
            _ => FrameVotes::default(),
        };
        timings.appearance_ms = elapsed_ms(started);

        // Ground truth from the same cloud, outside the latency.
        let ground_truth = self.ground_truth.label(&cells);
        Observation {
            result: FrameResult {
                index: current.index,
                stamp_ns: current.stamp_ns,
                layout,
                sensor_in_world: current.origin_in_world,
                cells,
                dropped_points: 0,
                features,
                predicted: None,
                filtered: None,
                ground_truth,
                timings,
            },
            votes,
        }
    }

    /// Stages 4 and 5 on an observation with its appearance features.
    pub fn decide(
        &self,
        observation: Observation,
        appearance: Option<(Vec<f32>, Vec<bool>)>,
        model: Option<&SvmModel>,
    ) -> FrameResult {
        let mut result = observation.result;
        if let Some((values, seen)) = appearance {
            result.features.set_appearance(values, seen);
        }
        let timings = &mut result.timings;
        if let Some(model) = model {
            let started = Instant::now();
            let labels = model.classify(&result.features);
            timings.classify_ms = elapsed_ms(started);
            let started = Instant::now();
            result.filtered = Some(self.filter.apply(&labels, result.layout.cells_per_side));
            timings.filter_ms = elapsed_ms(started);
            result.predicted = Some(labels);
        }
        timings.latency_ms = timings.grid_ms
            + timings.features_ms
            + timings.appearance_ms
            + timings.classify_ms
            + timings.filter_ms;
        result
    }
}

/// Adds an observation's votes to the colour memory and returns the appearance
/// features of its grid (None without appearance, or while no image has been seen).
fn remember_colours(
    colours: &mut ColourMemory,
    voter: Option<&AppearanceVoter>,
    observation: &Observation,
) -> Option<(Vec<f32>, Vec<bool>)> {
    let voter = voter?;
    colours.add(&observation.votes);
    let layout = &observation.result.layout;
    // A cell more than a grid side away is not coming back soon.
    colours.forget_outside(layout, layout.cells_per_side as i64);
    if colours.is_empty() {
        return None;
    }
    Some(colours.features(layout, voter.histogram_len()))
}

/// Runs consecutive `frames` (ascending indices) with rayon: every scan is moved to
/// the world once, each frame from `first_scored` on is observed on its own window in
/// parallel, the colour memory is updated in frame order, and the frames are decided
/// in parallel. Gives the same results as [`Pipeline::process_frame`] frame by frame.
pub fn process_in_parallel(
    pipeline: &Pipeline,
    mut frames: Vec<Frame>,
    first_scored: usize,
    model: Option<&SvmModel>,
) -> Vec<FrameResult> {
    let n = pipeline.config.integration.scans;
    let cameras: Vec<(Isometry3<f64>, Option<CameraImage>, usize)> = frames
        .iter_mut()
        .map(|f| (f.world_from_velodyne, f.camera.take(), f.dropped_points))
        .collect();
    let scans: Vec<WorldScan> = frames.into_par_iter().map(scan_to_world).collect();
    let observations: Vec<Observation> = (0..scans.len())
        .into_par_iter()
        .filter(|&i| scans[i].index >= first_scored)
        .map(|i| {
            // Indices ascend, so the window is the suffix of scans[..=i] within n frames.
            let current = scans[i].index;
            let start = scans[..=i]
                .iter()
                .rposition(|s| s.index + n <= current)
                .map_or(0, |p| p + 1);
            let window: Vec<&WorldScan> = scans[start..=i].iter().collect();
            let (pose, camera, dropped_points) = &cameras[i];
            let mut observation = pipeline.observe(&window, pose, camera.as_ref());
            observation.result.dropped_points = *dropped_points;
            observation
        })
        .collect();
    let mut colours = ColourMemory::default();
    let appearance: Vec<_> = observations
        .iter()
        .map(|o| remember_colours(&mut colours, pipeline.appearance.as_ref(), o))
        .collect();
    observations
        .into_par_iter()
        .zip(appearance)
        .map(|(observation, appearance)| pipeline.decide(observation, appearance, model))
        .collect()
}

/// Runs the pipeline over the frames of `source` in `frames`, reading the n - 1
/// frames before the first one to fill the window, and hands each result to `on_frame`.
/// `on_frame` may return its own error type (the binary's, say).
pub fn run_sequence<E: From<Error>>(
    source: &Source,
    frames: &Range<usize>,
    config: &Config,
    model: Option<&SvmModel>,
    mut on_frame: impl FnMut(FrameResult) -> Result<(), E>,
) -> Result<(), E> {
    let mut pipeline = Pipeline::new(config)?;
    let warm_up_start = frames.start.saturating_sub(config.integration.scans - 1);
    // Reading time: from the end of one frame's work to the arrival of the next frame.
    let mut read_started = Instant::now();
    source.for_each_frame(&(warm_up_start..frames.end), |frame| {
        let read_ms = elapsed_ms(read_started);
        if frame.index < frames.start {
            pipeline.integrate(frame);
        } else {
            let mut result = pipeline.process_frame(frame, model);
            result.timings.read_ms = read_ms;
            on_frame(result)?;
        }
        read_started = Instant::now();
        Ok(())
    })
}
