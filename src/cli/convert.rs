//! `travmap convert`: a KITTI / SemanticKITTI sequence to a ROS 2 MCAP.

use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::{Args, ValueEnum};
use serde_json::json;
use travmap::io::Source;
use travmap::io::mcap_drive::DriveOptions;
use travmap::outputs::conversion::convert_kitti;
use travmap::outputs::preflight::InputFiles;
use travmap::outputs::writing::Compression;

use super::{
    Outcome, Output, check_output, frame_count, open_selection, outcome, parse_frame_range,
    print_json_summary, print_wrote,
};

/// Convert a KITTI / SemanticKITTI sequence to a ROS 2 MCAP (clouds, poses on /tf, images).
#[derive(Args)]
pub struct ConvertArgs {
    /// The sequence directory.
    sequence: PathBuf,
    /// Where to write the MCAP.
    #[arg(short, long)]
    output: PathBuf,
    /// Frames to convert: A..B (B excluded), A..=B, A.. or N. Default: all.
    #[arg(long, value_parser = parse_frame_range)]
    frames: Option<std::ops::Range<usize>>,
    #[command(flatten)]
    compression: CompressionArg,
    /// Seconds since the Unix epoch added to times.txt for every stamp.
    #[arg(long, default_value_t = 0.0)]
    start_time: f64,
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
    if !(start_time_s.is_finite() && start_time_s >= 0.0) {
        bail!("--start-time must be seconds >= 0, got {start_time_s}");
    }
    if args.sequence.is_file() {
        bail!(
            "{}: convert takes a KITTI sequence directory (velodyne/, calib.txt, poses.txt, times.txt); this is a file",
            args.sequence.display()
        );
    }
    check_output(output_path, &InputFiles::of(&[&args.sequence]))?;
    let frames = args.frames.unwrap_or(0..usize::MAX);
    let selection = open_selection(
        &args.sequence,
        &frames,
        &DriveOptions::default(),
        false,
        false,
    )?;
    let selections = [selection];
    let Source::Kitti(sequence) = &selections[0].source else {
        bail!("convert takes one KITTI sequence directory");
    };
    let bar = output.progress(frame_count(&selections), "converting");
    let start_ns = (start_time_s * 1e9).round() as u64;
    let summary = convert_kitti(
        sequence,
        &frames,
        output_path,
        compression,
        start_ns,
        &|| bar.inc(1),
    )?;
    let seconds = bar.finish();
    if output.json {
        let fields = json!({"output": output_path, "compression": compression, "summary": summary, "elapsed_ms": seconds * 1e3});
        print_json_summary("convert", &selections, fields)?;
    } else if !output.quiet {
        let contents = format!(
            "{} with labels, {} images",
            summary.labelled_frames, summary.images
        );
        print_wrote(
            output_path,
            summary.frames,
            &contents,
            summary.output_bytes,
            seconds,
        );
        if summary.dropped_points > 0 {
            eprintln!(
                "{} points with a non-finite coordinate were left out",
                summary.dropped_points
            );
        }
    }
    Ok(outcome(&selections))
}
