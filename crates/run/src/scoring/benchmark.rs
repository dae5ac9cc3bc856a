//! `travmap bench`: per-stage latency of the pipeline one frame at a time on one
//! thread, and whole-run throughput on one thread and on all cores. Frames are read
//! into memory first, so the stage figures measure the method, not the disk.
//! Everything is repeated and reported as medians: shared machines are noisy.

use serde::Serialize;

use crate::scoring::evaluation::{Spread, TimingReport};
use crate::{DriveRun, ReadFrame};
use travmap_core::config::Config;
use travmap_core::error::{Error, Result};
use travmap_core::frame::Frame;
use travmap_core::posing::DriveFrame;
use travmap_core::stopwatch::{Stopwatch, timed};
use travmap_method::classifier::SvmModel;
use travmap_method::grid::GridLayout;
use travmap_method::registration::Odometry;

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
    /// One frame at a time, one thread, posed as the source is (`register` holds
    /// the registration when its poses are estimated).
    pub timings: TimingReport,
    /// The floor (`floor_ms`): moving the window's points into the frame's grid
    /// and counting them per cell, nothing else; one thread, per frame.
    pub floor_ms: Spread,
    /// Median latency over the floor's median.
    pub latency_over_floor: f64,
    /// Scan registration (`--poses registration`), one thread, every frame after the
    /// first (which only starts the map), whatever the source's posing: what
    /// estimating the poses would cost.
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

/// Benchmarks the selected frames, each measurement repeated `repeats` times. The
/// frames are read once; every run then goes through the selection as every command
/// does ([`DriveRun::run_loaded`]), posed as its source says.
pub fn benchmark(
    selection: &DriveRun,
    config: &Config,
    model: &SvmModel,
    repeats: usize,
) -> Result<BenchmarkReport> {
    let indices = selection.source.frames_in(&selection.frames);
    let first_timed = selection
        .pipeline(config)?
        .window()
        .first_full(indices.first().copied().unwrap_or(0));
    let loaded = selection.load(config)?;
    let timed_frames = indices.iter().filter(|&&i| i >= first_timed).count();
    if timed_frames == 0 {
        return Err(Error::TooFewFrames {
            selected: indices.len(),
            needed: config.integration.scans,
        });
    }
    let first = selection.frames.start;

    // Stage latency: one frame at a time on one thread.
    let (mut timings, mut cells, mut points) = (Vec::new(), Vec::new(), Vec::new());
    pool(1)?.install(|| {
        for _ in 0..repeats.max(1) {
            selection.run_loaded(&loaded, first, config, Some(model), 1, |result| {
                if result.index >= first_timed {
                    timings.push(result.timings);
                    cells.push(result.features.predictable.iter().filter(|p| **p).count() as f64);
                    points.push(result.cells.window_points() as f64);
                }
            })?;
        }
        Ok::<(), Error>(())
    })?;

    let floor = pool(1)?.install(|| floor_ms(&loaded, first_timed, config, repeats.max(1)));

    // Registration: each repeat registers the selection from scratch. A scan that
    // does not register (a synthetic drive of repeated scans jumps back) starts the
    // map again from it, as `--keep-going` would; it is counted, not timed.
    let mut registration_ms = Vec::new();
    let mut registration_lost = 0;
    pool(1)?.install(|| {
        for _ in 0..repeats.max(1) {
            let mut odometry = Odometry::new(config.registration.clone());
            for (i, (frame, _)) in loaded.iter().enumerate() {
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

    // Throughput: the timed frames in batches, with rayon across frames.
    let batch_size = |threads: usize| (2 * threads).clamp(1, 16);
    let throughput = |threads: usize| -> Result<Throughput> {
        let mut rates = Vec::new();
        pool(threads)?.install(|| {
            for _ in 0..repeats.max(1) {
                let watch = Stopwatch::start();
                let mut frames = 0;
                selection.run_loaded(
                    &loaded,
                    first_timed,
                    config,
                    Some(model),
                    batch_size(threads),
                    |_| frames += 1,
                )?;
                rates.push(frames as f64 / (watch.elapsed_ms() * 1e-3));
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
            .map(|(f, _)| f.points_in_velodyne.len() as f64)
            .sum::<f64>()
            / loaded.len() as f64,
        predictable_cells: Spread::of(&cells).median,
        points_in_grid: Spread::of(&points).median,
        support_vectors: model.support_vector_count(),
        latency_over_floor: TimingReport::of(&timings).latency_ms.median / floor.median,
        floor_ms: floor,
        timings: TimingReport::of(&timings),
        registration_ms: Spread::of(&registration_ms),
        registration_lost,
        speedup: all_cores.frames_per_second / one_thread.frames_per_second,
        one_thread,
        all_cores,
    })
}

/// The least any grid method must do per frame on this machine, timed over the
/// same frames as the stages: every point of the frame's n scans moved by its
/// scan's pose into the frame's grid (x and y: the cell needs no more) and counted
/// in its cell. No copy, no sort, no feature; the rotation in f32 with the
/// translation to the grid's corner taken in f64 first, so it stays exact far
/// from the origin. A frame's latency over this is what the method costs beyond
/// touching its points once.
fn floor_ms(loaded: &[ReadFrame], first_timed: usize, config: &Config, repeats: usize) -> Spread {
    let scans = config.integration.scans;
    let cells_per_side = config.grid.cells_per_side();
    let mut counts = vec![0u32; cells_per_side * cells_per_side];
    let mut times = Vec::new();
    let mut checksum = 0u64;
    for _ in 0..repeats {
        for (frame, _) in loaded.iter().filter(|(f, _)| f.index >= first_timed) {
            let window = loaded
                .iter()
                .map(|(f, _)| f)
                .filter(|f| f.index <= frame.index && f.index + scans > frame.index);
            let sensor = frame.world_from_velodyne.translation.vector;
            // On the world's lattice: the floor counts, it does not keep, the points.
            let layout = GridLayout::centred_on(
                [sensor.x, sensor.y],
                DriveFrame::default(),
                config.grid.cell_size_m,
                cells_per_side,
            );
            let watch = Stopwatch::start();
            counts.fill(0);
            for scan in window {
                count_into_cells(scan, &layout, &mut counts);
            }
            times.push(watch.elapsed_ms());
            // Keeps the counting from being optimised away.
            checksum = checksum.wrapping_add(counts.iter().map(|&c| c as u64).sum::<u64>());
        }
    }
    std::hint::black_box(checksum);
    Spread::of(&times)
}

/// Counts the points of `frame` in the cells of `layout`. (Computing a block's
/// cells first, so that it vectorises, was no faster: the pass is bound by
/// reading the points.)
fn count_into_cells(frame: &Frame, layout: &GridLayout, counts: &mut [u32]) {
    let m = frame.world_from_velodyne.to_homogeneous();
    let [min_x, min_y] = layout.min_corner_in_world();
    let r = |row: usize, col: usize| m[(row, col)] as f32;
    let (tx, ty) = ((m[(0, 3)] - min_x) as f32, (m[(1, 3)] - min_y) as f32);
    let per_cell = 1.0 / layout.cell_size_m as f32;
    let side = layout.cells_per_side as f32;
    for p in &frame.points_in_velodyne {
        let col = (r(0, 0) * p[0] + r(0, 1) * p[1] + r(0, 2) * p[2] + tx) * per_cell;
        let row = (r(1, 0) * p[0] + r(1, 1) * p[1] + r(1, 2) * p[2] + ty) * per_cell;
        if col >= 0.0 && row >= 0.0 && col < side && row < side {
            counts[row as usize * layout.cells_per_side + col as usize] += 1;
        }
    }
}
