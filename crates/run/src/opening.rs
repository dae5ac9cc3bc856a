//! Opening a drive as every front end does (the command line, the Python module):
//! which frames of it are read by default, and what is said about the flags and
//! ranges that do not apply to it.

use std::ops::Range;
use std::path::{Path, PathBuf};

use travmap_core::config::PoseSource;
use travmap_core::error::{Error, Result};
use travmap_io::{Source, SourceKind, SourceOptions};

use crate::DriveRun;

/// What opening a drive has to say: a notice (how the input is read) or a warning
/// (something asked for that does not apply to it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Remark {
    Notice,
    Warning,
}

impl Remark {
    /// The word a line of it starts with on stderr.
    pub fn word(self) -> &'static str {
        match self {
            Remark::Notice => "notice",
            Remark::Warning => "warning",
        }
    }
}

/// Opens one input and checks that it has frames in `frames`; without `frames`,
/// every frame but a packet log's first when the recording began mid-turn (a part
/// of a rotation, too few points to register or to map). `on_remark` hears each
/// notice and warning.
pub fn open_selection(
    path: &Path,
    frames: Option<Range<usize>>,
    options: &SourceOptions,
    read_images: bool,
    on_remark: &dyn Fn(Remark, &str),
) -> Result<DriveRun> {
    let mut source = Source::open(path, options, &|notice| on_remark(Remark::Notice, notice))?;
    if source.kind() == SourceKind::Kitti {
        warn_log_only_flags(path, options, on_remark);
    }
    source.set_read_images(read_images);
    let frames = match (frames, source.partial_first_scan()) {
        (Some(frames), _) => frames,
        (None, None) => 0..usize::MAX,
        (None, Some((first, second))) => {
            on_remark(
                Remark::Notice,
                &format!(
                    "{}: frame 0 is the part of a rotation the recording began with ({first} packets, against {second} in frame 1): left out (--frames 0.. reads it)",
                    path.display()
                ),
            );
            1..usize::MAX
        }
    };
    let all = source.frames();
    if source.frames_in(&frames).is_empty() {
        let has = match (all.first(), all.last()) {
            (Some(first), Some(last)) => format!("frames {first}..={last}"),
            _ => "no frames".into(),
        };
        return Err(Error::Sequence {
            path: path.to_path_buf(),
            message: format!(
                "no scans in {} (the input has {has})",
                describe_frames(&frames)
            ),
        });
    }
    // A range past the end is read as far as the input goes, and said so.
    if let Some(&last) = all
        .last()
        .filter(|&&last| frames.end != usize::MAX && frames.end > last + 1)
    {
        on_remark(
            Remark::Notice,
            &format!(
                "{}: {} goes past its last frame, {last}: reading {}..={last}",
                path.display(),
                describe_frames(&frames),
                frames.start.max(all[0])
            ),
        );
    }
    Ok(DriveRun::new(source, frames))
}

/// A KITTI directory has no topics, frames or recorded poses of a log: flags that
/// name them are ignored there, and said so.
fn warn_log_only_flags(path: &Path, options: &SourceOptions, on_remark: &dyn Fn(Remark, &str)) {
    let log = &options.log;
    let log_only = [
        ("--cloud-topic", &log.cloud_topic),
        ("--world-frame", &log.world_frame),
        ("--camera-topic", &log.camera_topic),
        ("--pose-topic", &log.pose_topic),
    ];
    for (flag, _) in log_only.iter().filter(|(_, value)| value.is_some()) {
        on_remark(
            Remark::Warning,
            &format!(
                "{flag} applies to recorded logs (MCAP, ROS 1 bag, rosbag2); {} is a KITTI directory, so it is ignored there",
                path.display()
            ),
        );
    }
    if matches!(options.poses, PoseSource::Tf | PoseSource::Odometry) {
        on_remark(
            Remark::Warning,
            &format!(
                "--poses {} names a recorded log's poses; {} is a KITTI directory, whose poses.txt is used",
                options.poses.name(),
                path.display()
            ),
        );
    }
}

/// Parses a frame range: `A..B` (B excluded), `A..=B`, `A..`, `..B` or a single `N`.
pub fn parse_frame_range(text: &str) -> std::result::Result<Range<usize>, String> {
    let number = |s: &str, default: usize| -> std::result::Result<usize, String> {
        let s = s.trim();
        if s.is_empty() {
            return Ok(default);
        }
        s.parse()
            .map_err(|_| format!("frame range `{text}`: `{s}` is not a frame number"))
    };
    let range = if let Some((a, b)) = text.split_once("..=") {
        number(a, 0)?..number(b, usize::MAX - 1)? + 1
    } else if let Some((a, b)) = text.split_once("..") {
        number(a, 0)?..number(b, usize::MAX)?
    } else if text.trim().is_empty() {
        return Err(format!(
            "frame range `{text}` is empty: give N, A..B (A to B-1), A..=B or A.. (`..` for every frame)"
        ));
    } else if let Some((a, b)) = text.split_once('-') {
        // `0-2` as other tools write ranges: said in this tool's words, both ways.
        let (a, b) = (number(a, 0)?, number(b, 0)?);
        return Err(format!(
            "frame range `{text}`: write a range as A..B (B left out) or A..=B: `{a}..{}` or `{a}..={b}`",
            b + 1
        ));
    } else {
        let n = number(text, 0)?;
        n..n + 1
    };
    if range.is_empty() {
        return Err(format!(
            "frame range `{text}` selects no frame: it ends before it starts (A..B is A to B-1, A..=B is A to B)"
        ));
    }
    Ok(range)
}

/// A folder of scans' rate, Hz, when its file names are not times: LiDARs spin at
/// about 1 to 100 Hz; far outside that is a typo.
/// Errs with what was expected (the caller says what it got, as the user wrote it).
pub fn scan_rate_hz(hz: f64) -> std::result::Result<f64, &'static str> {
    match (0.01..=1000.0).contains(&hz) {
        true => Ok(hz),
        false => Err("a scan rate of 0.01 to 1000 Hz"),
    }
}

/// A frame range as a person writes it: `frames 6..` (to the end), `frames 2..=5`.
pub fn describe_frames(frames: &Range<usize>) -> String {
    match frames.end {
        usize::MAX => format!("frames {}..", frames.start),
        end if end == frames.start + 1 => format!("frame {}", frames.start),
        end => format!("frames {}..={}", frames.start, end - 1),
    }
}

/// A file's device and inode: the same under every name it has.
type FileId = Option<(u64, u64)>;

/// The same input twice (however spelled, or hard-linked under another name) would
/// count its frames twice.
pub fn refuse_repeats(paths: &[PathBuf]) -> Result<()> {
    use std::os::unix::fs::MetadataExt;
    let file_id = |path: &Path| std::fs::metadata(path).ok().map(|m| (m.dev(), m.ino()));
    let mut seen: Vec<(PathBuf, FileId, &Path)> = Vec::new();
    for path in paths {
        let canonical = std::fs::canonicalize(path).unwrap_or_else(|_| path.clone());
        let id = file_id(path);
        let same =
            |(c, i, _): &&(PathBuf, FileId, &Path)| *c == canonical || (id.is_some() && *i == id);
        if let Some((_, _, first)) = seen.iter().find(same) {
            return Err(Error::SameInputTwice {
                first: first.to_path_buf(),
                second: path.clone(),
            });
        }
        seen.push((canonical, id, path));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_ranges() {
        assert_eq!(parse_frame_range("0..3").unwrap(), 0..3);
        assert_eq!(parse_frame_range("2..=4").unwrap(), 2..5);
        assert_eq!(parse_frame_range("7").unwrap(), 7..8);
        assert_eq!(parse_frame_range("5..").unwrap(), 5..usize::MAX);
        assert!(parse_frame_range("3..3").is_err());
        assert!(parse_frame_range("a..3").is_err());
        let empty = parse_frame_range("").unwrap_err();
        assert!(empty.contains("is empty"), "{empty}");
        assert_eq!(parse_frame_range("..").unwrap(), 0..usize::MAX);
        let reversed = parse_frame_range("2..=1").unwrap_err();
        assert!(reversed.contains("ends before it starts"), "{reversed}");
    }

    #[test]
    fn frame_ranges_read_as_written() {
        assert_eq!(describe_frames(&(6..usize::MAX)), "frames 6..");
        assert_eq!(describe_frames(&(2..6)), "frames 2..=5");
        assert_eq!(describe_frames(&(964..965)), "frame 964");
    }
}
