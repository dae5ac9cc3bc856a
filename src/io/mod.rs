//! Stage 0, reading: a drive into [`Frame`]s (METHOD.md section 1). A [`Source`] is
//! a KITTI odometry / SemanticKITTI sequence directory ([`kitti`]) or a recorded ROS
//! log ([`ros_drive`] over a [`log::Log`]: MCAP, ROS 1 bag, rosbag2), told apart by
//! content ([`format`]). [`ros`] holds the message types (CDR; [`ros1`] reads ROS 1's
//! format into the same types), [`cloud`] and [`image`] decode their payloads.
//! Nothing here knows the method.

pub mod bag;
pub mod cloud;
pub mod format;
pub mod image;
pub mod kitti;
mod kitti_text;
pub mod log;
pub mod mcap_records;
pub mod pcd;
pub mod ros;
pub mod ros1;
pub mod ros_drive;
pub mod rosbag2;
pub mod scan_folder;
pub mod transforms;

use std::ops::Range;
use std::path::Path;

use crate::config::PoseSource;
use crate::error::{Error, Result};
use crate::frame::Frame;
pub use kitti::KittiSequence;

/// A frame left out because its input was unreadable (`--keep-going`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Skip {
    pub frame: usize,
    pub reason: String,
}

/// Whether a frame whose input is unreadable stops the run (the default) or is
/// skipped and recorded, and the record.
#[derive(Clone, Debug, Default)]
pub struct SkipLog {
    keep_going: bool,
    skipped: std::sync::Arc<std::sync::Mutex<Vec<Skip>>>,
}

impl SkipLog {
    /// Records `error` for `frame` when keeping going, else returns it.
    pub fn handle(&self, frame: usize, error: Error) -> Result<()> {
        if !self.keep_going {
            return Err(error);
        }
        // The whole chain: "cannot read x.bin: No such file or directory".
        let mut reason = error.to_string();
        let mut cause = std::error::Error::source(&error);
        while let Some(inner) = cause {
            reason.push_str(&format!(": {inner}"));
            cause = inner.source();
        }
        if let Ok(mut skipped) = self.skipped.lock()
            && !skipped
                .iter()
                .any(|s| s.frame == frame && s.reason == reason)
        {
            // Passes over the same input (passthrough, then the method) report a frame once.
            skipped.push(Skip { frame, reason });
        }
        Ok(())
    }

    pub fn skipped(&self) -> Vec<Skip> {
        self.skipped.lock().map(|s| s.clone()).unwrap_or_default()
    }
}

/// How a source's scans are posed in the world.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Posing {
    /// By the input's own poses (`poses.txt`, /tf, Odometry).
    Recorded,
    /// By the method's registration stage, scan after scan.
    Registration,
    /// Not at all: each scan alone in its own frame.
    Alone,
}

/// A drive to read: a KITTI sequence directory, a recorded ROS log or a folder of scans.
pub enum Source {
    Kitti(Box<KittiSequence>, Posing),
    Log(Box<ros_drive::RosDrive>),
    Scans(Box<scan_folder::ScanFolder>, Posing),
}

impl Source {
    /// The drive at `path`, of the format its content says ([`format::detect`]).
    /// `on_notice` hears what the reader noticed and worked around (an unindexed
    /// bag, ...) as soon as it is known, before anything can fail later.
    pub fn open(
        path: &Path,
        options: &ros_drive::DriveOptions,
        on_notice: &dyn Fn(&str),
    ) -> Result<Self> {
        let posing = match options.poses {
            PoseSource::Registration => Posing::Registration,
            PoseSource::None => Posing::Alone,
            _ => Posing::Recorded,
        };
        match format::detect(path)? {
            format::InputFormat::Kitti if scan_folder::ScanFolder::holds_scans(path) => {
                let folder = scan_folder::ScanFolder::open(path, options.rate_hz)?;
                let posing = match options.poses {
                    PoseSource::Auto | PoseSource::Registration => Posing::Registration,
                    PoseSource::None => Posing::Alone,
                    source => {
                        return Err(Error::Sequence {
                            path: path.to_path_buf(),
                            message: format!(
                                "--poses {}: a folder of scans records no poses (--poses registration or none)",
                                source.name()
                            ),
                        });
                    }
                };
                on_notice(folder.notice());
                Ok(Source::Scans(Box::new(folder), posing))
            }
            format::InputFormat::Kitti => {
                Ok(Source::Kitti(Box::new(KittiSequence::open(path)?), posing))
            }
            format => {
                let log = log::Log::open(path, format)?;
                log.notices().iter().for_each(|notice| on_notice(notice));
                let drive = ros_drive::RosDrive::open(log, options)?;
                drive.notice().into_iter().for_each(on_notice);
                Ok(Source::Log(Box::new(drive)))
            }
        }
    }

    /// The frame the scans are in, as written to MCAP (`header.frame_id`).
    pub fn sensor_frame(&self) -> &str {
        match self {
            Source::Kitti(..) => "velodyne",
            Source::Log(drive) => drive.cloud_frame(),
            Source::Scans(..) => scan_folder::SENSOR_FRAME,
        }
    }

    /// How the scans are posed.
    pub fn posing(&self) -> Posing {
        match self {
            Source::Kitti(_, posing) | Source::Scans(_, posing) => *posing,
            Source::Log(drive) => drive.posing(),
        }
    }

    /// See [`KittiSequence::set_read_images`].
    pub fn set_read_images(&mut self, read_images: bool) {
        if let Source::Kitti(sequence, _) = self {
            sequence.set_read_images(read_images);
        }
    }

    /// Skip (and record) frames whose input is unreadable instead of stopping.
    pub fn set_keep_going(&mut self, keep_going: bool) {
        let log = SkipLog {
            keep_going,
            skipped: Default::default(),
        };
        *self.skip_log_mut() = log;
    }

    fn skip_log_mut(&mut self) -> &mut SkipLog {
        match self {
            Source::Kitti(sequence, _) => &mut sequence.skips,
            Source::Log(drive) => &mut drive.skips,
            Source::Scans(folder, _) => &mut folder.skips,
        }
    }

    /// Where unreadable frames (and frames a later stage cannot use) are recorded.
    pub fn skip_log(&self) -> &SkipLog {
        match self {
            Source::Kitti(sequence, _) => &sequence.skips,
            Source::Log(drive) => &drive.skips,
            Source::Scans(folder, _) => &folder.skips,
        }
    }

    /// The frames skipped so far.
    pub fn skipped(&self) -> Vec<Skip> {
        self.skip_log().skipped()
    }

    pub fn path(&self) -> &Path {
        match self {
            Source::Kitti(s, _) => s.dir(),
            Source::Log(d) => d.path(),
            Source::Scans(f, _) => f.dir(),
        }
    }

    /// Frame numbers in `range`, ascending.
    pub fn frames_in(&self, range: &Range<usize>) -> Vec<usize> {
        match self {
            Source::Kitti(s, _) => s.frames_in(range),
            Source::Log(d) => {
                (range.start.min(d.frame_count())..range.end.min(d.frame_count())).collect()
            }
            Source::Scans(f, _) => f.frames_in(range),
        }
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
        match self {
            Source::Kitti(sequence, _) => Box::new(frame_by_frame(
                sequence.frames_in(range),
                &sequence.skips,
                |index| sequence.read_frame(index),
            )),
            Source::Log(drive) => Box::new(drive.read(range)),
            Source::Scans(folder, _) => Box::new(frame_by_frame(
                folder.frames_in(range),
                &folder.skips,
                |index| folder.read_frame(index),
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
