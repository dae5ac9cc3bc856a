//! A drive to read, whatever holds it, told apart by content ([`format::detect`],
//! the one place that decides), and posed once by [`decide`]. What holds it
//! ([`Recording`]) stays inside: callers ask the [`Source`].

use std::collections::BTreeSet;
use std::ops::Range;
use std::path::{Path, PathBuf};

use nalgebra::Isometry3;

use super::format::{self, InputFormat};
use super::kitti::KittiSequence;
use super::log_drive::{LogDrive, LogOptions};
use super::skips::{Skip, SkipLog};
use crate::cloud_files::scan_folder::ScanFolder;
use crate::cloud_files::site_cloud::SiteCloud;
use crate::containers::log::Log;
use crate::recorded::{Recorded, RecordedKitti, RecordedLog};
use travmap_core::config::PoseSource;
use travmap_core::error::{Error, Result};
use travmap_core::frame::Frame;
use travmap_core::posing::{DriveFrame, PoseRecord, Posing, decide};

/// How to read a drive: what every kind uses, then what one kind uses.
#[derive(Clone, Debug, Default)]
pub struct SourceOptions {
    /// Where the scans' poses come from.
    pub poses: PoseSource,
    /// Skip (and record) frames whose input is unreadable instead of stopping.
    pub keep_going: bool,
    /// Recorded logs: topics, frames and sensors.
    pub log: LogOptions,
    /// Folders of scans, and sequences without `times.txt`: the rate stamps are
    /// made at (10 Hz when None; 2 Hz for nuScenes-lidarseg's keyframes).
    pub rate_hz: Option<f64>,
    /// One saved point cloud is read as a site of square tiles this wide (m), as
    /// `travmap map` reads it; None: it is refused as no drive.
    pub site_tile_m: Option<f64>,
}

/// What holds a drive.
enum Recording {
    Kitti(Box<KittiSequence>),
    Log(Box<LogDrive>),
    Scans(Box<ScanFolder>),
    /// One saved point cloud read as tiles (site maps).
    Site(Box<SiteCloud>),
}

/// What kind of drive a source is, for reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SourceKind {
    Kitti,
    /// A recorded log of point clouds.
    Log,
    /// A recorded log of LiDAR packets.
    PacketLog,
    Scans,
    Site,
}

impl SourceKind {
    /// Its name in reports (`bench --tools`).
    pub fn name(self) -> &'static str {
        match self {
            SourceKind::Kitti => "kitti",
            SourceKind::Log => "log",
            SourceKind::PacketLog => "packets",
            SourceKind::Scans => "scans",
            SourceKind::Site => "site",
        }
    }
}

/// Where a map's frame lies in a georeferenced source's coordinates: a LAS file's,
/// or a log's `utm` / `earth` frame.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Georeference {
    /// The log's frame the map is placed in; None: the source file's coordinates.
    pub frame: Option<String>,
    /// The map frame's (0, 0, 0) in those coordinates.
    pub origin_m: [f64; 3],
    /// The map frame's rotation in those coordinates (x, y, z, w; identity for a file).
    pub rotation_xyzw: [f64; 4],
    /// The source's coordinate reference system, as WKT.
    pub crs_wkt: Option<String>,
}

impl Georeference {
    /// Whether the coordinates are planar metres a world file can carry: a file's
    /// (projected CRS) or `utm`; not `earth`, which is ECEF.
    pub fn is_planar(&self) -> bool {
        self.frame.as_deref().is_none_or(|frame| frame == "utm")
    }

    /// The rotation about z (radians), as a world file carries it.
    pub fn yaw_rad(&self) -> f64 {
        let [x, y, z, w] = self.rotation_xyzw;
        (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
    }
}

/// The world frame of inputs that do not name one (KITTI, folders of scans).
pub const WORLD_FRAME: &str = "map";

/// A drive to read, and how its scans are posed.
pub struct Source {
    recording: Recording,
    posing: Posing,
    /// The frame the method keeps the drive in.
    drive: DriveFrame,
    /// Frames carry their points' labels (false: read as if unlabelled).
    read_labels: bool,
    /// Frames carry their camera images (where the input has them).
    read_images: bool,
    /// The frames skipped as unreadable (`--keep-going`), whichever pass met them.
    skips: SkipLog,
}

impl Source {
    /// The drive at `path`, of the format its content says ([`format::detect`]),
    /// posed as [`decide`] says. `on_notice` hears what the reader noticed and worked
    /// around (an unindexed bag, poses estimated, ...) as soon as it is known, before
    /// anything can fail later.
    pub fn open(path: &Path, options: &SourceOptions, on_notice: &dyn Fn(&str)) -> Result<Self> {
        let mut skips = SkipLog::new(options.keep_going);
        let (recording, record) = match format::detect(path)? {
            InputFormat::ScanFolder if let Some(sequence) = velodyne_of_sequence(path, options) => {
                return Err(Error::Sequence {
                    path: path.to_path_buf(),
                    message: format!(
                        "the velodyne/ folder of the sequence {}: point at the sequence, not its velodyne/ folder (or pass --poses registration to treat it as a folder of scans)",
                        sequence.display()
                    ),
                });
            }
            InputFormat::ScanFolder => {
                let folder = ScanFolder::open(path, options.rate_hz)?;
                on_notice(folder.notice());
                let record = PoseRecord::Missing("a folder of scans records no poses".into());
                (Recording::Scans(Box::new(folder)), record)
            }
            InputFormat::Kitti => {
                let sequence = KittiSequence::open(path, options.rate_hz, on_notice)?;
                (Recording::Kitti(Box::new(sequence)), PoseRecord::Reaches)
            }
            InputFormat::SiteCloud(kind) => {
                let Some(tile_m) = options.site_tile_m else {
                    return Err(format::refuse(path, InputFormat::SiteCloud(kind)));
                };
                let site = SiteCloud::open(path, kind, tile_m)?;
                on_notice(&site.notice());
                // Each tile is posed by its virtual sensor; the reader already moved
                // the file's coordinates near zero.
                return Ok(Self {
                    recording: Recording::Site(Box::new(site)),
                    posing: Posing::Recorded,
                    drive: DriveFrame::default(),
                    read_labels: true,
                    read_images: true,
                    skips,
                });
            }
            format => {
                let log = Log::open(path, format)?;
                log.notices().iter().for_each(|notice| on_notice(notice));
                log.lost_to_cuts()
                    .into_iter()
                    .for_each(|lost| skips.record_lost(lost));
                // A log's poses depend on its transform tree: the drive decides as it opens.
                let drive = LogDrive::open(log, &options.log, options.poses)?;
                drive.notice().into_iter().for_each(on_notice);
                let posing = drive.posing();
                return Self::posed(Recording::Log(Box::new(drive)), posing, skips);
            }
        };
        let decision = decide(path, options.poses, &record)?;
        decision.notice.as_deref().into_iter().for_each(on_notice);
        Self::posed(recording, decision.posing, skips)
    }

    /// The source of `recording` posed as `posing`: the drive frame at its first
    /// recorded pose (estimated poses start at the world's origin).
    fn posed(recording: Recording, posing: Posing, skips: SkipLog) -> Result<Self> {
        let mut source = Self {
            recording,
            posing,
            drive: DriveFrame::default(),
            read_labels: true,
            read_images: true,
            skips,
        };
        if let Some((_, first)) = source.recorded_poses()?.first() {
            source.drive = DriveFrame::at(first.translation.vector.into());
        }
        Ok(source)
    }

    /// What kind of drive this is.
    pub fn kind(&self) -> SourceKind {
        match &self.recording {
            Recording::Kitti(..) => SourceKind::Kitti,
            Recording::Log(drive) if drive.packet_model().is_some() => SourceKind::PacketLog,
            Recording::Log(..) => SourceKind::Log,
            Recording::Scans(..) => SourceKind::Scans,
            Recording::Site(..) => SourceKind::Site,
        }
    }

    /// Where this drive's labels are read from, as a person reads it (said when none
    /// were found).
    pub fn where_labels_are_read(&self) -> String {
        let place = match &self.recording {
            Recording::Kitti(..) => "labels/NNNNNN.label beside velodyne/NNNNNN.bin",
            Recording::Log(..) => {
                "a `label` field of its point clouds (as `travmap convert` writes from SemanticKITTI)"
            }
            Recording::Scans(..) => {
                "a folder of scans carries no labels (a KITTI sequence's labels/ does)"
            }
            Recording::Site(..) => "a `label` field of the cloud's points",
        };
        format!("{}: {place}", self.path().display())
    }

    /// What the input recorded beside its frames (convert, annotate's
    /// passthrough), read with this source's skip log.
    pub fn recorded(&self) -> Recorded<'_> {
        let skips = &self.skips;
        match &self.recording {
            Recording::Kitti(sequence) => Recorded::Kitti(RecordedKitti { sequence, skips }),
            Recording::Log(drive) => Recorded::Log(RecordedLog { drive, skips }),
            Recording::Scans(..) | Recording::Site(..) => Recorded::FramesOnly,
        }
    }

    /// The scans a frame's window holds at most, where the source decides it: a site
    /// cloud's tile is already a whole window (its neighbours' points are its own).
    pub fn window_scans(&self) -> Option<usize> {
        matches!(self.recording, Recording::Site(..)).then_some(1)
    }

    /// When the drive is a packet log that began mid-turn: the packets of frame 0 (a
    /// part of a rotation) and of frame 1.
    pub fn partial_first_scan(&self) -> Option<(usize, usize)> {
        match &self.recording {
            Recording::Log(drive) => drive.partial_first_scan(),
            _ => None,
        }
    }

    /// Where the world frame lies on the Earth or in a file's coordinates, when the
    /// source says: a log's `utm` / `earth` frame, a site cloud's origin and CRS.
    pub fn georeference(&self) -> Option<Georeference> {
        match &self.recording {
            Recording::Site(site) => site.georeference().map(|(origin_m, crs)| Georeference {
                frame: None,
                origin_m,
                rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
                crs_wkt: crs.map(str::to_string),
            }),
            Recording::Log(drive) => drive.georeference().map(|(frame, geo_from_world)| {
                let q = geo_from_world.rotation.coords;
                Georeference {
                    frame: Some(frame.clone()),
                    origin_m: geo_from_world.translation.vector.into(),
                    rotation_xyzw: [q.x, q.y, q.z, q.w],
                    crs_wkt: None,
                }
            }),
            Recording::Kitti(..) | Recording::Scans(..) => None,
        }
    }

    /// The frame the scans are in, as written to MCAP (`header.frame_id`).
    pub fn sensor_frame(&self) -> &str {
        match &self.recording {
            Recording::Kitti(..) => "velodyne",
            Recording::Log(drive) => drive.cloud_frame(),
            Recording::Scans(..) => crate::cloud_files::scan_folder::SENSOR_FRAME,
            Recording::Site(..) => crate::cloud_files::site_cloud::SENSOR_FRAME,
        }
    }

    /// The frame the poses put the scans in: the log's world frame, else `map`.
    pub fn world_frame(&self) -> &str {
        match &self.recording {
            Recording::Log(drive) => drive.world_frame(),
            Recording::Kitti(..) | Recording::Scans(..) | Recording::Site(..) => WORLD_FRAME,
        }
    }

    /// How the scans are posed.
    pub fn posing(&self) -> Posing {
        self.posing
    }

    /// The frame the method keeps the drive in ([`DriveFrame`]): the world moved to
    /// the drive's first recorded pose, so that a drive far from the world's origin
    /// maps as one at it.
    pub fn drive_frame(&self) -> DriveFrame {
        self.drive
    }

    /// Every pose the input records for its scans (frame number and
    /// `world_from_velodyne`), also past the selected frames; none when its scans
    /// are not posed by recorded poses.
    pub fn recorded_poses(&self) -> Result<Vec<(usize, Isometry3<f64>)>> {
        if self.posing != Posing::Recorded {
            return Ok(Vec::new());
        }
        match &self.recording {
            Recording::Kitti(sequence) => sequence.recorded_poses(),
            Recording::Log(drive) => Ok(drive.recorded_poses()),
            Recording::Scans(..) => Ok(Vec::new()),
            Recording::Site(site) => Ok(site.poses()),
        }
    }

    /// Whether frames carry their camera images (default true). Decoding one costs
    /// more than the rest of the method, and without images a log's image messages
    /// are not even parsed.
    pub fn set_read_images(&mut self, read_images: bool) {
        self.read_images = read_images;
        match &mut self.recording {
            Recording::Kitti(sequence) => sequence.set_read_images(read_images),
            Recording::Log(drive) => drive.set_read_images(read_images),
            Recording::Scans(..) | Recording::Site(..) => {}
        }
    }

    /// Whether frames carry their points' labels (default true). Without, nothing
    /// downstream can see them: KITTI label files are not even opened.
    pub fn set_read_labels(&mut self, read_labels: bool) {
        self.read_labels = read_labels;
        if let Recording::Kitti(sequence) = &mut self.recording {
            sequence.set_read_labels(read_labels);
        }
    }

    /// Whether frames carry their camera images and their labels: what
    /// [`Self::set_read_images`] and [`Self::set_read_labels`] last said.
    pub fn reads(&self) -> (bool, bool) {
        (self.read_images, self.read_labels)
    }

    /// Where unreadable frames (and frames a later stage cannot use) are recorded.
    pub fn skip_log(&self) -> &SkipLog {
        &self.skips
    }

    /// The frames skipped so far.
    pub fn skipped(&self) -> Vec<Skip> {
        self.skips.skipped()
    }

    /// The parts of the input that could not be read besides whole frames (a
    /// recording cut short), in words.
    pub fn lost(&self) -> &[String] {
        self.skips.lost()
    }

    pub fn path(&self) -> &Path {
        match &self.recording {
            Recording::Kitti(s) => s.dir(),
            Recording::Log(d) => d.path(),
            Recording::Scans(f) => f.dir(),
            Recording::Site(site) => site.path(),
        }
    }

    /// Frame numbers in `range`, ascending.
    pub fn frames_in(&self, range: &Range<usize>) -> Vec<usize> {
        match &self.recording {
            Recording::Kitti(s) => s.frames_in(range),
            Recording::Log(d) => {
                (range.start.min(d.frame_count())..range.end.min(d.frame_count())).collect()
            }
            Recording::Scans(f) => f.frames_in(range),
            Recording::Site(site) => site.frames_in(range),
        }
    }

    /// The time `frames` (ascending) span as recorded: from the first stamp to the
    /// last, plus the median period between them; None for a source without stamps
    /// (folders of scans, site clouds) or fewer than two frames.
    pub fn recorded_seconds(&self, frames: &[usize]) -> Option<f64> {
        let stamp_ns = |frame: usize| match &self.recording {
            Recording::Kitti(s) => s.stamp_ns(frame).ok(),
            Recording::Log(d) => d.stamp_ns(frame),
            Recording::Scans(..) | Recording::Site(..) => None,
        };
        let stamps: Vec<u64> = frames.iter().map(|&f| stamp_ns(f)).collect::<Option<_>>()?;
        let (first, last) = (*stamps.first()?, *stamps.last()?);
        (stamps.len() > 1).then(|| {
            (last - first + crate::log_drive::merged_clouds::median_period_ns(&stamps)) as f64
                * 1e-9
        })
    }

    /// All frame numbers, ascending.
    pub fn frames(&self) -> Vec<usize> {
        self.frames_in(&(0..usize::MAX))
    }

    /// The frames in `range`, in order. With `--keep-going`
    /// ([`SourceOptions::keep_going`]) an unreadable frame is recorded and left out;
    /// otherwise its error ends the run.
    pub fn read<'a>(
        &'a self,
        range: &Range<usize>,
    ) -> Box<dyn Iterator<Item = Result<Frame>> + 'a> {
        self.read_some(range, None)
    }

    /// The frames of `frames` alone, in order, read as [`Self::read`] reads them: in
    /// one pass over a log, its other clouds passed over undecoded.
    pub fn read_only<'a>(
        &'a self,
        frames: &BTreeSet<usize>,
    ) -> Box<dyn Iterator<Item = Result<Frame>> + 'a> {
        let (Some(&first), Some(&last)) = (frames.first(), frames.last()) else {
            return Box::new(std::iter::empty());
        };
        self.read_some(&(first..last + 1), Some(frames.clone()))
    }

    fn read_some<'a>(
        &'a self,
        range: &Range<usize>,
        only: Option<BTreeSet<usize>>,
    ) -> Box<dyn Iterator<Item = Result<Frame>> + 'a> {
        let frames = self.read_recording(range, only);
        if self.read_labels {
            return frames;
        }
        Box::new(frames.map(|frame| frame.map(|f| Frame { labels: None, ..f })))
    }

    fn read_recording<'a>(
        &'a self,
        range: &Range<usize>,
        only: Option<BTreeSet<usize>>,
    ) -> Box<dyn Iterator<Item = Result<Frame>> + 'a> {
        let wanted = |frames: Vec<usize>| match &only {
            Some(only) => frames.into_iter().filter(|f| only.contains(f)).collect(),
            None => frames,
        };
        match &self.recording {
            Recording::Kitti(sequence) => Box::new(frame_by_frame(
                wanted(sequence.frames_in(range)),
                &self.skips,
                |index| sequence.read_frame(index),
            )),
            Recording::Log(drive) => Box::new(drive.read(range, only.clone(), &self.skips)),
            Recording::Scans(folder) => Box::new(frame_by_frame(
                wanted(folder.frames_in(range)),
                &self.skips,
                |index| folder.read_frame(index),
            )),
            Recording::Site(site) => Box::new(frame_by_frame(
                wanted(site.frames_in(range)),
                &self.skips,
                |index| site.read_frame(index),
            )),
        }
    }
}

/// Frames read one file at a time; unreadable ones go to `skips`.
fn frame_by_frame<'a>(
    frames: Vec<usize>,
    skips: &'a SkipLog,
    read: impl Fn(usize) -> Result<Frame> + 'a,
) -> impl Iterator<Item = Result<Frame>> + 'a {
    frames
        .into_iter()
        .filter_map(move |index| match read(index) {
            Ok(frame) => Some(Ok(frame)),
            Err(error) => skips.handle(index, error).err().map(Err),
        })
}

/// The sequence whose `velodyne/` folder `path` is, unless `--poses registration`
/// asks to read that folder as a folder of scans.
fn velodyne_of_sequence(path: &Path, options: &SourceOptions) -> Option<PathBuf> {
    let sequence = path.parent().filter(|p| format::is_sequence(p))?;
    let is_velodyne = path.file_name().is_some_and(|n| n == "velodyne");
    (is_velodyne && options.poses != PoseSource::Registration).then(|| sequence.to_path_buf())
}
