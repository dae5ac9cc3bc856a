//! What a drive's input recorded beside its frames, for the outputs that copy or
//! convert it (`convert`, annotate's passthrough): a log's messages in order (and its
//! chunks as stored, its LiDAR packets as scans), a KITTI sequence's frames, images
//! and calibration. [`Source::recorded`](crate::Source::recorded) hands it out with
//! the source's skip log inside, so that what copying meets is recorded where reading
//! the frames records it.

use std::ops::Range;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix3};
use travmap_core::error::Result;
use travmap_core::frame::Frame;
use travmap_formats::log_message::LogMessage;
use travmap_formats::mcap::stored::StoredLog;

use crate::kitti::KittiSequence;
use crate::log_drive::LogDrive;
use crate::log_drive::frames::DecodedScan;
use crate::skips::SkipLog;

/// What an input recorded beside its frames.
pub enum Recorded<'a> {
    Log(RecordedLog<'a>),
    Kitti(RecordedKitti<'a>),
    /// A folder of scans or one saved cloud: the frames are all it holds.
    FramesOnly,
}

/// A recorded log, read as its drive reads it.
pub struct RecordedLog<'a> {
    pub(crate) drive: &'a LogDrive,
    pub(crate) skips: &'a SkipLog,
}

impl<'a> RecordedLog<'a> {
    pub fn path(&self) -> &Path {
        self.drive.path()
    }

    /// Every message in order, undecoded; with `--keep-going` the messages of damaged
    /// chunks are left out and recorded, else the first is an error.
    pub fn messages(&self) -> impl Iterator<Item = Result<LogMessage>> + 'a {
        self.drive.messages(self.skips)
    }

    /// The chunks as stored, when the log is one MCAP file whose chunks hold every
    /// message and none is damaged (for copying without decoding).
    pub fn stored(&self) -> Option<StoredLog> {
        self.drive.stored()
    }

    /// The scans of every LiDAR packet topic read, in log order (None without one).
    pub fn packet_scans(&self) -> Option<impl Iterator<Item = Result<DecodedScan<'a>>> + 'a> {
        self.drive.packet_scans(self.skips)
    }

    /// Whether the packet recording began mid-turn (its frame 0 a part of a rotation).
    pub fn begins_mid_turn(&self) -> bool {
        self.drive.partial_first_scan().is_some()
    }

    /// The topic the frames' scans come from.
    pub fn cloud_topic(&self) -> &str {
        self.drive.cloud_topic()
    }

    /// The frames the log holds.
    pub fn frame_count(&self) -> usize {
        self.drive.frame_count()
    }
}

/// A KITTI / SemanticKITTI sequence directory.
pub struct RecordedKitti<'a> {
    pub(crate) sequence: &'a KittiSequence,
    pub(crate) skips: &'a SkipLog,
}

impl RecordedKitti<'_> {
    pub fn dir(&self) -> &Path {
        self.sequence.dir()
    }

    /// The frame numbers in `range`.
    pub fn frames_in(&self, range: &Range<usize>) -> Vec<usize> {
        self.sequence.frames_in(range)
    }

    /// One frame, read on its own (for reading frames in parallel).
    pub fn read_frame(&self, index: usize) -> Result<Frame> {
        self.sequence.read_frame(index)
    }

    /// Frame `index`'s camera image file, when it has one.
    pub fn image_path(&self, index: usize) -> Option<PathBuf> {
        self.sequence.image_path(index)
    }

    /// The rigid velodyne -> camera_0 pose (`inv(Tr)`), as `/tf_static` carries it.
    pub fn velodyne_from_camera_0(&self) -> Isometry3<f64> {
        self.sequence.calibration().velodyne_from_camera_0()
    }

    /// The colour camera: its intrinsics K (P2's left 3x3) and camera_0 -> camera_2;
    /// None without P2.
    pub fn camera_2(&self) -> Option<(Matrix3<f64>, Isometry3<f64>)> {
        self.sequence.calibration().camera_2()
    }

    /// An error of frame `index`: recorded and None with `--keep-going`, else the
    /// error.
    pub fn kept<T>(&self, index: usize, made: Result<T>) -> Result<Option<T>> {
        match made {
            Ok(made) => Ok(Some(made)),
            Err(error) => self.skips.handle(index, error).map(|()| None),
        }
    }

    /// The frames skipped so far.
    pub fn skips(&self) -> &SkipLog {
        self.skips
    }
}
