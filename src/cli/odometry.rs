//! `travmap odometry`: the trajectory of a drive by scan registration, in KITTI or
//! TUM format, to check against a ground truth.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, ValueEnum};
use serde_json::json;
use travmap_outputs::trajectory::{TrajectoryFormat, write_trajectory};
use travmap_run::scoring::evaluation::Spread;

use super::{Inputs, Outcome, check_output, frame_count, outcome, path_text, print_json_summary};

/// Estimate a drive's trajectory by scan registration (whatever poses it records).
#[derive(Args)]
#[command(mut_arg("sequences", super::one_input))]
#[command(
    after_long_help = "Examples (SEQ: a KITTI sequence folder, e.g. ../shared/data/semantickitti-00/sequences/00):\n  travmap odometry drive.mcap -o poses.txt\n  travmap odometry SEQ -o traj.tum --format tum"
)]
pub struct OdometryArgs {
    #[command(flatten)]
    inputs: Inputs,
    /// Where to write the poses.
    #[arg(short, long)]
    output: PathBuf,
    /// KITTI: a 3x4 pose per line (the scan's frame in the first scan's); TUM:
    /// `stamp tx ty tz qx qy qz qw`.
    #[arg(long, value_enum, default_value_t = Format::Kitti)]
    format: Format,
}

#[derive(Clone, Copy, ValueEnum)]
enum Format {
    Kitti,
    Tum,
}

pub fn odometry(args: OdometryArgs) -> Result<Outcome> {
    let config = args.inputs.settings.load()?;
    let (output, output_path) = (args.inputs.output, args.output.as_path());
    check_output(output_path, &args.inputs.files(None))?;
    let mut selection = args.inputs.open_one(&config, false)?;
    // Registration needs no labels: one short cannot stop it.
    selection.source.set_read_labels(false);
    let selections = [selection];
    let bar = output.progress(frame_count(&selections), "registering");
    let poses = selections[0].estimate_trajectory(&config, || bar.inc(1))?;
    let seconds = bar.finish();
    let format = match args.format {
        Format::Kitti => TrajectoryFormat::Kitti,
        Format::Tum => TrajectoryFormat::Tum,
    };
    if poses.is_empty() {
        let selection = &selections[0];
        let skipped = selection.source.skipped();
        return Err(travmap_io::nothing_read(output_path, selection.describe(), &skipped).into());
    }
    write_trajectory(output_path, &poses, format)?;
    let register_ms = Spread::of(&poses.iter().map(|p| p.register_ms).collect::<Vec<_>>());
    if output.json {
        let fields = json!({
            "output": path_text(output_path),
            "format": match format { TrajectoryFormat::Kitti => "kitti", TrajectoryFormat::Tum => "tum" },
            "frames": poses.len(),
            "register_ms": register_ms,
            "config": config,
            "elapsed_ms": seconds * 1e3,
        });
        print_json_summary("odometry", &selections, fields)?;
    } else if !output.quiet {
        println!(
            "wrote {} ({} poses, registration median {:.1} ms per scan, p95 {:.1} ms)",
            output_path.display(),
            poses.len(),
            register_ms.median,
            register_ms.p95
        );
    }
    Ok(outcome(&selections))
}
