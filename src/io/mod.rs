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
mod mcap_records;
pub mod ros;
pub mod ros1;
pub mod ros_drive;
pub mod rosbag2;
pub mod transforms;

use std::ops::Range;
use std::path::Path;

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

/// A drive to read: a KITTI sequence directory or a recorded ROS log.
pub enum Source {
    Kitti(Box<KittiSequence>),
    Log(Box<ros_drive::RosDrive>),
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
        match format::detect(path)? {
            format::InputFormat::Kitti => Ok(Source::Kitti(Box::new(KittiSequence::open(path)?))),
            format => {
                let log = log::Log::open(path, format)?;
                log.notices().iter().for_each(|notice| on_notice(notice));
                Ok(Source::Log(Box::new(ros_drive::RosDrive::open(
                    log, options,
                )?)))
            }
        }
    }

    /// See [`KittiSequence::set_read_images`].
    pub fn set_read_images(&mut self, read_images: bool) {
        if let Source::Kitti(sequence) = self {
            sequence.set_read_images(read_images);
        }
    }

    /// Skip (and record) frames whose input is unreadable instead of stopping.
    pub fn set_keep_going(&mut self, keep_going: bool) {
        let log = SkipLog {
            keep_going,
            skipped: Default::default(),
        };
        match self {
            Source::Kitti(sequence) => sequence.skips = log,
            Source::Log(drive) => drive.skips = log,
        }
    }

    /// The frames skipped so far.
    pub fn skipped(&self) -> Vec<Skip> {
        match self {
            Source::Kitti(sequence) => sequence.skips.skipped(),
            Source::Log(drive) => drive.skips.skipped(),
        }
    }

    pub fn path(&self) -> &Path {
        match self {
            Source::Kitti(s) => s.dir(),
            Source::Log(d) => d.path(),
        }
    }

    /// Frame numbers in `range`, ascending.
    pub fn frames_in(&self, range: &Range<usize>) -> Vec<usize> {
        match self {
            Source::Kitti(s) => s.frames_in(range),
            Source::Log(d) => {
                (range.start.min(d.frame_count())..range.end.min(d.frame_count())).collect()
            }
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
            Source::Kitti(sequence) => {
                Box::new(sequence.frames_in(range).into_iter().filter_map(|index| {
                    match sequence.read_frame(index) {
                        Ok(frame) => Some(Ok(frame)),
                        Err(error) => sequence.skips.handle(index, error).err().map(Err),
                    }
                }))
            }
            Source::Log(drive) => Box::new(drive.read(range)),
        }
    }
}
