//! The method in order. [`Pipeline::process_frames`] calls every stage, one comment
//! per step; the [`IntegrationWindow`] and the colour memory are the state carried
//! from frame to frame, with the registration's map when poses are estimated. Stage
//! 0, posing ([`Pipeline::pose`]), runs on each frame in order before it is
//! processed: registration is sequential by nature and may refuse a frame.
//!
//! Frames are processed in batches of consecutive frames (one frame is a batch of
//! one): the grid, the geometric features and the image's votes of a frame need no
//! state, so the frames of a batch run them in parallel; the colour memory then takes
//! the votes in frame order, and classification and filter run in parallel again.
//! The results are the same whatever the batch size.

use std::sync::Mutex;

use nalgebra::Isometry3;
use rayon::prelude::*;
use serde::Serialize;

use crate::appearance::{AppearanceVoter, CellAppearance, ColourMemory, FrameVotes};
use crate::classifier::{ForeignRemission, SvmModel};
use crate::features::{FeatureExtractor, FeatureGrid};
use crate::filter::OutlierFilter;
use crate::footprint::{Footprint, PathKind, Trajectory};
use crate::grid::{CellClass, GridBuffers, GridLayout, KeptCellPoints, grid_points};
use crate::ground_truth::{GroundTruth, UnknownLabels};
use crate::integration::{
    DriveScan, IntegrationWindow, ground_normal, rank_remission, scale_remission_to_reference,
    scan_to_drive,
};
use crate::registration::{Odometry, RegistrationError};
use crate::self_labels::SelfLabeller;
use crate::vehicle_points::VehicleBox;
use travmap_core::config::{ClassifierConfig, Config, RemissionScaling};
use travmap_core::error::Result;
use travmap_core::frame::{CameraImage, Frame, RemissionScale};
use travmap_core::posing::{DriveFrame, Posing};
use travmap_core::stopwatch::timed;

/// Wall time of each stage for one frame, milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct StageTimings {
    pub read_ms: f64,
    /// Scan registration, when the poses are estimated (0 otherwise).
    pub register_ms: f64,
    pub integrate_ms: f64,
    pub grid_ms: f64,
    pub features_ms: f64,
    /// Projection and pixel voting, plus the colour memory's update (0 without images).
    pub appearance_ms: f64,
    pub classify_ms: f64,
    pub filter_ms: f64,
    /// Scan in to filtered grid out: register + integrate + grid + features +
    /// appearance + classify + filter.
    pub latency_ms: f64,
}

/// Everything the method produced for one frame.
#[derive(Clone, Debug)]
pub struct FrameResult {
    pub index: usize,
    pub stamp_ns: u64,
    pub layout: GridLayout,
    /// The sensor's pose in the world (estimated when registration posed the scan).
    pub world_from_velodyne: Isometry3<f64>,
    /// The sensor's position in the world.
    pub sensor_in_world: [f64; 3],
    /// What the outputs read of the integrated points inside the grid.
    pub cells: KeptCellPoints,
    /// Every point of the frame's own scan, in the drive frame (`layout.drive`;
    /// shared with the integration window, not copied).
    pub scan_in_drive: std::sync::Arc<Vec<[f32; 3]>>,
    /// Points of this frame's scan that the reader dropped (non-finite coordinates).
    pub dropped_points: usize,
    /// Points of this frame's scan whose label id the label set does not define.
    pub unknown_labels: UnknownLabels,
    /// The scale of the scan's remission, as the reader found it.
    pub remission: RemissionScale,
    /// Remission features were configured but the window had no usable remission,
    /// so they were left out and the model's fallback classified the frame.
    pub without_remission: bool,
    /// Points of this frame's scan whose remission was NaN or infinite (the scan then
    /// has no usable remission).
    pub non_finite_remission: usize,
    /// The frame's remission lay far outside the model's training range: the
    /// model's fallback classified it without remission.
    pub foreign_remission: Option<ForeignRemission>,
    pub features: FeatureGrid,
    /// The classifier's labels before filtering (None without a model).
    pub predicted: Option<Vec<CellClass>>,
    /// The labels after the outlier filter (None without a model).
    pub filtered: Option<Vec<CellClass>>,
    /// The classifier's margin per cell (decision value minus threshold; NaN where
    /// unpredictable; None without a model).
    pub margins: Option<Vec<f32>>,
    /// P(traversable) per cell, the margin through the model's calibration (NaN where
    /// unpredictable; None without a model).
    pub probabilities: Option<Vec<f32>>,
    /// Ground truth, when every scan of the window has labels.
    pub ground_truth: Option<Vec<CellClass>>,
    /// The cells the vehicle drove over and where its path came from, when the
    /// pipeline follows a trajectory ([`Pipeline::follow`]).
    pub footprint: Option<(Vec<bool>, PathKind)>,
    /// The drive's own labels of its cells (stage 6b), when it follows a trajectory:
    /// traversable, not, or unknown.
    pub self_labels: Option<Vec<Option<bool>>>,
    /// SHA-256 of the frame's scan, when the caller asked for it.
    pub scan_sha256: Option<String>,
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

/// A frame posed by the pipeline's posing stage ([`Pipeline::pose`]), ready for the
/// others.
pub struct Posed {
    frame: Frame,
    drive_from_velodyne: Isometry3<f64>,
    drive: DriveFrame,
    register_ms: f64,
}

impl Posed {
    pub fn index(&self) -> usize {
        self.frame.index
    }

    pub fn world_from_velodyne(&self) -> Isometry3<f64> {
        self.drive.to_world(&self.drive_from_velodyne)
    }

    /// The registration's time, ms (0 when the pose was not estimated).
    pub fn register_ms(&self) -> f64 {
        self.register_ms
    }
}

/// What a frame brings besides its scan, set aside while the scan is integrated.
struct FrameExtras {
    drive_from_velodyne: Isometry3<f64>,
    register_ms: f64,
    remission: RemissionScale,
    camera: Option<CameraImage>,
    dropped_points: usize,
    unknown_labels: UnknownLabels,
    integrate_ms: f64,
}

/// The stages, built once from a validated configuration and the source's posing,
/// and the state carried from frame to frame: the scan window, the colour memory and
/// the registration's map.
pub struct Pipeline {
    posing: Posing,
    /// The frame the stages keep the drive in.
    drive: DriveFrame,
    window: IntegrationWindow,
    colours: ColourMemory,
    features: FeatureExtractor,
    appearance: Option<AppearanceVoter>,
    filter: OutlierFilter,
    ground_truth: GroundTruth,
    cell_size_m: f64,
    cells_per_side: usize,
    classifier: ClassifierConfig,
    /// Feature groups configured.
    feature_groups: usize,
    /// Scan registration, when the poses are estimated or refined.
    registration: Option<Odometry>,
    /// The vehicle's body in the sensor frame, whose points are left out.
    vehicle_box: Option<VehicleBox>,
    /// Footprint and self-labels (stages 6a, 6b), when following a trajectory.
    adaptation: Option<Adaptation>,
    /// The grid stage's buffers not in use: each frame in flight takes a set and
    /// gives it back.
    grid_buffers: Mutex<Vec<GridBuffers>>,
}

/// What the adaptation stages need: the drive's trajectory and the vehicle.
struct Adaptation {
    trajectory: std::sync::Arc<Trajectory>,
    footprint: Footprint,
    labeller: SelfLabeller,
}

impl Pipeline {
    /// The pipeline for scans posed as `posing` says: each scan alone has nothing to
    /// be integrated with (a window of one), estimated poses need the registration.
    /// Recorded poses are moved into `drive` (estimated ones start at its origin).
    pub fn new(config: &Config, posing: Posing, drive: DriveFrame) -> Result<Self> {
        config.validate()?;
        let scans = match posing {
            Posing::Alone => 1,
            Posing::Recorded | Posing::Registration => config.integration.scans,
        };
        Ok(Self {
            posing,
            drive,
            window: IntegrationWindow::new(scans),
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
            ground_truth: GroundTruth::new(config.ground_truth.clone()),
            cell_size_m: config.grid.cell_size_m,
            cells_per_side: config.grid.cells_per_side(),
            classifier: config.classifier.clone(),
            feature_groups: config.features.groups.len(),
            registration: (posing == Posing::Registration)
                .then(|| Odometry::new(config.registration.clone())),
            vehicle_box: None,
            adaptation: None,
            grid_buffers: Mutex::default(),
        })
    }

    /// Adds stages 6a and 6b: each frame's footprint along `trajectory` (the whole
    /// drive's poses, in the drive frame) and its self-labels, by the prior's margins
    /// when a model is given.
    pub fn follow(&mut self, trajectory: std::sync::Arc<Trajectory>, config: &Config) {
        self.adaptation = Some(Adaptation {
            trajectory,
            footprint: Footprint {
                vehicle: config.vehicle.clone(),
                horizon_m: config.adapt.horizon_m,
            },
            labeller: SelfLabeller {
                vehicle: config.vehicle.clone(),
                adapt: config.adapt.clone(),
            },
        });
    }

    /// Recorded poses are refined from now on: each scan registered to the window's
    /// map starting from its recorded pose (`pose_check` said they disagree).
    pub fn refine_recorded_poses(&mut self, config: &Config) {
        if self.posing == Posing::Recorded {
            self.registration = Some(Odometry::new(config.registration.clone()));
        }
    }

    /// From now on the points inside `vehicle_box` (the vehicle's body, in the
    /// sensor frame) are left out of every scan (stage 0a).
    pub fn leave_out_vehicle(&mut self, vehicle_box: VehicleBox) {
        self.vehicle_box = Some(vehicle_box);
    }

    /// Stage 0, posing: the vehicle's own points left out (0a); then the frame's pose
    /// in the drive frame as the source's posing says: its own (refined by
    /// registration when asked), the registration's estimate (frames in order,
    /// warm-up frames included; a scan that does not register is refused), or none
    /// (each scan in its own frame).
    pub fn pose(&mut self, mut frame: Frame) -> Result<Posed, RegistrationError> {
        if let Some(vehicle_box) = &self.vehicle_box {
            vehicle_box.remove_from(&mut frame.points_in_velodyne, frame.labels.as_mut());
        }
        let mut register_ms = 0.0;
        let recorded = self.drive.from_world(&frame.world_from_velodyne);
        let drive_from_velodyne = match (self.posing, &mut self.registration) {
            (Posing::Alone, _) => Isometry3::identity(),
            (Posing::Registration, Some(odometry)) => {
                let pose;
                (pose, register_ms) = timed(|| odometry.register(&frame.points_in_velodyne));
                pose?
            }
            (Posing::Recorded, Some(odometry)) => {
                let refined;
                (refined, register_ms) =
                    timed(|| odometry.register_from(&frame.points_in_velodyne, recorded));
                refined?
            }
            _ => recorded,
        };
        Ok(Posed {
            frame,
            drive_from_velodyne,
            drive: self.drive,
            register_ms,
        })
    }

    /// The scan window, to ask which frames fill it.
    pub fn window(&self) -> &IntegrationWindow {
        &self.window
    }

    /// Stage 1 alone, for a frame before the first one wanted: its scan joins the
    /// window so that the next frames integrate it. Returns the time it took, ms.
    pub fn warm_up(&mut self, posed: Posed) -> f64 {
        self.start_afresh_before(posed.frame.index);
        let (scan, integrate_ms) =
            timed(|| self.integrate(posed.frame, &posed.drive_from_velodyne));
        self.window.extend([scan]);
        self.window.forget_old();
        integrate_ms
    }

    /// Runs the method on one frame, posing it first; `model` None skips
    /// classification and filter.
    pub fn process_frame(
        &mut self,
        frame: Frame,
        model: Option<&SvmModel>,
    ) -> Result<FrameResult, RegistrationError> {
        let posed = self.pose(frame)?;
        let mut results = self.process_frames(vec![posed], model);
        Ok(results.pop().expect("one result per frame"))
    }

    /// Runs the method on consecutive frames (ascending indices), in parallel where
    /// the method allows; the results are those of [`Self::process_frame`] frame by frame.
    pub fn process_frames(
        &mut self,
        posed: Vec<Posed>,
        model: Option<&SvmModel>,
    ) -> Vec<FrameResult> {
        let Some(first) = posed.first() else {
            return Vec::new();
        };
        self.start_afresh_before(first.index());
        let (mut frames, poses): (Vec<Frame>, Vec<(Isometry3<f64>, f64)>) = posed
            .into_iter()
            .map(|p| (p.frame, (p.drive_from_velodyne, p.register_ms)))
            .unzip();
        let extras: Vec<FrameExtras> = frames
            .iter_mut()
            .zip(poses)
            .map(|(f, (drive_from_velodyne, register_ms))| FrameExtras {
                drive_from_velodyne,
                register_ms,
                remission: f.remission,
                camera: f.camera.take(),
                dropped_points: f.dropped_points,
                unknown_labels: f
                    .labels
                    .as_deref()
                    .map(|labels| self.ground_truth.unknown_labels(labels))
                    .unwrap_or_default(),
                integrate_ms: 0.0,
            })
            .collect();

        // 1. Integration: each scan into the drive frame, joined with the previous n - 1.
        let held = self.window.scans().len();
        let posed: Vec<(Frame, Isometry3<f64>)> = frames
            .into_iter()
            .zip(extras.iter().map(|e| e.drive_from_velodyne))
            .collect();
        let (scans, integrate_ms): (Vec<DriveScan>, Vec<f64>) =
            map_frames(posed, |(frame, pose)| {
                timed(|| self.integrate(frame, &pose))
            })
            .into_iter()
            .unzip();
        self.window.extend(scans);
        let extras: Vec<FrameExtras> = extras
            .into_iter()
            .zip(integrate_ms)
            .map(|(extras, integrate_ms)| FrameExtras {
                integrate_ms,
                ..extras
            })
            .collect();

        // 2. Grid, 3. geometric features, and the first half of 3b: each image's pixels
        // vote for the cells they show.
        let observations = map_frames(extras.into_iter().enumerate().collect(), |(i, extras)| {
            self.observe(self.window.window_of(held + i), extras)
        });

        // 3b. Appearance: the votes join the colour memory in frame order, which gives
        // each frame's appearance features.
        let observations: Vec<Observation> = observations
            .into_iter()
            .map(|mut observation| {
                let (appearance, remember_ms) = timed(|| self.remember_colours(&observation));
                observation.appearance = appearance;
                observation.result.timings.appearance_ms += remember_ms;
                observation
            })
            .collect();

        // 4. Classification, 5. outlier filter.
        let results = map_frames(observations, |observation| self.decide(observation, model));
        self.window.forget_old();
        results
    }

    /// Stage 1 for one scan: into the drive frame, its remission scaled as configured.
    fn integrate(&self, frame: Frame, drive_from_velodyne: &Isometry3<f64>) -> DriveScan {
        let scaling = self.features.config.remission_scale;
        let mut scan = scan_to_drive(frame, drive_from_velodyne, scaling);
        match scaling {
            RemissionScaling::AsRead => {}
            RemissionScaling::ScanP95 => scale_remission_to_reference(&mut scan),
            RemissionScaling::ScanRank => rank_remission(&mut scan),
        }
        scan
    }

    /// A frame from the past (a new pass over the sequence) starts afresh.
    fn start_afresh_before(&mut self, index: usize) {
        if self.window.restarts_at(index) {
            self.window.clear();
            self.colours = ColourMemory::default();
        }
    }

    /// Stages 2, 3 and the voting of 3b on the window of a frame (its scan last).
    fn observe(&self, window: &[DriveScan], extras: FrameExtras) -> Observation {
        let current = &window[window.len() - 1];
        let mut timings = StageTimings {
            register_ms: extras.register_ms,
            integrate_ms: extras.integrate_ms,
            ..StageTimings::default()
        };
        let sensor = current.sensor_in_drive;
        let layout = GridLayout::centred_on(
            [sensor[0], sensor[1]],
            self.drive,
            self.cell_size_m,
            self.cells_per_side,
        );
        let spare = self
            .grid_buffers
            .lock()
            .ok()
            .and_then(|mut spare| spare.pop());
        let mut buffers = spare.unwrap_or_default();
        let cells;
        (cells, timings.grid_ms) = timed(|| grid_points(window, layout, &mut buffers));
        let features;
        (features, timings.features_ms) =
            timed(|| self.features.compute(&cells, ground_normal(window), sensor));
        let votes;
        (votes, timings.appearance_ms) = timed(|| match (&self.appearance, &extras.camera) {
            (Some(voter), Some(camera)) => voter.vote(&cells, &extras.drive_from_velodyne, camera),
            _ => FrameVotes::default(),
        });
        // Ground truth from the same cloud, outside the latency.
        let ground_truth = self.ground_truth.label(&cells);
        // 6a. Footprint: the cells the vehicle drove over.
        let footprint = self.adaptation.as_ref().map(|a| {
            a.footprint.cells(
                &layout,
                &a.trajectory,
                current.index,
                &extras.drive_from_velodyne,
            )
        });
        let kept = cells.kept_for_outputs(&mut buffers);
        if let Ok(mut spare) = self.grid_buffers.lock() {
            spare.push(buffers);
        }
        Observation {
            result: FrameResult {
                index: current.index,
                stamp_ns: current.stamp_ns,
                layout,
                world_from_velodyne: self.drive.to_world(&extras.drive_from_velodyne),
                sensor_in_world: self.drive.point_in_world(sensor),
                cells: kept,
                scan_in_drive: current.points_in_drive.clone(),
                dropped_points: extras.dropped_points,
                unknown_labels: extras.unknown_labels,
                remission: extras.remission,
                without_remission: features.groups.len() < self.feature_groups,
                non_finite_remission: current.non_finite_remission,
                foreign_remission: None,
                features,
                predicted: None,
                filtered: None,
                margins: None,
                probabilities: None,
                ground_truth,
                footprint,
                self_labels: None,
                scan_sha256: None,
                timings,
            },
            votes,
            appearance: None,
        }
    }

    /// Adds an observation's votes to the colour memory and returns the appearance
    /// features of its grid (None without appearance, or while no image has been seen).
    fn remember_colours(&mut self, observation: &Observation) -> Option<CellAppearance> {
        let voter = self.appearance.as_ref()?;
        self.colours.add(&observation.votes);
        let layout = &observation.result.layout;
        // A cell more than a grid side away is not coming back soon.
        self.colours
            .forget_outside(layout, layout.cells_per_side as i64);
        if self.colours.is_empty() {
            return None;
        }
        Some(self.colours.features(layout, voter.histogram_len()))
    }

    /// Stages 4 and 5 on an observation with its appearance features.
    fn decide(&self, observation: Observation, model: Option<&SvmModel>) -> FrameResult {
        let mut result = observation.result;
        if let Some(appearance) = observation.appearance {
            result.features.appearance = appearance;
        }
        let timings = &mut result.timings;
        if let Some(model) = model {
            result.foreign_remission = model.foreign_remission(&result.features);
            let margins;
            (margins, timings.classify_ms) =
                timed(|| model.margins(&result.features, &self.classifier));
            let labels: Vec<CellClass> = margins.iter().map(|m| CellClass::of_margin(*m)).collect();
            let filtered;
            (filtered, timings.filter_ms) =
                timed(|| self.filter.apply(&labels, result.layout.cells_per_side));
            result.filtered = Some(filtered);
            result.predicted = Some(labels);
            result.probabilities = Some(margins.iter().map(|&m| model.probability(m)).collect());
            result.margins = Some(margins);
        }
        // 6b. Self-labels: footprint, confident rejections and obstacles.
        if let (Some(adaptation), Some((footprint, _))) = (&self.adaptation, &result.footprint) {
            let margins = result.margins.as_deref();
            result.self_labels = Some(adaptation.labeller.label(
                &result.features,
                footprint,
                margins,
            ));
        }
        let timings = &mut result.timings;
        timings.latency_ms = timings.register_ms
            + timings.integrate_ms
            + timings.grid_ms
            + timings.features_ms
            + timings.appearance_ms
            + timings.classify_ms
            + timings.filter_ms;
        result
    }
}

/// What one frame shows, and its appearance features once the colour memory has
/// taken its votes.
struct Observation {
    result: FrameResult,
    votes: FrameVotes,
    appearance: Option<CellAppearance>,
}

/// `f` over the frames of a batch, in parallel; a batch of one stays on this thread.
fn map_frames<T: Send, U: Send>(items: Vec<T>, f: impl Fn(T) -> U + Sync + Send) -> Vec<U> {
    if items.len() == 1 {
        items.into_iter().map(f).collect()
    } else {
        items.into_par_iter().map(f).collect()
    }
}
