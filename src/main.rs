//! The `travmap` binary: parses arguments and calls one command of the library.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand, ValueEnum};
use travmap::annotation::AnnotationOptions;
use travmap::commands::{self, Inputs, Outcome, Output};
use travmap::reading::mcap_drive::DriveOptions;
use travmap::writing::Compression;

#[derive(Parser)]
#[command(
    name = "travmap",
    version,
    about = "Traversability maps from recorded drives (LiDAR + SVM, CPU only)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Predict the filtered traversability grid of every frame.
    Run {
        #[command(flatten)]
        common: Common,
        /// Model file (default: the model compiled into travmap).
        #[arg(long)]
        model: Option<PathBuf>,
        /// Draw each grid as text ('.' traversable, '#' not, ' ' unknown; x right, y up).
        #[arg(long)]
        ascii: bool,
    },
    /// Score predictions against SemanticKITTI ground truth (the paper's table).
    Eval {
        #[command(flatten)]
        common: Common,
        /// Model file (default: the model compiled into travmap).
        #[arg(long)]
        model: Option<PathBuf>,
    },
    /// Train the SVM (grid search over C and gamma, spatially-blocked CV).
    Train {
        #[command(flatten)]
        common: Common,
        /// Where to write the model (JSON).
        #[arg(short, long)]
        output: PathBuf,
    },
    /// One Parquet row per predictable cell per frame: features, appearance, ground
    /// truth and (with --model) the prediction, on the training grid.
    Dataset {
        #[command(flatten)]
        common: Common,
        /// Where to write the Parquet file.
        #[arg(short, long)]
        output: PathBuf,
        /// Add the prediction of this model file (by default no prediction column values).
        #[arg(long)]
        model: Option<PathBuf>,
    },
    /// Held-out accuracy by spatially-blocked cross-validation over the frames.
    Crossval {
        #[command(flatten)]
        common: Common,
    },
    /// Convert a KITTI / SemanticKITTI sequence to a ROS 2 MCAP (clouds, poses on /tf, images).
    Convert {
        /// The sequence directory.
        sequence: PathBuf,
        /// Where to write the MCAP.
        #[arg(short, long)]
        output: PathBuf,
        /// Frames to convert: A..B (B excluded), A..=B, A.. or N. Default: all.
        #[arg(long)]
        frames: Option<String>,
        /// Chunk compression.
        #[arg(long, value_enum, default_value_t = CompressionArg::Zstd)]
        compression: CompressionArg,
        /// Seconds since the Unix epoch added to times.txt for every stamp.
        #[arg(long, default_value_t = 0.0)]
        start_time: f64,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
        /// No progress bar, no summary.
        #[arg(short, long)]
        quiet: bool,
    },
    /// Write the annotated MCAP: predicted and ground-truth grids, classified cloud, metrics.
    Annotate {
        #[command(flatten)]
        common: Common,
        /// Where to write the MCAP.
        #[arg(short, long)]
        output: PathBuf,
        /// Model file (default: the model compiled into travmap).
        #[arg(long)]
        model: Option<PathBuf>,
        /// Chunk compression.
        #[arg(long, value_enum, default_value_t = CompressionArg::Zstd)]
        compression: CompressionArg,
        /// Do not copy the input's messages into the output.
        #[arg(long)]
        no_passthrough: bool,
        /// Height of the drawn grids relative to the sensor, metres.
        #[arg(long, default_value_t = -1.73, allow_negative_numbers = true)]
        grid_height: f64,
    },
    /// Draw ground truth, prediction and errors of a frame side by side as PNG.
    Render {
        #[command(flatten)]
        common: Common,
        /// The PNG to write (with --frame) or the directory for one PNG per frame (--all).
        #[arg(short, long)]
        output: PathBuf,
        /// The frame to draw.
        #[arg(long, conflicts_with = "all")]
        frame: Option<usize>,
        /// Draw every selected frame (see --frames) into the output directory.
        #[arg(long)]
        all: bool,
        /// Model file (default: the model compiled into travmap).
        #[arg(long)]
        model: Option<PathBuf>,
        /// Pixels per cell side.
        #[arg(long, default_value_t = 8)]
        cell_pixels: u32,
    },
    /// Per-stage latency (median, p95) and throughput on 1 thread and all cores.
    Bench {
        #[command(flatten)]
        common: Common,
        /// Model file (default: the model compiled into travmap).
        #[arg(long)]
        model: Option<PathBuf>,
        /// Times each measurement is repeated.
        #[arg(long, default_value_t = 20)]
        repeats: usize,
    },
    /// Print the effective configuration (TOML; JSON with --json).
    Config {
        #[command(flatten)]
        settings: Settings,
        #[arg(long)]
        json: bool,
    },
}

#[derive(Clone, Copy, ValueEnum)]
enum CompressionArg {
    Zstd,
    Lz4,
    None,
}

impl From<CompressionArg> for Compression {
    fn from(arg: CompressionArg) -> Self {
        match arg {
            CompressionArg::Zstd => Compression::Zstd,
            CompressionArg::Lz4 => Compression::Lz4,
            CompressionArg::None => Compression::None,
        }
    }
}

#[derive(Args)]
struct Settings {
    /// TOML file overriding configuration defaults (see `travmap config`).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Override one setting, e.g. --set grid.size_m=24 (repeatable).
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    sets: Vec<String>,
}

#[derive(Args)]
struct Common {
    /// KITTI odometry / SemanticKITTI sequence directories (holding velodyne/, calib.txt,
    /// poses.txt, times.txt) or ROS 2 MCAP drives.
    #[arg(required = true)]
    sequences: Vec<PathBuf>,
    /// MCAP input: the PointCloud2 topic (needed when there are several).
    #[arg(long)]
    cloud_topic: Option<String>,
    /// MCAP input: the world frame poses are taken in (default: the root of the
    /// transform tree above the clouds' frame).
    #[arg(long)]
    world_frame: Option<String>,
    /// MCAP input: the camera's Image or CompressedImage topic (needed when there are
    /// several with a CameraInfo).
    #[arg(long)]
    camera_topic: Option<String>,
    /// Frames to use: A..B (B excluded), A..=B, A.. or N. Default: all.
    #[arg(long)]
    frames: Option<String>,
    #[command(flatten)]
    settings: Settings,
    /// Machine-readable output.
    #[arg(long)]
    json: bool,
    /// No progress bars, no tables.
    #[arg(short, long)]
    quiet: bool,
    /// Skip frames whose input is unreadable, report them, and exit with code 3
    /// (instead of stopping at the first one with code 1).
    #[arg(long)]
    keep_going: bool,
}

impl Common {
    fn inputs(&self) -> Inputs {
        Inputs {
            sequences: self.sequences.clone(),
            drive: DriveOptions {
                cloud_topic: self.cloud_topic.clone(),
                world_frame: self.world_frame.clone(),
                camera_topic: self.camera_topic.clone(),
            },
            frames: self.frames.clone(),
            keep_going: self.keep_going,
        }
    }

    fn output(&self) -> Output {
        Output {
            json: self.json,
            quiet: self.quiet,
        }
    }

    fn config(&self) -> anyhow::Result<travmap::Config> {
        commands::load_config(self.settings.config.as_deref(), &self.settings.sets)
    }
}

fn dispatch(cli: Cli) -> anyhow::Result<Outcome> {
    match cli.command {
        Command::Run {
            common,
            model,
            ascii,
        } => commands::run(
            &common.inputs(),
            &common.config()?,
            model.as_deref(),
            ascii,
            common.output(),
        ),
        Command::Eval { common, model } => commands::eval(
            &common.inputs(),
            &common.config()?,
            model.as_deref(),
            common.output(),
        ),
        Command::Train { common, output } => commands::train(
            &common.inputs(),
            &common.config()?,
            &output,
            common.output(),
        ),
        Command::Dataset {
            common,
            output,
            model,
        } => commands::dataset(
            &common.inputs(),
            &common.config()?,
            model.as_deref(),
            &output,
            common.output(),
        ),
        Command::Crossval { common } => {
            commands::crossval(&common.inputs(), &common.config()?, common.output())
        }
        Command::Convert {
            sequence,
            output,
            frames,
            compression,
            start_time,
            json,
            quiet,
        } => {
            let compression = compression.into();
            let inputs = Inputs {
                sequences: vec![sequence],
                drive: DriveOptions::default(),
                frames,
                keep_going: false,
            };
            commands::convert(
                &inputs,
                &output,
                compression,
                start_time,
                Output { json, quiet },
            )
        }
        Command::Annotate {
            common,
            output,
            model,
            compression,
            no_passthrough,
            grid_height,
        } => {
            let options = AnnotationOptions {
                compression: compression.into(),
                passthrough: !no_passthrough,
                grid_height_m: grid_height,
            };
            commands::annotate(
                &common.inputs(),
                &common.config()?,
                model.as_deref(),
                &output,
                &options,
                common.output(),
            )
        }
        Command::Render {
            common,
            output,
            frame,
            all,
            model,
            cell_pixels,
        } => {
            let mut inputs = common.inputs();
            match (frame, all) {
                (Some(frame), _) => inputs.frames = Some(frame.to_string()),
                (None, true) => {}
                (None, false) => anyhow::bail!("render needs --frame N or --all"),
            }
            commands::render(
                &inputs,
                &common.config()?,
                model.as_deref(),
                &output,
                all,
                cell_pixels,
                common.output(),
            )
        }
        Command::Bench {
            common,
            model,
            repeats,
        } => commands::bench(
            &common.inputs(),
            &common.config()?,
            model.as_deref(),
            repeats,
            common.output(),
        ),
        Command::Config { settings, json } => {
            let config = commands::load_config(settings.config.as_deref(), &settings.sets)?;
            commands::print_config(&config, Output { json, quiet: false })?;
            Ok(Outcome::Complete)
        }
    }
}

/// Exit codes: 0 complete, 1 error (no output written), 3 completed
/// with skipped frames (`--keep-going`), 130 interrupted (no output written).
fn main() -> ExitCode {
    // Interrupted: remove partial outputs, exit as shells expect after SIGINT.
    let _ = ctrlc::set_handler(|| {
        travmap::writing::remove_temporary_files();
        std::process::exit(130);
    });
    match dispatch(Cli::parse()) {
        Ok(Outcome::Complete) => ExitCode::SUCCESS,
        Ok(Outcome::Skipped(frames)) => {
            eprintln!("completed with {frames} skipped frame(s)");
            ExitCode::from(3)
        }
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}
