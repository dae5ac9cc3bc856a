//! Where reading meets the method: a [`Selection`] is a [`Source`] and the frames
//! of it to use, and [`Selection::run`] feeds them through a [`Pipeline`].

use std::ops::Range;

use nalgebra::Isometry3;

use crate::config::{Config, IntegrationConfig, RegistrationConfig};
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::io::{Posing, Source};
use crate::method::classifier::SvmModel;
use crate::method::pipeline::{FrameResult, Pipeline};
use crate::method::registration::{Odometry, RegistrationError};
use crate::stopwatch::{Stopwatch, timed};

/// A frame read and posed, waiting for the pipeline.
struct Arrival {
    frame: Frame,
    read_ms: f64,
    register_ms: f64,
    scan_sha256: Option<String>,
}

/// A scan's pose as registration estimated it.
#[derive(Clone, Debug)]
pub struct EstimatedPose {
    pub index: usize,
    pub stamp_ns: u64,
    pub world_from_velodyne: Isometry3<f64>,
    pub register_ms: f64,
}

/// A drive and the frames of it to use.
pub struct Selection {
    pub source: Source,
    pub frames: Range<usize>,
    /// Give each result its scan's SHA-256 (`FrameResult::scan_sha256`): costs a
    /// few milliseconds a frame, so only where a frame's identity matters.
    pub fingerprint_scans: bool,
}

impl Selection {
    pub fn new(source: Source, frames: Range<usize>) -> Self {
        Self {
            source,
            frames,
            fingerprint_scans: false,
        }
    }

    /// Runs the pipeline over the selected frames, reading the n - 1 frames before
    /// the first one to fill the window, and hands each result to `on_frame`, which
    /// may return its own error type (the binary's, say).
    pub fn run<E: From<Error>>(
        &self,
        config: &Config,
        model: Option<&SvmModel>,
        mut on_frame: impl FnMut(FrameResult) -> Result<(), E>,
    ) -> Result<(), E> {
        let posing = self.source.posing();
        let alone;
        let config = match posing {
            // Each scan alone: nothing to integrate it with.
            Posing::Alone => {
                alone = Config {
                    integration: IntegrationConfig {
                        scans: 1,
                        ..config.integration.clone()
                    },
                    ..config.clone()
                };
                &alone
            }
            _ => config,
        };
        let mut pipeline = Pipeline::new(config)?;
        if posing == Posing::Registration {
            pipeline.estimate_poses(&config.registration);
        }
        let first = self.frames.start;
        let frames = pipeline.window().warm_up_start(first)..self.frames.end;
        // Three stages on their own threads, joined by bounded queues: frames read
        // ahead; the method on batches of them (each batch in parallel on rayon);
        // and here `on_frame` (encoding, writing) while the next batch runs.
        let batch_size = (2 * rayon::current_num_threads()).clamp(1, 16);
        std::thread::scope(|scope| {
            let (read_frames, arrivals) = std::sync::mpsc::sync_channel(batch_size);
            scope.spawn(move || {
                let mut reading = Stopwatch::start();
                for frame in self.source.read(&frames) {
                    let read_ms = reading.lap_ms();
                    if read_frames.send(frame.map(|f| (f, read_ms))).is_err() {
                        return;
                    }
                }
            });
            let (results, processed) = std::sync::mpsc::sync_channel(batch_size);
            scope.spawn(move || {
                let mut emit = |result| results.send(Ok(result)).is_ok();
                let method = self.run_method(&mut pipeline, arrivals, model, batch_size, &mut emit);
                if let Err(error) = method {
                    let _ = results.send(Err(error));
                }
            });
            // A failing `on_frame` drops `processed`, which stops the stages above.
            for result in processed {
                on_frame(result?)?;
            }
            Ok(())
        })
    }

    /// The method stage of [`Selection::run`]: registers the frames that arrive,
    /// warms the window up, and processes the selected ones in batches of
    /// consecutive frames, handing each result to `emit` until it returns false.
    fn run_method(
        &self,
        pipeline: &mut Pipeline,
        arrivals: std::sync::mpsc::Receiver<Result<(Frame, f64)>>,
        model: Option<&SvmModel>,
        batch_size: usize,
        emit: &mut dyn FnMut(FrameResult) -> bool,
    ) -> Result<()> {
        let posing = self.source.posing();
        let first = self.frames.start;
        // Block for one frame, then take what else has arrived, up to a batch.
        while let Ok(arrival) = arrivals.recv() {
            let mut arrived = vec![arrival];
            while arrived.len() < batch_size {
                match arrivals.try_recv() {
                    Ok(arrival) => arrived.push(arrival),
                    Err(_) => break,
                }
            }
            let mut batch: Vec<Arrival> = Vec::with_capacity(arrived.len());
            for arrival in arrived {
                let (mut frame, read_ms) = arrival?;
                if posing == Posing::Alone {
                    frame.world_from_velodyne = Isometry3::identity();
                }
                let register_ms = match pipeline.register(&mut frame) {
                    Ok(ms) => ms,
                    Err(problem) => {
                        self.unregistered(frame.index, problem)?;
                        continue;
                    }
                };
                if frame.index < first {
                    pipeline.warm_up(frame);
                    continue;
                }
                // A batch is consecutive frames: a skipped one ends it.
                if batch
                    .last()
                    .is_some_and(|b| b.frame.index + 1 != frame.index)
                    && !Self::process(pipeline, std::mem::take(&mut batch), model, emit)
                {
                    return Ok(());
                }
                batch.push(Arrival {
                    scan_sha256: self.fingerprint_scans.then(|| frame.content_sha256()),
                    frame,
                    read_ms,
                    register_ms,
                });
            }
            if !Self::process(pipeline, batch, model, emit) {
                return Ok(());
            }
        }
        Ok(())
    }

    /// Runs the method on a batch of consecutive frames and hands on the results;
    /// false once `emit` wants no more.
    fn process(
        pipeline: &mut Pipeline,
        batch: Vec<Arrival>,
        model: Option<&SvmModel>,
        emit: &mut dyn FnMut(FrameResult) -> bool,
    ) -> bool {
        let (frames, extras): (Vec<Frame>, Vec<_>) = batch
            .into_iter()
            .map(|a| (a.frame, (a.read_ms, a.register_ms, a.scan_sha256)))
            .unzip();
        for (mut result, (read_ms, register_ms, scan_sha256)) in pipeline
            .process_frames(frames, model)
            .into_iter()
            .zip(extras)
        {
            result.timings.read_ms = read_ms;
            result.timings.register_ms = register_ms;
            result.timings.latency_ms += register_ms;
            result.scan_sha256 = scan_sha256;
            if !emit(result) {
                return false;
            }
        }
        true
    }

    /// The selected frames' poses by scan registration alone, whatever the input
    /// records (`travmap odometry`): the first scan that registers is the world.
    /// A scan that cannot be registered ends the run, or is skipped (`--keep-going`).
    pub fn estimate_trajectory(
        &self,
        config: &RegistrationConfig,
        mut on_frame: impl FnMut(),
    ) -> Result<Vec<EstimatedPose>> {
        let mut odometry = Odometry::new(config.clone());
        let mut trajectory = Vec::new();
        for frame in self.source.read(&self.frames) {
            let frame = frame?;
            let (pose, register_ms) = timed(|| odometry.register(&frame.points_in_velodyne));
            match pose {
                Ok(world_from_velodyne) => trajectory.push(EstimatedPose {
                    index: frame.index,
                    stamp_ns: frame.stamp_ns,
                    world_from_velodyne,
                    register_ms,
                }),
                Err(problem) => self.unregistered(frame.index, problem)?,
            }
            on_frame();
        }
        Ok(trajectory)
    }

    /// A frame registration refused: the end of the run, or a skipped frame
    /// (`--keep-going`).
    fn unregistered(&self, frame: usize, problem: RegistrationError) -> Result<()> {
        let error = Error::Registration {
            path: self.source.path().to_path_buf(),
            frame,
            problem,
        };
        self.source.skip_log().handle(frame, error)
    }

    /// The input and the frames of it, as a person reads them.
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
