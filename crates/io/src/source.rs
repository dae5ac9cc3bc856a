//! A drive to read, whatever holds it, told apart by content ([`super::format`]), and
//! posed once by [`travmap_core::posing::decide`].

use std::ops::Range;
use std::path::Path;

use super::format;
use super::kitti::KittiSequence;
use super::ros_drive::{DriveOptions, RosDrive};
use super::skips::{Skip, SkipLog};
use crate::cloud_files::scan_folder::ScanFolder;
use crate::cloud_files::site_cloud::SiteCloud;
use crate::containers::log::Log;
use travmap_core::error::{Error, Result};
use travmap_core::frame::Frame;
use travmap_core::posing::{PoseRecord, Posing, decide};

/// What holds a drive: a KITTI sequence directory, a recorded ROS log or a folder of
/// scans.
pub enum Recording {
    Kitti(Box<KittiSequence>),
    Log(Box<RosDrive>),
    Scans(Box<ScanFolder>),
    /// One saved point cloud read as tiles (site maps).
    Site(Box<SiteCloud>),
}

/// The world frame of inputs that do not name one (KITTI, folders of scans).
pub const WORLD_FRAME: &str = "map";

/// A drive to read, and how its scans are posed.
pub struct Source {
    pub recording: Recording,
    posing: Posing,
    /// Frames carry their points' labels (false: read as if unlabelled).
    read_labels: bool,
}

impl Source {
    /// The drive at `path`, of the format its content says ([`format::detect`]),
    /// posed as [`decide`] says. `on_notice` hears what the reader noticed and worked
    /// around (an unindexed bag, poses estimated, ...) as soon as it is known, before
    /// anything can fail later.
    pub fn open(path: &Path, options: &DriveOptions, on_notice: &dyn Fn(&str)) -> Result<Self> {
        let (recording, record) = match format::detect(path)? {
            format::InputFormat::Kitti if let Some(problem) = misplaced(path, options) => {
                return Err(Error::Sequence {
                    path: path.to_path_buf(),
                    message: problem,
                });
            }
            format::InputFormat::Kitti if ScanFolder::holds_scans(path) => {
                let folder = ScanFolder::open(path, options.rate_hz)?;
                on_notice(folder.notice());
                let record = PoseRecord::Missing("a folder of scans records no poses".into());
                (Recording::Scans(Box::new(folder)), record)
            }
            format::InputFormat::Kitti => {
                let sequence = KittiSequence::open(path)?;
                (Recording::Kitti(Box::new(sequence)), PoseRecord::Reaches)
            }
            format => {
                let log = Log::open(path, format)?;
                log.notices().iter().for_each(|notice| on_notice(notice));
                // A log's poses depend on its transform tree: the drive decides as it opens.
                let drive = RosDrive::open(log, options)?;
                drive.notice().into_iter().for_each(on_notice);
                let posing = drive.posing();
                return Ok(Self {
                    recording: Recording::Log(Box::new(drive)),
                    posing,
                    read_labels: true,
                });
            }
        };
        let decision = decide(path, options.poses, &record)?;
        decision.notice.as_deref().into_iter().for_each(on_notice);
        Ok(Self {
            recording,
            posing: decision.posing,
            read_labels: true,
        })
    }

    /// One saved point cloud (a PCD file) as a site: tiles of `grid_size_m` read
    /// as frames posed by their virtual sensors (see [`SiteCloud`]).
    pub fn site_cloud(path: &Path, grid_size_m: f64) -> Result<Self> {
        Ok(Self {
            recording: Recording::Site(Box::new(SiteCloud::open(path, grid_size_m)?)),
            posing: Posing::Recorded,
            read_labels: true,
        })
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

    /// Every pose the input records for its scans (frame number and
    /// `world_from_velodyne`), also past the selected frames; none when its scans
    /// are not posed by recorded poses.
    pub fn recorded_poses(&self) -> Result<Vec<(usize, nalgebra::Isometry3<f64>)>> {
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

    /// Whether frames carry their camera images (default true): see
    /// [`KittiSequence::set_read_images`] and [`RosDrive::set_read_images`].
    pub fn set_read_images(&mut self, read_images: bool) {
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

    /// Skip (and record) frames whose input is unreadable instead of stopping.
    pub fn set_keep_going(&mut self, keep_going: bool) {
        *self.skip_log_mut() = SkipLog::new(keep_going);
    }

    fn skip_log_mut(&mut self) -> &mut SkipLog {
        match &mut self.recording {
            Recording::Kitti(sequence) => &mut sequence.skips,
            Recording::Log(drive) => &mut drive.skips,
            Recording::Scans(folder) => &mut folder.skips,
            Recording::Site(site) => &mut site.skips,
        }
    }

    /// Where unreadable frames (and frames a later stage cannot use) are recorded.
    pub fn skip_log(&self) -> &SkipLog {
        match &self.recording {
            Recording::Kitti(sequence) => &sequence.skips,
            Recording::Log(drive) => &drive.skips,
            Recording::Scans(folder) => &folder.skips,
            Recording::Site(site) => &site.skips,
        }
    }

    /// The frames skipped so far.
    pub fn skipped(&self) -> Vec<Skip> {
        self.skip_log().skipped()
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
            (last - first + crate::ros_drive::merged_clouds::median_period_ns(&stamps)) as f64
                * 1e-9
        })
    }

    /// All frame numbers, ascending.
    pub fn frames(&self) -> Vec<usize> {
        self.frames_in(&(0..usize::MAX))
    }

    /// The frames in `range`, in order. With `--keep-going` (see
    /// [`Source::set_keep_going`]) an unreadable frame is recorded and left out;
    /// otherwise its error ends the run.
    pub fn read<'a>(
        &'a self,
        range: &Range<usize>,
    ) -> Box<dyn Iterator<Item = Result<Frame>> + 'a> {
        let frames = self.read_recording(range);
        if self.read_labels {
            return frames;
        }
        Box::new(frames.map(|frame| frame.map(|f| Frame { labels: None, ..f })))
    }

    fn read_recording<'a>(
        &'a self,
        range: &Range<usize>,
    ) -> Box<dyn Iterator<Item = Result<Frame>> + 'a> {
        match &self.recording {
            Recording::Kitti(sequence) => Box::new(frame_by_frame(
                sequence.frames_in(range),
                &sequence.skips,
                |index| sequence.read_frame(index),
            )),
            Recording::Log(drive) => Box::new(drive.read(range)),
            Recording::Scans(folder) => Box::new(frame_by_frame(
                folder.frames_in(range),
                &folder.skips,
                |index| folder.read_frame(index),
            )),
            Recording::Site(site) => Box::new(frame_by_frame(
                site.frames_in(range),
                &site.skips,
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

/// What a directory that is no drive is instead, and where to point: a dataset root,
/// its `sequences/`, a sequence's `velodyne/` (a folder of scans only when asked), a
/// rosbag2 directory without its metadata.
fn misplaced(path: &Path, options: &DriveOptions) -> Option<String> {
    let is_sequence = |dir: &Path| dir.join("velodyne").is_dir() && dir.join("calib.txt").is_file();
    let subdirs = || -> Vec<std::path::PathBuf> {
        let entries = std::fs::read_dir(path).into_iter().flatten().flatten();
        let mut dirs: Vec<_> = entries.map(|e| e.path()).filter(|p| p.is_dir()).collect();
        dirs.sort();
        dirs
    };
    if is_sequence(path) {
        return None;
    }
    if let Some(first) = subdirs().into_iter().find(|d| is_sequence(d)) {
        return Some(format!(
            "a folder of sequences, not one: point at one of them, e.g. {}",
            first.display()
        ));
    }
    let sequences = path.join("sequences");
    if sequences.is_dir() {
        let first = std::fs::read_dir(&sequences)
            .into_iter()
            .flatten()
            .flatten();
        let example = first.map(|e| e.path()).filter(|p| is_sequence(p)).min();
        return Some(format!(
            "a dataset root: point at one sequence, e.g. {}",
            example.unwrap_or_else(|| sequences.join("00")).display()
        ));
    }
    let parent = path.parent().filter(|p| is_sequence(p));
    if let Some(sequence) = parent
        && path.file_name().is_some_and(|n| n == "velodyne")
        && options.poses != travmap_core::config::PoseSource::Registration
    {
        return Some(format!(
            "the velodyne/ folder of the sequence {}: point at the sequence, not its velodyne/ folder (or pass --poses registration to treat it as a folder of scans)",
            sequence.display()
        ));
    }
    None
}
