//! Where reading meets the method: a [`DriveRun`] is a [`Source`] and the frames
//! of it to run; [`scoring`] says how good and how fast the result was.
//! [`DriveRun::run`] feeds them through a [`Pipeline`] built for the source's
//! posing, and [`DriveRun::run_mapped`] also fuses every result into the drive map,
//! the one place that map is fed; [`opening`] opens a drive as every front end does. Every command goes through here, the
//! benchmark included ([`DriveRun::load`], [`DriveRun::run_loaded`]).

pub mod labelling;
pub mod opening;
pub mod report;
pub mod scoring;

use std::collections::{BTreeMap, BTreeSet};
use std::ops::Range;
use std::sync::Arc;

use nalgebra::{Isometry3, Vector3};

use rayon::prelude::*;
use travmap_core::config::{Config, OwnPoints, RefinePoses};
use travmap_core::error::{Error, Result};
use travmap_core::frame::Frame;
use travmap_core::posing::{DriveFrame, Posing};
use travmap_core::stopwatch::Stopwatch;
use travmap_io::Source;
use travmap_method::classifier::SvmModel;
use travmap_method::footprint::Trajectory;
use travmap_method::fusion::DriveMap;
use travmap_method::pipeline::{FrameResult, Pipeline, Posed};
use travmap_method::pose_check::{ScanGround, ground_disagreement_m};
use travmap_method::registration::RegistrationError;
use travmap_method::vehicle_points::{SURVEY_SPACING_M, VehicleBox, find_vehicle_box};

/// A frame read, and how long reading it took, ms.
pub type ReadFrame = (Frame, f64);

/// How the method stage takes frames: those before `first` only fill the window,
/// the others go in batches of at most `size`.
struct Batches {
    first: usize,
    size: usize,
}

/// A frame posed, waiting for the rest of the pipeline.
struct PosedFrame {
    posed: Posed,
    read_ms: f64,
    scan_sha256: Option<String>,
}

/// What a command makes of each frame as it is read ([`DriveRun::run_mapped_beside`]).
pub type OnRead<'a, B> = &'a (dyn Fn(&Frame) -> Result<B> + Sync);

/// What [`DriveRun::run_mapped_beside`] hands on, in the order it comes.
pub enum RunEvent<'a, B> {
    /// What `beside` made of a frame as it was read.
    Read(B),
    /// A frame's result, with the drive map so far (it included).
    Result(Box<FrameResult>, &'a DriveMap),
}

/// What the reading and method stages send on to the command's.
enum StageOutput<B> {
    Read(B),
    Result(Box<FrameResult>),
}

/// Frames at least [`SURVEY_SPACING_M`] apart along the recorded poses, from the
/// first on, at most [`SURVEY_BODY_SCANS`] of them.
fn spaced_frames(frames: &[usize], poses: &BTreeMap<usize, Isometry3<f64>>) -> Vec<usize> {
    let mut taken: Vec<(usize, Vector3<f64>)> = Vec::new();
    for &frame in frames {
        let Some(pose) = poses.get(&frame) else {
            continue;
        };
        let at = pose.translation.vector;
        if taken
            .iter()
            .all(|(_, t)| (t - at).norm() >= SURVEY_SPACING_M)
        {
            taken.push((frame, at));
        }
        if taken.len() == SURVEY_BODY_SCANS {
            break;
        }
    }
    taken.into_iter().map(|(frame, _)| frame).collect()
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
pub struct DriveRun {
    pub source: Source,
    pub frames: Range<usize>,
    /// Which results carry their scan's SHA-256 (`FrameResult::scan_sha256`): it
    /// costs a few milliseconds a frame, so only where a frame's identity matters.
    pub fingerprint_scans: Fingerprints,
    /// The drive's trajectory, once followed ([`DriveRun::follow_trajectory`]).
    trajectory: Option<Arc<Trajectory>>,
    /// What [`DriveRun::survey`] found.
    survey: Survey,
}

/// Which scans' results carry their SHA-256, the scan's identity by content.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fingerprints {
    None,
    /// Labelled scans only (what a model learns from and is scored on).
    Labelled,
    All,
}

/// What a look at a few of a drive's scans found before the method runs
/// ([`DriveRun::survey`]).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct Survey {
    /// The median ground height difference of consecutive scans under the recorded
    /// poses, metres, when measured.
    pub pose_disagreement_m: Option<f64>,
    /// The recorded poses are refined by registration.
    pub refine_poses: bool,
    /// The vehicle's body found in the sensor frame.
    pub vehicle_box: Option<VehicleBox>,
}

/// A survey looks no further into the drive than this many frames.
const SURVEY_REACH_FRAMES: usize = 600;
/// Consecutive pairs of scans whose ground is compared.
const SURVEY_PAIRS: usize = 4;
/// Scans taken for the vehicle's body, at most.
const SURVEY_BODY_SCANS: usize = 8;

impl DriveRun {
    pub fn new(source: Source, frames: Range<usize>) -> Self {
        Self {
            source,
            frames,
            fingerprint_scans: Fingerprints::None,
            trajectory: None,
            survey: Survey::default(),
        }
    }

    /// Looks at a few of the drive's scans before the method runs, when their poses
    /// are recorded: whether consecutive scans lay the same ground under them (else
    /// the poses are refined by registration, `integration.refine_poses`), and where
    /// the vehicle's own points are (`vehicle.own_points`). `on_notice` hears what
    /// was found; unreadable scans are left to the run to report.
    pub fn survey(&mut self, config: &Config, on_notice: &dyn Fn(&str)) -> Result<&Survey> {
        self.survey = Survey::default();
        let recorded = self.source.posing() == Posing::Recorded;
        let refine = config.integration.refine_poses;
        let find_body = config.vehicle.own_points == OwnPoints::Auto
            && config.vehicle.own_points_box_m.is_none();
        if !recorded {
            return Ok(&self.survey);
        }
        // Told whether to refine, the survey measures nothing for it.
        self.survey.refine_poses = refine == RefinePoses::Always;
        let measure_poses = refine == RefinePoses::Auto;
        if !measure_poses && !find_body {
            return Ok(&self.survey);
        }
        let reach = self.frames.start..self.frames.end.min(self.frames.start + SURVEY_REACH_FRAMES);
        let frames = self.source.frames_in(&reach);
        // In the drive frame, as the method sees them: near the origin, whatever the
        // world's coordinates.
        let drive = self.source.drive_frame();
        let poses: BTreeMap<usize, Isometry3<f64>> = (self.source.recorded_poses()?.iter())
            .map(|(index, pose)| (*index, drive.from_world(pose)))
            .collect();
        let body_frames = spaced_frames(&frames, &poses);
        let pairs: Vec<(usize, usize)> = (body_frames.iter())
            .filter_map(|f| {
                let at = frames.binary_search(f).ok()?;
                Some((*f, *frames.get(at + 1)?))
            })
            .take(if measure_poses { SURVEY_PAIRS } else { 0 })
            .collect();
        let wanted: BTreeSet<usize> = (pairs.iter())
            .flat_map(|&(a, b)| [a, b])
            .chain(body_frames.iter().copied().filter(|_| find_body))
            .collect();
        // The survey looks at points alone: images decoded and labels read for it would
        // only cost (a camera image a frame decodes slower than the rest of a frame).
        let (images, labels) = self.source.reads();
        self.source.set_read_images(false);
        self.source.set_read_labels(false);
        let scans = self.read_some(&wanted);
        self.source.set_read_images(images);
        self.source.set_read_labels(labels);
        let scan = |f: &usize| {
            scans
                .get(f)
                .map(|s| (&poses[f], s.points_in_velodyne.as_slice()))
        };
        // Each scan's ground once, the scans at once.
        let paired: BTreeSet<usize> = pairs.iter().flat_map(|&(a, b)| [a, b]).collect();
        let grounds: BTreeMap<usize, ScanGround> = (paired.par_iter())
            .filter_map(|f| scan(f).map(|(pose, points)| (*f, ScanGround::of(pose, points))))
            .collect();
        let mut disagreements: Vec<f64> = (pairs.iter())
            .filter_map(|(a, b)| ground_disagreement_m(grounds.get(a)?, grounds.get(b)?))
            .collect();
        disagreements.sort_by(f64::total_cmp);
        let path = self.source.path().display().to_string();
        self.survey.pose_disagreement_m = disagreements.get(disagreements.len() / 2).copied();
        if let Some(apart) = self.survey.pose_disagreement_m
            && apart > config.integration.pose_disagreement_m
        {
            self.survey.refine_poses = true;
            on_notice(&format!(
                "{path}: consecutive scans lay the ground a median {apart:.2} m apart under the recorded poses (a 2-D localisation's?): each scan is registered to the window from its recorded pose (integration.refine_poses; for every log of this localisation, unsurveyed: --set integration.refine_poses=always)"
            ));
        }
        if find_body {
            let body: Vec<_> = (body_frames.iter())
                .filter_map(|f| scan(f).map(|(pose, points)| (*pose, points)))
                .collect();
            self.survey.vehicle_box = find_vehicle_box(&body);
        }
        if let Some(found) = &self.survey.vehicle_box {
            let (min, max) = (found.min_m, found.max_m);
            // The box is the vehicle's, not the log's: given, every log of the vehicle
            // leaves out the same points, and none is surveyed for it.
            let corners: Vec<String> = (min.iter().chain(&max))
                .map(|v| format!("{}", (v * 100.0).round() / 100.0))
                .collect();
            on_notice(&format!(
                "{path}: the vehicle's own points found in the sensor frame (x {:.1} to {:.1}, y {:.1} to {:.1}, z {:.1} to {:.1} m): left out of every scan (vehicle.own_points; the same box for every log of this vehicle, unsurveyed: --set 'vehicle.own_points_box_m=[{}]')",
                min[0],
                max[0],
                min[1],
                max[1],
                min[2],
                max[2],
                corners.join(", ")
            ));
        }
        Ok(&self.survey)
    }

    /// What the survey found (nothing before [`Self::survey`]).
    pub fn surveyed(&self) -> &Survey {
        &self.survey
    }

    /// The frames `wanted` that read, by number.
    fn read_some(&self, wanted: &BTreeSet<usize>) -> BTreeMap<usize, Frame> {
        (self.source.read_only(wanted))
            .filter_map(|frame| frame.ok().filter(|f| wanted.contains(&f.index)))
            .map(|frame| (frame.index, frame))
            .collect()
    }

    /// The pipeline for this source's scans, as its posing asks (following the
    /// trajectory once it is followed).
    pub fn pipeline(&self, config: &Config) -> Result<Pipeline> {
        // Where each frame is already a whole window (a site cloud's tile), the
        // window is one scan.
        let mut windowed;
        let config = match self.source.window_scans() {
            Some(scans) if scans < config.integration.scans => {
                windowed = config.clone();
                windowed.integration.scans = scans;
                &windowed
            }
            _ => config,
        };
        let mut pipeline = Pipeline::new(config, self.source.posing(), self.source.drive_frame())?;
        if self.survey.refine_poses {
            pipeline.refine_recorded_poses(config);
        }
        let given = config
            .vehicle
            .own_points_box_m
            .map(VehicleBox::from_corners);
        let off = config.vehicle.own_points == OwnPoints::Off;
        if let Some(vehicle_box) = given.or(self.survey.vehicle_box.filter(|_| !off)) {
            pipeline.leave_out_vehicle(vehicle_box);
        }
        if let Some(trajectory) = &self.trajectory {
            pipeline.follow(trajectory.clone(), config);
        }
        Ok(pipeline)
    }

    /// From now on every result carries its footprint and self-labels (stages 6a,
    /// 6b) along the drive's trajectory (in the drive frame): every pose the input
    /// records, also past the selected frames; the registration's estimates from the
    /// first frame read on when poses are estimated; none when each scan is alone
    /// (each footprint then runs straight along its scan's x axis).
    pub fn follow_trajectory(&mut self, config: &Config) -> Result<Arc<Trajectory>> {
        let drive = self.source.drive_frame();
        let poses = match self.source.posing() {
            Posing::Recorded => (self.source.recorded_poses()?.into_iter())
                .map(|(index, pose)| (index, drive.from_world(&pose)))
                .collect(),
            Posing::Registration => {
                let first = self
                    .pipeline(config)?
                    .window()
                    .warm_up_start(self.frames.start);
                let poses = self.registered_poses(config, &(first..usize::MAX), || {})?;
                poses
                    .iter()
                    .map(|p| (p.index, p.world_from_velodyne))
                    .collect()
            }
            Posing::Alone => Vec::new(),
        };
        let trajectory = Arc::new(Trajectory::new(&poses));
        self.trajectory = Some(trajectory.clone());
        Ok(trajectory)
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
        self.run_fusing(
            config,
            model,
            false,
            None::<OnRead<()>>,
            |handed| match handed {
                RunEvent::Read(()) => Ok(()),
                RunEvent::Result(result, _) => on_frame(*result),
            },
        )?;
        Ok(())
    }

    /// [`Self::run`], with every result fused into the drive map before `on_frame`
    /// sees it with the map so far; returns the map of the whole selection.
    pub fn run_mapped<E: From<Error>>(
        &self,
        config: &Config,
        model: Option<&SvmModel>,
        mut on_frame: impl FnMut(FrameResult, &DriveMap) -> Result<(), E>,
    ) -> Result<DriveMap, E> {
        self.run_fusing(
            config,
            model,
            true,
            None::<OnRead<()>>,
            |handed| match handed {
                RunEvent::Read(()) => Ok(()),
                RunEvent::Result(result, map) => on_frame(*result, map),
            },
        )
    }

    /// [`Self::run_mapped`], with `beside` made of each selected frame as it is read,
    /// on the reading thread (annotate passes a KITTI frame's messages through
    /// without reading it again). `on_handed` takes those and the results as they
    /// come: each in frame order, the two interleaved as the stages run.
    pub fn run_mapped_beside<E: From<Error>, B: Send>(
        &self,
        config: &Config,
        model: Option<&SvmModel>,
        beside: OnRead<B>,
        on_handed: impl FnMut(RunEvent<B>) -> Result<(), E>,
    ) -> Result<DriveMap, E> {
        self.run_fusing(config, model, true, Some(beside), on_handed)
    }

    /// [`Self::run_mapped_beside`], fusing the results into the drive map when
    /// `fuse` says so.
    fn run_fusing<E: From<Error>, B: Send>(
        &self,
        config: &Config,
        model: Option<&SvmModel>,
        fuse: bool,
        beside: Option<OnRead<B>>,
        mut on_handed: impl FnMut(RunEvent<B>) -> Result<(), E>,
    ) -> Result<DriveMap, E> {
        let mut drive_map = DriveMap::new(config.grid.cell_size_m, self.source.drive_frame());
        let mut pipeline = self.pipeline(config)?;
        let frames = pipeline.window().warm_up_start(self.frames.start)..self.frames.end;
        // Three stages on their own threads, joined by bounded queues: frames read
        // ahead; the method on batches of them (each batch in parallel on rayon);
        // and here `on_frame` (encoding, writing) while the next batch runs.
        let batch_size = (2 * rayon::current_num_threads()).clamp(1, 16);
        std::thread::scope(|scope| {
            let (read_frames, arrivals) = std::sync::mpsc::sync_channel(batch_size);
            let (results, processed) = std::sync::mpsc::sync_channel(batch_size);
            let made = results.clone();
            scope.spawn(move || {
                let mut reading = Stopwatch::start();
                for frame in self.source.read(&frames) {
                    let read_ms = reading.lap_ms();
                    if let (Some(beside), Ok(frame)) = (beside, &frame)
                        && frame.index >= self.frames.start
                    {
                        let beside = beside(frame).map(StageOutput::Read);
                        let failed = beside.is_err();
                        if made.send(beside).is_err() || failed {
                            return;
                        }
                    }
                    if read_frames.send(frame.map(|f| (f, read_ms))).is_err() {
                        return;
                    }
                }
            });
            scope.spawn(move || {
                let mut next = |block: bool| match block {
                    true => arrivals.recv().ok(),
                    false => arrivals.try_recv().ok(),
                };
                let mut emit = |result| {
                    results
                        .send(Ok(StageOutput::Result(Box::new(result))))
                        .is_ok()
                };
                let batches = Batches {
                    first: self.frames.start,
                    size: batch_size,
                };
                let method = self.run_method(&mut pipeline, batches, &mut next, model, &mut emit);
                if let Err(error) = method {
                    let _ = results.send(Err(error));
                }
            });
            // A failing `on_handed` drops `processed`, which stops the stages above.
            for step in processed {
                match step? {
                    StageOutput::Read(made) => on_handed(RunEvent::Read(made))?,
                    StageOutput::Result(result) => {
                        if fuse {
                            drive_map.add_result(&result);
                        }
                        on_handed(RunEvent::Result(result, &drive_map))?;
                    }
                }
            }
            Ok(drive_map)
        })
    }

    /// Every frame [`Self::run`] reads (those that fill the window first), into
    /// memory, each with the time reading it took.
    pub fn load(&self, config: &Config) -> Result<Vec<ReadFrame>> {
        let warm_up_start = self
            .pipeline(config)?
            .window()
            .warm_up_start(self.frames.start);
        let mut reading = Stopwatch::start();
        self.source
            .read(&(warm_up_start..self.frames.end))
            .map(|frame| frame.map(|f| (f, reading.lap_ms())))
            .collect()
    }

    /// The method over frames from [`Self::load`], on this thread, as [`Self::run`]
    /// runs it, in batches of at most `batch_size` consecutive frames: frames
    /// before `first` only fill the window.
    pub fn run_loaded(
        &self,
        loaded: &[ReadFrame],
        first: usize,
        config: &Config,
        model: Option<&SvmModel>,
        batch_size: usize,
        mut on_frame: impl FnMut(FrameResult),
    ) -> Result<()> {
        let mut pipeline = self.pipeline(config)?;
        let mut frames = loaded.iter().cloned().map(Ok);
        let mut next = |_block: bool| frames.next();
        let mut emit = |result| {
            on_frame(result);
            true
        };
        let batches = Batches {
            first,
            size: batch_size,
        };
        self.run_method(&mut pipeline, batches, &mut next, model, &mut emit)
    }

    /// The method stage of [`Self::run`]: poses the frames that `next` hands on
    /// (blocking for one when asked, else only what has arrived), warms the window
    /// up with those before `first`, and processes the others in batches of at most
    /// `size` consecutive frames, handing each result to `emit` until it returns
    /// false.
    fn run_method(
        &self,
        pipeline: &mut Pipeline,
        Batches { first, size }: Batches,
        next: &mut dyn FnMut(bool) -> Option<Result<ReadFrame>>,
        model: Option<&SvmModel>,
        emit: &mut dyn FnMut(FrameResult) -> bool,
    ) -> Result<()> {
        // Block for one frame, then take what else has arrived, up to a batch.
        while let Some(arrival) = next(true) {
            let mut arrived = vec![arrival];
            while arrived.len() < size {
                match next(false) {
                    Some(arrival) => arrived.push(arrival),
                    None => break,
                }
            }
            let mut batch: Vec<PosedFrame> = Vec::with_capacity(arrived.len());
            for arrival in arrived {
                let (frame, read_ms) = arrival?;
                let index = frame.index;
                let scan_sha256 = match self.fingerprint_scans {
                    Fingerprints::All => Some(frame.content_sha256()),
                    Fingerprints::Labelled if frame.labels.is_some() => {
                        Some(frame.content_sha256())
                    }
                    _ => None,
                };
                let posed = match pipeline.pose(frame) {
                    Ok(posed) => posed,
                    // A frame read only to fill the window (not selected: a packet
                    // log's partial first scan, say) is left out of it.
                    Err(_) if index < first => continue,
                    Err(problem) => {
                        self.unregistered(index, problem)?;
                        continue;
                    }
                };
                if index < first {
                    pipeline.warm_up(posed);
                    continue;
                }
                // A batch is consecutive frames: a skipped one ends it.
                if batch.last().is_some_and(|b| b.posed.index() + 1 != index)
                    && !Self::process(pipeline, std::mem::take(&mut batch), model, emit)
                {
                    return Ok(());
                }
                batch.push(PosedFrame {
                    posed,
                    read_ms,
                    scan_sha256,
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
        batch: Vec<PosedFrame>,
        model: Option<&SvmModel>,
        emit: &mut dyn FnMut(FrameResult) -> bool,
    ) -> bool {
        let (frames, extras): (Vec<Posed>, Vec<_>) = batch
            .into_iter()
            .map(|a| (a.posed, (a.read_ms, a.scan_sha256)))
            .unzip();
        for (mut result, (read_ms, scan_sha256)) in pipeline
            .process_frames(frames, model)
            .into_iter()
            .zip(extras)
        {
            result.timings.read_ms = read_ms;
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
        config: &Config,
        on_frame: impl FnMut(),
    ) -> Result<Vec<EstimatedPose>> {
        self.registered_poses(config, &self.frames, on_frame)
    }

    /// The poses of the frames in `frames` by registration alone.
    fn registered_poses(
        &self,
        config: &Config,
        frames: &Range<usize>,
        mut on_frame: impl FnMut(),
    ) -> Result<Vec<EstimatedPose>> {
        // The first scan that registers is the drive frame's origin, and the world's.
        let mut pipeline = Pipeline::new(config, Posing::Registration, DriveFrame::default())?;
        let mut trajectory = Vec::new();
        for frame in self.source.read(frames) {
            let frame = frame?;
            let (index, stamp_ns) = (frame.index, frame.stamp_ns);
            match pipeline.pose(frame) {
                Ok(posed) => trajectory.push(EstimatedPose {
                    index,
                    stamp_ns,
                    world_from_velodyne: posed.world_from_velodyne(),
                    register_ms: posed.register_ms(),
                }),
                Err(problem) => self.unregistered(index, problem)?,
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

    /// Whether the frames run are posed scans, more than one: a drive whose
    /// footprint adaptation can learn from (a single scan, or scans each alone, show
    /// none).
    pub fn moves(&self) -> bool {
        self.source.posing() != travmap_core::posing::Posing::Alone
            && self.source.frames_in(&self.frames).len() > 1
    }

    /// Whether the drive carries labels to score against, by its first and last
    /// frame read alone: a command that needs them says so before any other work.
    pub fn has_labels(&self) -> Result<bool> {
        let frames = self.source.frames_in(&self.frames);
        let ends: std::collections::BTreeSet<usize> = frames
            .first()
            .into_iter()
            .chain(frames.last())
            .copied()
            .collect();
        for frame in self.source.read_only(&ends) {
            if frame?.labels.is_some() {
                return Ok(true);
            }
        }
        Ok(false)
    }

    /// The input and the frames of it, as a person reads them.
    pub fn describe(&self) -> String {
        let frames = self.source.frames_in(&self.frames);
        match (frames.first(), frames.last()) {
            (Some(first), Some(last)) => {
                format!("{} frames {first}..={last}", self.source.path().display(),)
            }
            _ => format!("{} (no frames in range)", self.source.path().display()),
        }
    }
}
