//! What every subcommand shares: the input and output arguments, loading the
//! configuration and the model, opening the inputs, progress bars and how a command
//! ends. One file per subcommand beside this one; `main.rs` dispatches to them.

pub mod adapt;
pub mod annotate;
pub mod bench;
#[cfg(feature = "bench-tools")]
mod child_flags;
pub mod config;
pub mod convert;
pub mod crossval;
pub mod dataset;
pub mod eval;
pub mod label;
pub mod map;
pub mod odometry;
pub mod render;
mod report;
pub mod run;
pub mod shell;
pub mod train;

pub use report::{
    counted, fit_said, input_json, model_json, notice, notice_drives, other_rule_said, path_text,
    print_json_error, print_json_frame, print_json_summary, print_wrote, say_once, setting_word,
    with_summary,
};

use std::io::IsTerminal;
use std::ops::Range;
use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use travmap_core::Config;
use travmap_core::config::ModelChoice;
use travmap_core::config_sources::{AssemblyError, ConfigSources};
use travmap_core::stopwatch::Stopwatch;
use travmap_io::{LidarCalibrations, LidarFrames, LogOptions, MergedTopics, SourceOptions};
use travmap_method::classifier::SvmModel;
use travmap_outputs::preflight::{
    InputFiles, Preflight, check_output_directory, check_output_file,
};
use travmap_run::DriveRun;
pub use travmap_run::opening::{
    Remark, open_selection, parse_frame_range, refuse_repeats, scan_rate_hz,
};

/// How a command ended: exit code 0, or 3 when it completed but skipped frames
/// (`--keep-going`), as the mcap CLI reports data loss.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    Complete,
    /// Frames skipped, and parts of inputs lost otherwise (a recording cut short).
    Incomplete {
        skipped: usize,
        lost: usize,
    },
}

/// The configuration: defaults, then a file, then `--set`s.
#[derive(Args)]
pub struct Settings {
    /// TOML file overriding configuration defaults (see `travmap config`).
    #[arg(long, help_heading = "Configuration")]
    config: Option<PathBuf>,
    /// Override one setting, e.g. --set grid.size_m=24 or --set integration.poses=tf
    /// (repeatable; text bare or quoted, other values as TOML).
    #[arg(
        long = "set",
        value_name = "SECTION.KEY=VALUE",
        help_heading = "Configuration"
    )]
    sets: Vec<String>,
    /// Where the scans' poses come from (integration.poses): the input's own (auto
    /// falls back to registration, with a notice), only /tf, only Odometry or a
    /// PoseStamped / PoseWithCovarianceStamped topic, estimated by registration, or
    /// none (each scan alone).
    #[arg(
        long,
        value_parser = ["auto", "tf", "odometry", "registration", "none"],
        help_heading = "Configuration"
    )]
    poses: Option<String>,
    /// The configuration once loaded, and where its model was named: the file is
    /// read once (a `<(...)` pipe can be read only once).
    #[arg(skip)]
    loaded: std::sync::OnceLock<(Config, Option<String>)>,
}

impl Settings {
    /// The effective configuration of a command that chooses no model: defaults,
    /// then the file, then each `--set`.
    pub fn load(&self) -> Result<Config> {
        self.load_with_model(None)
    }

    /// The effective configuration, with `model` (`--model`) as its
    /// `classifier.model`: said once when the file or a `--set` named another.
    pub fn load_with_model(&self, model: Option<&str>) -> Result<Config> {
        if let Some((config, _)) = self.loaded.get() {
            return Ok(config.clone());
        }
        let loaded = self.read(model)?;
        Ok(self.loaded.get_or_init(|| loaded).0.clone())
    }

    /// The model `config` (this one's, loaded) chooses, checked against it, and the
    /// name to report it by; its errors say where it was named, when a file or a
    /// `--set` named it.
    pub fn load_model(&self, config: &Config) -> Result<(SvmModel, String)> {
        let named_by = self
            .loaded
            .get()
            .and_then(|(_, named_by)| named_by.as_deref());
        SvmModel::load(&config.classifier.model, config).map_err(|error| match named_by {
            Some(named_by) => {
                anyhow::Error::from(error).context(format!("the model of {named_by}"))
            }
            None => error.into(),
        })
    }

    fn read(&self, model: Option<&str>) -> Result<(Config, Option<String>)> {
        let poses = self
            .poses
            .iter()
            .map(|poses| format!("integration.poses={poses}"));
        let assignments: Vec<String> = self.sets.iter().cloned().chain(poses).collect();
        let sources = ConfigSources {
            file: self.config.as_deref(),
            assignments: &assignments,
            model,
            ..Default::default()
        };
        // A configuration that cannot be used is a mistake in the command line.
        let assembled = sources.assemble().map_err(|e| match e {
            AssemblyError::File(error) => anyhow::Error::from(error),
            AssemblyError::Usage(message) => usage(message),
        })?;
        if let Some(said) = assembled.model_notice {
            notice(&said);
        }
        Ok((assembled.config, assembled.model_named_by))
    }
}

/// A mistake in the command line that clap's grammar cannot see (a `--set` typo,
/// two inputs where one is taken): exits 2, as clap's own usage errors do.
#[derive(Debug)]
pub struct UsageError(String);

impl std::fmt::Display for UsageError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for UsageError {}

pub fn usage(message: String) -> anyhow::Error {
    UsageError(message).into()
}

/// How a command reports.
#[derive(Args, Clone, Copy)]
pub struct Output {
    /// Machine-readable output.
    #[arg(long, help_heading = "Reporting")]
    pub json: bool,
    /// No progress bars and no chatter: only the answer (scores, a table, the
    /// configuration), notices and errors.
    #[arg(short, long, help_heading = "Reporting")]
    pub quiet: bool,
}

impl Output {
    /// A progress bar on a terminal (hidden otherwise or with `--quiet` / `--json`),
    /// and the stopwatch of the work it follows.
    pub fn progress(&self, length: u64, message: &str) -> Progress {
        let watch = Stopwatch::start();
        if self.quiet || self.json || !std::io::stderr().is_terminal() {
            return Progress {
                bar: ProgressBar::hidden(),
                watch,
            };
        }
        let bar = ProgressBar::new(length).with_message(message.to_string());
        bar.set_style(
            ProgressStyle::with_template("{msg:<24} [{wide_bar}] {pos}/{len} {elapsed}")
                .expect("valid template")
                .progress_chars("=> "),
        );
        Progress { bar, watch }
    }
}

/// A command's progress bar and the time since it started.
pub struct Progress {
    bar: ProgressBar,
    watch: Stopwatch,
}

impl std::ops::Deref for Progress {
    type Target = ProgressBar;

    fn deref(&self) -> &ProgressBar {
        &self.bar
    }
}

impl Progress {
    /// Clears the bar; returns the seconds the work took.
    pub fn finish(self) -> f64 {
        self.watch.elapsed_ms() * 1e-3
    }

    /// Runs `print` with the bar off the terminal, so that what it prints never
    /// shares a line with the bar (which is drawn again after it).
    pub fn print_beside<R>(&self, print: impl FnOnce() -> R) -> R {
        self.bar.suspend(print)
    }
}

/// A bar left drawn would start the next line printed (a result, or the error that
/// ended the work): it is cleared however the work ends.
impl Drop for Progress {
    fn drop(&mut self) {
        self.bar.finish_and_clear();
    }
}

/// [`Inputs`] of a command that reads one drive (`#[command(mut_arg("sequences",
/// one_input))]`): its help and usage say one.
pub fn one_input(arg: clap::Arg) -> clap::Arg {
    arg.num_args(1).action(clap::ArgAction::Set).value_name("INPUT").help(
        "A KITTI odometry / SemanticKITTI sequence directory, a recorded log (MCAP, ROS 1 bag, rosbag2 directory or .db3) or a folder of .pcd / .bin scans",
    )
}

/// Which of a log's LiDAR topics are read, and their calibrations.
#[derive(Args)]
pub struct Sensors {
    /// Log input: the PointCloud2 or LiDAR packet topic (needed when there are
    /// several). Repeated, the first topic's scans with the other sensors' clouds
    /// merged in (through /tf_static); `all` merges every cloud and packet topic.
    #[arg(long, help_heading = "Recorded logs and packets")]
    cloud_topic: Vec<String>,
    /// LiDAR packet input: the sensor's calibration, Velodyne's YAML
    /// (velodyne_pointcloud / nebula format) or Hesai's angle-correction CSV; the
    /// VLP-16, VLP-32C and Pandar XT32, XT16, XT32M, 40P, 64, QT64 and QT128 have built-in tables. With several
    /// packet topics, TOPIC=FILE gives one topic's (repeatable); a FILE alone is
    /// for every packet topic without its own.
    #[arg(
        long,
        value_name = "[TOPIC=]FILE",
        help_heading = "Recorded logs and packets"
    )]
    lidar_calibration: Vec<String>,
    /// Log input: the frame the LiDAR's points are in, when its clouds name none or
    /// the wrong one (a driver's empty or default frame_id), or its packets name none
    /// (an Ouster's custom sensor_frame, a capture). With several LiDAR topics,
    /// TOPIC=FRAME gives one topic's (repeatable); a FRAME alone is for every LiDAR
    /// topic without its own.
    #[arg(
        long,
        value_name = "[TOPIC=]FRAME",
        help_heading = "Recorded logs and packets"
    )]
    lidar_frame: Vec<String>,
}

impl Sensors {
    /// `options` reading these topics with these calibrations.
    pub fn log_options(&self, options: LogOptions) -> Result<LogOptions> {
        let (cloud_topic, merged_topics) = MergedTopics::from_arguments(&self.cloud_topic);
        Ok(LogOptions {
            cloud_topic,
            merged_topics,
            lidar_calibrations: LidarCalibrations::from_arguments(&self.lidar_calibration)
                .map_err(|problem| usage(format!("--lidar-calibration: {problem}")))?,
            lidar_frames: LidarFrames::from_arguments(&self.lidar_frame)
                .map_err(|problem| usage(format!("--lidar-frame: {problem}")))?,
            ..options
        })
    }

    /// The calibration files named (malformed flags are refused when the input is
    /// opened: here they name none).
    pub fn calibrations(&self) -> LidarCalibrations {
        LidarCalibrations::from_arguments(&self.lidar_calibration).unwrap_or_default()
    }
}

/// The drives a command reads, the frames of each, and how to read them.
#[derive(Args)]
pub struct Inputs {
    /// KITTI odometry / SemanticKITTI sequence directories (holding velodyne/, calib.txt,
    /// poses.txt, times.txt), recorded logs (MCAP, ROS 1 bag, rosbag2 directory or
    /// .db3) or folders of .pcd / .bin scans.
    #[arg(required = true)]
    pub sequences: Vec<PathBuf>,
    /// Frames to use: A..B (B excluded), A..=B, A.. or N. Default: all.
    #[arg(long, value_parser = parse_frame_range, help_heading = "Reading the inputs")]
    pub frames: Option<Range<usize>>,
    /// Folder-of-scans input: the scan rate, Hz, when the file names are not times
    /// (default 10).
    #[arg(long, value_name = "HZ", value_parser = parse_rate_hz, help_heading = "Reading the inputs")]
    rate: Option<f64>,
    #[command(flatten)]
    sensors: Sensors,
    /// MCAP input: the world frame poses are taken in (default: the root of the
    /// transform tree above the clouds' frame; the frame below it when the root is
    /// `utm` or `earth`).
    #[arg(long, help_heading = "Recorded logs and packets")]
    world_frame: Option<String>,
    /// MCAP input: the camera's Image or CompressedImage topic (needed when there are
    /// several with a CameraInfo).
    #[arg(long, help_heading = "Recorded logs and packets")]
    camera_topic: Option<String>,
    /// Recorded log input: the PoseStamped or PoseWithCovarianceStamped topic that
    /// poses the vehicle, when there are several and nothing else moves the clouds.
    #[arg(long, help_heading = "Recorded logs and packets")]
    pose_topic: Option<String>,
    #[command(flatten)]
    pub settings: Settings,
    #[command(flatten)]
    pub output: Output,
    /// Skip frames whose input is unreadable, report them, and exit with code 3
    /// (instead of stopping at the first one with code 1).
    #[arg(long, help_heading = "Reading the inputs")]
    keep_going: bool,
}

impl Inputs {
    /// How the inputs are read: the flags given, and the configuration's poses.
    pub fn source_options(&self, config: &Config) -> Result<SourceOptions> {
        Ok(SourceOptions {
            poses: config.integration.poses,
            keep_going: self.keep_going,
            log: self.sensors.log_options(LogOptions {
                world_frame: self.world_frame.clone(),
                camera_topic: self.camera_topic.clone(),
                pose_topic: self.pose_topic.clone(),
                ..Default::default()
            })?,
            rate_hz: self.rate,
            site_tile_m: None,
        })
    }

    /// Opens every input under `config` (the command's, loaded once);
    /// `read_images` decodes camera images into the frames.
    pub fn open(&self, config: &Config, read_images: bool) -> Result<Vec<DriveRun>> {
        let options = self.source_options(config)?;
        self.open_paths(&self.sequences, &options, config, read_images)
    }

    /// Opens `paths` (some of the inputs) as [`Inputs::open`] does, read as
    /// `options` say.
    pub fn open_paths(
        &self,
        paths: &[PathBuf],
        options: &SourceOptions,
        config: &Config,
        read_images: bool,
    ) -> Result<Vec<DriveRun>> {
        refuse_repeats(paths)?;
        paths
            .iter()
            .map(|path| {
                let mut selection =
                    open_selection(path, self.frames.clone(), options, read_images, &say)?;
                selection.survey(config, &|text: &str| notice(text))?;
                Ok(selection)
            })
            .collect()
    }

    /// Every file the command reads: the inputs, `--config`, `model` and the LiDAR
    /// calibrations.
    pub fn files(&self, model: Option<&Path>) -> InputFiles {
        let mut paths: Vec<&Path> = self.sequences.iter().map(PathBuf::as_path).collect();
        paths.extend(model);
        paths.extend(self.settings.config.as_deref());
        let calibrations = self.sensors.calibrations();
        paths.extend(calibrations.files());
        InputFiles::of(&paths)
    }

    /// Opens the one input of a command that takes one (clap has checked that it is
    /// one: [`one_input`]).
    pub fn open_one(&self, config: &Config, read_images: bool) -> Result<DriveRun> {
        self.open_one_as(&self.source_options(config)?, config, read_images)
    }

    /// Opens the one input, read as `options` say.
    pub fn open_one_as(
        &self,
        options: &SourceOptions,
        config: &Config,
        read_images: bool,
    ) -> Result<DriveRun> {
        Ok(self
            .open_paths(&self.sequences, options, config, read_images)?
            .remove(0))
    }
}

/// Before any work: the file `output` replaces none of `inputs` and can be written.
/// Temporary files that killed runs left beside it are removed, and said so.
pub fn check_output(output: &Path, inputs: &InputFiles) -> Result<()> {
    say_removed(check_output_file(output, inputs)?);
    Ok(())
}

fn say_removed(preflight: Preflight) {
    for stale in preflight.removed_stale {
        eprintln!(
            "removed {}, left by a travmap run that was killed",
            stale.display()
        );
    }
}

/// A note when `output`'s extension names another format than the `extension` it
/// is written in (`convert -o x.txt` writes an MCAP): written as asked, and said.
pub fn note_extension(output: &Path, extension: &str, format: &str) {
    let other = output
        .extension()
        .is_some_and(|e| !e.eq_ignore_ascii_case(extension));
    if other && !travmap_outputs::atomic::is_stream(output) {
        eprintln!(
            "note: {} is written as {format}, whatever its extension says (.{extension} is the usual one)",
            output.display()
        );
    }
}

/// Before any work: the directory `output` (one file per frame) is no input's.
pub fn check_output_dir(output: &Path, inputs: &InputFiles) -> Result<()> {
    say_removed(check_output_directory(output, inputs)?);
    Ok(())
}

/// Prints a remark of opening a drive on stderr, as `notice: ...` or `warning: ...`,
/// once however often the drive is opened.
pub fn say(remark: Remark, text: &str) {
    say_once(&format!("{}: {text}", remark.word()));
}

/// A scan rate in Hz: LiDARs spin at about 1 to 100 Hz; far outside that is a typo.
fn parse_rate_hz(text: &str) -> Result<f64, String> {
    scan_rate_hz(parse_finite(text)?).map_err(|expected| format!("{expected}, got {text}"))
}

/// A number that is not NaN or infinite.
pub fn parse_finite(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(value) if value.is_finite() => Ok(value),
        Ok(_) => Err(format!("a finite number, got {text}")),
        Err(_) => Err(format!("`{text}` is not a number")),
    }
}

/// The model a command predicts with.
#[derive(Args)]
pub struct ModelArg {
    /// The model: `road` (a car's road; the default), `offroad` (a robot that may
    /// also drive on grass, dirt and low vegetation), both compiled into travmap, or
    /// a model file (`./road` for a file of that name). Default: `classifier.model`.
    #[arg(long = "model", value_name = "MODEL")]
    pub model: Option<String>,
}

impl ModelArg {
    /// The command's effective configuration: `settings`, with this model as its
    /// `classifier.model` (the one every output records).
    pub fn config(&self, settings: &Settings) -> Result<Config> {
        settings.load_with_model(self.model.as_deref())
    }

    /// The model file chosen, if a file was: an input, which no output may replace.
    pub fn file(config: &Config) -> Option<PathBuf> {
        match &config.classifier.model {
            ModelChoice::File(path) => Some(path.clone()),
            ModelChoice::Embedded(_) => None,
        }
    }
}

/// The colours of a command's pictures.
#[derive(Args)]
pub struct PaletteArg {
    /// The pictures' colours: `safe` (blue traversable, orange not; apart for every
    /// common colour vision deficiency, the default) or `classic` (green and red).
    #[arg(long, value_enum, default_value_t = PaletteName::Safe)]
    palette: PaletteName,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum PaletteName {
    Safe,
    Classic,
}

impl PaletteArg {
    pub fn palette(&self) -> travmap_outputs::palette::Palette {
        use travmap_outputs::palette::Palette;
        match self.palette {
            PaletteName::Safe => Palette::SAFE,
            PaletteName::Classic => Palette::CLASSIC,
        }
    }
}

/// Frames the selections will hand on, for progress bars.
pub fn frame_count(selections: &[DriveRun]) -> u64 {
    selections
        .iter()
        .map(|s| s.source.frames_in(&s.frames).len() as u64)
        .sum()
}

/// Prints every skipped frame to stderr, once, and says how the command ended.
pub fn outcome(selections: &[DriveRun]) -> Outcome {
    let (mut skipped, mut lost) = (0, 0);
    for selection in selections {
        for skip in selection.source.skipped() {
            eprintln!(
                "skipped frame {} of {}: {}",
                skip.frame,
                selection.source.path().display(),
                skip.reason
            );
            skipped += 1;
        }
        for why in selection.source.lost() {
            eprintln!("lost: {why}");
            lost += 1;
        }
    }
    match (skipped, lost) {
        (0, 0) => Outcome::Complete,
        (skipped, lost) => Outcome::Incomplete { skipped, lost },
    }
}
