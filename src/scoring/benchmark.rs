//! `travmap bench`: per-stage latency of the pipeline one frame at a time on one
//! thread, and whole-run throughput on one thread and on all cores. Frames are read
//! into memory first, so the stage figures measure the method, not the disk.
//! Everything is repeated and reported as medians: shared machines are noisy.

use std::ops::Range;

use serde::Serialize;

use crate::config::Config;
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::io::Source;
use crate::method::classifier::SvmModel;
use crate::method::pipeline::{Pipeline, StageTimings};
use crate::method::registration::Odometry;
use crate::scoring::evaluation::{Spread, TimingReport};
use crate::stopwatch::{Stopwatch, timed};

#[derive(Clone, Debug, Serialize)]
pub struct Throughput {
    pub threads: usize,
    /// Median over the repeats of frames processed per second of wall time.
    pub frames_per_second: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct BenchmarkReport {
    /// Frames timed per repeat: those with a full integration window.
    pub timed_frames: usize,
    pub repeats: usize,
    pub mean_points_per_scan: f64,
    /// Median over timed frames of cells with at least `grid.min_points` points.
    pub predictable_cells: f64,
    /// Median over timed frames of integrated points inside the grid.
    pub points_in_grid: f64,
    pub support_vectors: usize,
    /// One frame at a time, one thread.
    pub stages_ms: TimingReport,
    /// Scan registration (`--poses registration`), one thread, every frame after the
    /// first (which only starts the map); not in `stages_ms`, which times the
    /// input's own poses.
    pub registration_ms: Spread,
    /// Scans (over all repeats) that did not register, after which the map started
    /// again.
    pub registration_lost: usize,
    pub one_thread: Throughput,
    pub all_cores: Throughput,
    /// all_cores / one_thread frames per second.
    pub speedup: f64,
}

fn pool(threads: usize) -> Result<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| Error::ThreadPool {
            threads,
            message: e.to_string(),
        })
}

/// Benchmarks `frames` of `sequence`, each measurement repeated `repeats` times.
pub fn benchmark(
    source: &Source,
    frames: &Range<usize>,
    config: &Config,
    model: &SvmModel,
    repeats: usize,
) -> Result<BenchmarkReport> {
    let indices = source.frames_in(frames);
    let first_timed = Pipeline::new(config)?
        .window()
        .first_full(indices.first().copied().unwrap_or(0));
    let mut read_ms = Vec::new();
    let mut loaded: Vec<Frame> = Vec::new();
    let mut reading = Stopwatch::start();
    for frame in source.read(frames) {
        loaded.push(frame?);
        read_ms.push(reading.lap_ms());
    }
    let timed_frames = indices.iter().filter(|&&i| i >= first_timed).count();
    if timed_frames == 0 {
        return Err(Error::TooFewFrames {
            selected: indices.len(),
            needed: config.integration.scans,
        });
    }

    // Stage latency: one frame at a time on one thread.
    let (mut timings, mut cells, mut points) = (Vec::new(), Vec::new(), Vec::new());
    pool(1)?.install(|| {
        for _ in 0..repeats.max(1) {
            let mut sequential = Pipeline::new(config)?;
            for (frame, &read) in loaded.iter().zip(&read_ms) {
                let result = sequential.process_frame(frame.clone(), Some(model));
                if result.index >= first_timed {
                    timings.push(StageTimings {
                        read_ms: read,
                        ..result.timings
                    });
                    cells.push(result.features.predictable.iter().filter(|p| **p).count() as f64);
                    points.push(result.cells.points_in_grid.len() as f64);
                }
            }
        }
        Ok::<(), Error>(())
    })?;

    // Registration: each repeat registers the selection from scratch. A scan that
    // does not register (a synthetic drive of repeated scans jumps back) starts the
    // map again from it, as `--keep-going` would; it is counted, not timed.
    let mut registration_ms = Vec::new();
    let mut registration_lost = 0;
    pool(1)?.install(|| {
        for _ in 0..repeats.max(1) {
            let mut odometry = Odometry::new(config.registration.clone());
            for (i, frame) in loaded.iter().enumerate() {
                let (pose, ms) = timed(|| odometry.register(&frame.points_in_velodyne));
                if pose.is_err() {
                    registration_lost += 1;
                    odometry = Odometry::new(config.registration.clone());
                    let _ = odometry.register(&frame.points_in_velodyne);
                } else if i > 0 {
                    registration_ms.push(ms);
                }
            }
        }
    });

    // Throughput: the whole selection with rayon across frames.
    let throughput = |threads: usize| -> Result<Throughput> {
        let mut rates = Vec::new();
        pool(threads)?.install(|| {
            for _ in 0..repeats.max(1) {
                let (warm_up, timed): (Vec<Frame>, Vec<Frame>) =
                    loaded.iter().cloned().partition(|f| f.index < first_timed);
                let watch = Stopwatch::start();
                let mut pipeline = Pipeline::new(config)?;
                for frame in warm_up {
                    pipeline.warm_up(frame);
                }
                let results = pipeline.process_frames(timed, Some(model));
                rates.push(results.len() as f64 / (watch.elapsed_ms() * 1e-3));
            }
            Ok::<(), Error>(())
        })?;
        Ok(Throughput {
            threads,
            frames_per_second: Spread::of(&rates).median,
        })
    };
    let one_thread = throughput(1)?;
    let all_cores = throughput(std::thread::available_parallelism().map_or(1, |n| n.get()))?;
    Ok(BenchmarkReport {
        timed_frames,
        repeats: repeats.max(1),
        mean_points_per_scan: loaded
            .iter()
            .map(|f| f.points_in_velodyne.len() as f64)
            .sum::<f64>()
            / loaded.len() as f64,
        predictable_cells: Spread::of(&cells).median,
        points_in_grid: Spread::of(&points).median,
        support_vectors: model.support_vector_count(),
        stages_ms: TimingReport::of(&timings),
        registration_ms: Spread::of(&registration_ms),
        registration_lost,
        speedup: all_cores.frames_per_second / one_thread.frames_per_second,
        one_thread,
        all_cores,
    })
}
