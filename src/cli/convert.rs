//! `travmap convert`: a KITTI / SemanticKITTI sequence or a recorded log (ROS 1 bag,
//! ROS 1 MCAP, rosbag2) to a ROS 2 MCAP.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use clap::{Args, ValueEnum};
use serde_json::json;
use travmap_formats::mcap::writer::Compression;
use travmap_io::{LogOptions, Recorded, RecordedLog, SourceOptions};
use travmap_outputs::conversion::{convert_kitti, convert_log};
use travmap_outputs::preflight::InputFiles;

use super::{
    Outcome, Output, Sensors, check_output, frame_count, note_extension, open_selection, outcome,
    parse_frame_range, path_text, print_json_summary, print_wrote, with_summary,
};

/// Convert a KITTI / SemanticKITTI sequence or a recorded log to a ROS 2 MCAP
///
/// A sequence gives its clouds, its poses on /tf and its images; a log may be a ROS 1
/// bag, a ROS 1 MCAP, a rosbag2 directory or .db3, or captured packets.
#[derive(Args)]
#[command(
    after_long_help = "Examples (SEQ: a KITTI sequence folder, e.g. ../shared/data/semantickitti-00/sequences/00):\n  travmap convert SEQ -o drive.mcap\n  travmap convert drive.bag -o drive.mcap\n  travmap convert capture.pcap -o scans.mcap --lidar-calibration VLP16.yaml"
)]
pub struct ConvertArgs {
    /// The sequence directory, or the log.
    sequence: PathBuf,
    /// Where to write the MCAP.
    #[arg(short, long)]
    output: PathBuf,
    /// Frames to convert (KITTI input): A..B (B excluded), A..=B, A.. or N. Default: all.
    #[arg(long, value_parser = parse_frame_range)]
    frames: Option<std::ops::Range<usize>>,
    #[command(flatten)]
    compression: CompressionArg,
    /// Seconds since the Unix epoch added to times.txt for every stamp.
    #[arg(long, default_value_t = 0.0, value_parser = parse_start_time)]
    start_time: f64,
    /// Log input: every topic is converted either way; these choose the cloud
    /// topic whose clouds are counted as frames and the packet topics decoded.
    #[command(flatten)]
    sensors: Sensors,
    /// Log input: leave out the messages of damaged chunks (named on stderr, exit
    /// code 3) instead of stopping at the first.
    #[arg(long)]
    keep_going: bool,
    #[command(flatten)]
    report: Output,
}

/// MCAP chunk compression, for the commands that write MCAP.
#[derive(Args)]
pub struct CompressionArg {
    /// Chunk compression.
    #[arg(long = "compression", value_enum, default_value_t = Codec::Zstd)]
    codec: Codec,
}

#[derive(Clone, Copy, ValueEnum)]
enum Codec {
    Zstd,
    Lz4,
    None,
}

impl CompressionArg {
    pub fn compression(&self) -> Compression {
        match self.codec {
            Codec::Zstd => Compression::Zstd,
            Codec::Lz4 => Compression::Lz4,
            Codec::None => Compression::None,
        }
    }
}

pub fn convert(args: ConvertArgs) -> Result<Outcome> {
    let (output, output_path) = (args.report, args.output.as_path());
    let compression = args.compression.compression();
    let start_time_s = args.start_time;
    let calibrations = args.sensors.calibrations();
    let mut read: Vec<&Path> = vec![&args.sequence];
    read.extend(calibrations.files());
    check_output(output_path, &InputFiles::of(&read))?;
    note_extension(output_path, "mcap", "an MCAP file");
    // Every scan: convert keeps a log's first, however partial.
    let frames = args.frames.clone().unwrap_or(0..usize::MAX);
    let options = SourceOptions {
        keep_going: args.keep_going,
        log: args.sensors.log_options(LogOptions::default())?,
        ..SourceOptions::default()
    };
    let selection = open_selection(
        &args.sequence,
        Some(frames.clone()),
        &options,
        false,
        &super::say,
    )?;
    let selections = [selection];
    let sequence = match selections[0].source.recorded() {
        Recorded::Log(drive) => {
            if args.frames.is_some() {
                bail!("--frames applies to KITTI input; a log is converted whole");
            }
            return convert_whole_log(&drive, output_path, compression, &output, &selections);
        }
        Recorded::Kitti(sequence) => sequence,
        Recorded::FramesOnly => bail!(
            "convert takes a KITTI sequence directory or a recorded log, not a folder of scans"
        ),
    };
    let bar = output.progress(frame_count(&selections), "converting");
    let start_ns = (start_time_s * 1e9).round() as u64;
    let summary = convert_kitti(
        &sequence,
        &frames,
        output_path,
        compression,
        start_ns,
        &|| bar.inc(1),
    )?;
    let seconds = bar.finish();
    let written = Written {
        frames: summary.frames,
        contents: format!(
            "{} with labels, {} images",
            summary.labelled_frames, summary.images
        ),
        output_bytes: summary.output_bytes,
        note: (summary.dropped_points > 0).then(|| {
            format!(
                "{} points without a return (a NaN or infinite coordinate, or the sensor's origin) were left out",
                summary.dropped_points
            )
        }),
        summary: serde_json::to_value(&summary)?,
    };
    written.report(output_path, compression, &output, seconds, &selections)
}

/// The last start ROS 2's `int32` seconds can stamp (2038-01-19), a day before the
/// end so that a drive fits after it.
const LATEST_START_S: f64 = (i32::MAX - 86_400) as f64;

/// `--start-time` as seconds since the epoch, with a hint when it looks like a
/// finer unit (a usage error otherwise).
fn parse_start_time(text: &str) -> Result<f64, String> {
    let seconds: f64 = text
        .parse()
        .map_err(|_| format!("`{text}` is not a number"))?;
    if seconds.is_finite() && (0.0..=LATEST_START_S).contains(&seconds) {
        return Ok(seconds);
    }
    // A time since 1973 in a finer unit: the user's clock's, read as seconds.
    let unit = [
        ("milliseconds", 1e3),
        ("microseconds", 1e6),
        ("nanoseconds", 1e9),
    ]
    .into_iter()
    .find(|(_, per_second)| (1e8..=LATEST_START_S).contains(&(seconds / per_second)));
    let hint = match unit {
        Some((name, per_second)) => {
            format!(
                "; it looks like {name}: --start-time {}",
                seconds / per_second
            )
        }
        None => String::new(),
    };
    Err(format!(
        "seconds since the epoch, 0 to {LATEST_START_S} (ROS 2 stamps end in 2038), got {seconds}{hint}"
    ))
}

/// What a conversion wrote, for its report.
struct Written {
    summary: serde_json::Value,
    frames: usize,
    /// What the frames hold, as a person reads it.
    contents: String,
    output_bytes: u64,
    /// Said on stderr after the report.
    note: Option<String>,
}

impl Written {
    /// The `wrote ...` line (or the `--json` summary) and the note.
    fn report(
        self,
        output_path: &std::path::Path,
        compression: Compression,
        output: &Output,
        seconds: f64,
        selections: &[travmap_run::DriveRun],
    ) -> Result<Outcome> {
        if output.json {
            let fields = json!({"output": path_text(output_path), "compression": compression, "elapsed_ms": seconds * 1e3});
            let fields = with_summary(fields, &self.summary)?;
            print_json_summary("convert", selections, fields)?;
        } else if !output.quiet {
            print_wrote(
                output_path,
                self.frames,
                &self.contents,
                self.output_bytes,
                seconds,
            );
            if let Some(note) = &self.note {
                eprintln!("{note}");
            }
        }
        Ok(outcome(selections))
    }
}

/// `convert` of a recorded log: every message, as ROS 2 where travmap knows the type.
fn convert_whole_log(
    drive: &RecordedLog,
    output_path: &std::path::Path,
    compression: Compression,
    output: &Output,
    selections: &[travmap_run::DriveRun],
) -> Result<Outcome> {
    let bar = output.progress(drive.frame_count() as u64, "converting");
    let summary = convert_log(drive, output_path, compression, &|topic, count| {
        if topic == drive.cloud_topic() {
            bar.inc(count);
        }
    })?;
    let seconds = bar.finish();
    let written = Written {
        frames: drive.frame_count(),
        contents: format!(
            "{} messages, {} of them re-encoded as ROS 2 (from ROS 1 or Foxglove's schemas)",
            summary.messages, summary.translated_messages
        ),
        output_bytes: summary.output_bytes,
        note: {
            let mut notes = Vec::new();
            if !summary.topics_as_recorded.is_empty() {
                notes.push(format!(
                    "copied as recorded (types travmap does not translate): {}",
                    summary.topics_as_recorded.join(", ")
                ));
            }
            if summary.partial_first_scan_left_out {
                notes.push(format!(
                    "the part of a rotation the log began with is left out of {} (its packets are copied; its stamp would be the next scan's)",
                    summary.decoded_topic.as_deref().unwrap_or("the decoded scans")
                ));
            }
            (!notes.is_empty()).then(|| notes.join("\n"))
        },
        summary: serde_json::to_value(&summary)?,
    };
    written.report(output_path, compression, output, seconds, selections)
}
