//! The library's one error type. Every variant names the file (or model / config)
//! and carries the numbers needed to see what went wrong: what was expected and
//! what was found, and where.

use std::path::PathBuf;

/// Errors from reading inputs, validating configuration and loading models.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("cannot read {path}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    #[error(
        "{output} would overwrite the input {input}: travmap never writes over what it reads; choose another -o"
    )]
    OutputIsInput { output: PathBuf, input: PathBuf },

    #[error("cannot write {output}: the directory {directory} does not exist")]
    NoOutputDirectory { output: PathBuf, directory: PathBuf },

    #[error("{output} is a directory; -o names the file to write")]
    OutputIsDirectory { output: PathBuf },

    #[error(
        "{output} is {what}; travmap writes regular files, character devices (/dev/null) and FIFOs"
    )]
    OutputIsSpecial { output: PathBuf, what: &'static str },

    #[error(
        "{output} is write-protected (mode {mode:o}): travmap does not replace it; remove it first or choose another -o"
    )]
    OutputWriteProtected { output: PathBuf, mode: u32 },

    #[error(
        "{output} is inside the input directory {input}: travmap never writes into what it reads (the next run would read it); choose another -o"
    )]
    OutputInsideInput { output: PathBuf, input: PathBuf },

    #[error("{first} and {second} name the same file; give each output its own")]
    SameOutputTwice { first: PathBuf, second: PathBuf },

    #[error("{first} and {second} are the same input; give each input once")]
    SameInputTwice { first: PathBuf, second: PathBuf },

    #[error("{path}: no space left on device (wrote {written_bytes}{} bytes); nothing was left behind", expected_bytes.map(|b| format!(" of {b}")).unwrap_or_default())]
    NoSpace {
        path: PathBuf,
        written_bytes: u64,
        expected_bytes: Option<u64>,
    },

    #[error("cannot write {path}: the writer thread stopped")]
    WriterStopped { path: PathBuf },

    #[error("cannot write {path}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    #[error("{path}: size {size_bytes} bytes is not a multiple of {record_bytes} ({what})")]
    RecordSize {
        path: PathBuf,
        size_bytes: u64,
        record_bytes: u64,
        what: &'static str,
    },

    #[error(
        "{path}: 0 bytes, no points: a scan file that was never written (--keep-going skips it)"
    )]
    EmptyScan { path: PathBuf },

    #[error("{path}: {message}")]
    Dataset { path: PathBuf, message: String },

    /// A map whose extent no dense image can hold: a pose or a point far from the
    /// rest, most likely (a 1e6 m jump once asked for 6.2 TB).
    #[error(
        "{what} would be {columns} x {rows} {unit}s ({width_m:.0} x {height_m:.0} m), more than the {limit} one image may hold: is a pose or a point far from the rest? ({hint})"
    )]
    MapTooLarge {
        what: &'static str,
        columns: u64,
        rows: u64,
        unit: &'static str,
        width_m: f64,
        height_m: f64,
        limit: u64,
        hint: &'static str,
    },

    /// An output of no frame is no result: a fleet script would count it as done.
    #[error("{path} is not written: no frame of {inputs} was read ({why})")]
    NothingWritten {
        path: PathBuf,
        inputs: String,
        /// The skipped frames in words (`travmap_io::nothing_read` builds it).
        why: String,
    },

    #[error("{path}: {labels} labels for {points} points in {scan}; the counts must be equal")]
    LabelCount {
        path: PathBuf,
        scan: PathBuf,
        labels: usize,
        points: usize,
    },

    #[error("{path}:{line}: {message}")]
    Parse {
        path: PathBuf,
        line: usize,
        message: String,
    },

    #[error("{path}: no `{key}:` line; expected a 3x4 matrix of 12 numbers{hint}")]
    MissingCalibration {
        path: PathBuf,
        key: &'static str,
        hint: &'static str,
    },

    #[error(
        "{path}: no pose for frame {frame} (the file has {lines} pose lines; frame N is line N+1)"
    )]
    MissingPose {
        path: PathBuf,
        frame: usize,
        lines: usize,
    },

    #[error("{path}: no timestamp for frame {frame} (the file has {lines} lines)")]
    MissingTime {
        path: PathBuf,
        frame: usize,
        lines: usize,
    },

    #[error("{path}: {message}")]
    Sequence { path: PathBuf, message: String },

    /// A file an option names (a model, a configuration, a calibration) that cannot
    /// be read, and why.
    #[error("{path}: {problem}")]
    OptionFile { path: PathBuf, problem: String },

    #[error("{path} does not exist")]
    InputMissing { path: PathBuf },

    #[error("{path} is {what}; {readable}")]
    UnsupportedInput {
        path: PathBuf,
        what: String,
        /// What travmap reads instead, as the format detection says it.
        readable: &'static str,
    },

    /// The container itself (MCAP, bag, sqlite, rosbag2 metadata): magic, records, chunks, CRCs, lengths (the text
    /// comes from the record checks in `io/mcap_records.rs`, the mcap crate,
    /// `io/bag.rs` or `io/rosbag2.rs` and carries the byte offsets).
    #[error("{path}: {problem}")]
    LogContainer { path: PathBuf, problem: String },

    #[error("{path}: {}{problem}", messages_before(*ordinal))]
    LogRecord {
        path: PathBuf,
        ordinal: usize,
        problem: String,
    },

    #[error(
        "{path}: the chunk at byte {offset} (log time {start_s:.3} to {end_s:.3} s) is damaged ({problem}): its messages are lost (--keep-going reads on past it{})",
        recover_hint(path)
    )]
    LogChunk {
        path: PathBuf,
        offset: usize,
        start_s: f64,
        end_s: f64,
        problem: String,
        /// The messages it lost, topic and log time, where the file lists them apart
        /// from the damage (an MCAP's message indexes): the frames they were.
        lost: Vec<(String, u64)>,
    },

    /// One message that does not read, in a container that reads on past it (a
    /// zstd frame of rosbag2's message compression).
    #[error("{0}")]
    LogMessageLost(LostMessage),

    #[error("{path}: unreadable from cloud {cloud} on: {problem}")]
    LogUnreadableFrom {
        path: PathBuf,
        cloud: usize,
        problem: String,
    },

    #[error("{path}: {problem}; {}", topics_said(cloud_topics, all_topics))]
    LogCloudTopic {
        path: PathBuf,
        problem: CloudTopicProblem,
        cloud_topics: Vec<String>,
        /// `topic (schema)` of every channel.
        all_topics: Vec<String>,
    },

    #[error(
        "{path}: --poses {requested}: {why}; --poses registration estimates poses from the scans, --poses none takes each scan alone"
    )]
    NoPose {
        path: PathBuf,
        requested: &'static str,
        why: String,
    },

    #[error("{path}: no transform from `{frame}` up to the world frame `{world_frame}`")]
    LogNotBelowWorld {
        path: PathBuf,
        frame: String,
        world_frame: String,
    },

    #[error("{path}: {topic} cloud {cloud}: {problem}")]
    LogCloud {
        path: PathBuf,
        topic: String,
        cloud: usize,
        problem: String,
    },

    #[error("{path}: {topic} at {stamp_ns} ns: {problem}")]
    LogImage {
        path: PathBuf,
        topic: String,
        stamp_ns: u64,
        problem: String,
    },

    #[error("{path}: {problem}")]
    LogCamera { path: PathBuf, problem: String },

    #[error("{path}: {problem}")]
    LogPoseTopic { path: PathBuf, problem: String },

    #[error("{path}: {problem}")]
    LogLidarFrame { path: PathBuf, problem: String },

    #[error("{path}: channel {topic} ({schema}), message at log time {log_time_ns} ns: {problem}")]
    UndecodableMessage {
        path: PathBuf,
        topic: String,
        schema: String,
        log_time_ns: u64,
        problem: String,
    },

    #[error(
        "{path}: channel {topic} ({schema}) has message encoding `{encoding}`; travmap reads `cdr` (ROS 2), `ros1` and, of Foxglove's schemas, `protobuf` and `json`"
    )]
    LogEncoding {
        path: PathBuf,
        topic: String,
        schema: String,
        encoding: String,
    },

    #[error(
        "{path}: frame {frame}: {problem}; scans that are not one continuous drive take --poses none (each scan alone), --keep-going skips the scans that do not register"
    )]
    Registration {
        path: PathBuf,
        frame: usize,
        problem: RegistrationError,
    },

    #[error("{path}: {problem}")]
    Transform {
        path: PathBuf,
        problem: TransformError,
    },

    #[error("invalid configuration: {0}")]
    Config(String),

    #[error("model {source_name}: {message}")]
    Model {
        source_name: String,
        message: String,
        /// The model's file, when it is one (not a compiled-in model).
        file: Option<std::path::PathBuf>,
    },

    #[error(
        "model {source_name}: format `{format}` version {version}; this travmap reads `{expected_format}` version {expected_version}"
    )]
    ModelVersion {
        source_name: String,
        /// The model's file, when it is one.
        file: Option<std::path::PathBuf>,
        format: String,
        version: String,
        expected_format: &'static str,
        expected_version: u32,
    },

    #[error(
        "model {model} was trained with {setting} = {model_value}, this run has {value}; run it with --set {setting}={model_value} (or train a model with these settings)"
    )]
    ModelSettings {
        model: String,
        setting: String,
        model_value: String,
        value: String,
    },

    #[error("training set: {0}")]
    Training(String),

    #[error("{path}: cannot adapt to this drive: {problem}")]
    Adaptation { path: PathBuf, problem: String },

    #[error("cannot start {threads} worker threads: {message}")]
    ThreadPool { threads: usize, message: String },

    #[error(
        "{selected} frames selected; the benchmark needs at least {needed} consecutive ones (a full integration window)"
    )]
    TooFewFrames { selected: usize, needed: usize },
}

/// Why a registration was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum Divergence {
    #[error("ICP did not converge")]
    NotConverged,
    /// The scan is not where the prediction put it, or not of this place.
    #[error("too few points match the map")]
    LostMap,
    /// No correspondence within the gate at the start supports a walk that long.
    #[error("the estimate moved the points farther than the gate")]
    JumpTooLarge,
    /// The correspondences do not fix all six degrees of freedom.
    #[error("the correspondences do not fix the pose")]
    Degenerate,
}

/// What one registration saw.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RegistrationStats {
    /// Points registered, after range filtering and downsampling.
    pub points: usize,
    /// Of those, with a map point within the gate at the last iteration.
    pub matched: usize,
    pub iterations: usize,
    /// The correspondence gate, three times the adaptive threshold, metres.
    pub gate_m: f64,
    /// RMS distance the points moved from the predicted pose to the estimate, metres.
    pub shift_m: f64,
}

impl std::fmt::Display for RegistrationStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} of {} points within the {:.2} m gate of a map point after {} ICP iterations; the estimate is {:.2} m from the prediction",
            self.matched, self.points, self.gate_m, self.iterations, self.shift_m
        )
    }
}

/// A scan that could not be registered: the odometry is as it was, but for the next
/// prediction, which spans the refused scan.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RegistrationError {
    #[error("{points} points left to register after filtering, at least {needed} needed")]
    TooFewPoints { points: usize, needed: usize },
    #[error("scan registration diverged: {cause} ({seen})")]
    Diverged {
        cause: Divergence,
        seen: RegistrationStats,
    },
}

/// Why a pose could not be had from the tree.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TransformError {
    #[error(
        "no transform {parent} -> {child} near {stamp_ns} ns (recorded {first_ns}..{last_ns} ns)"
    )]
    NoSample {
        parent: String,
        child: String,
        stamp_ns: u64,
        first_ns: u64,
        last_ns: u64,
    },
    #[error("the transform tree above {frame} has a cycle")]
    Cycle { frame: String },
    #[error(
        "transform ({x}, {y}, {z}), rotation (w {qw}, x {qx}, y {qy}, z {qz}): expected finite values and a unit quaternion"
    )]
    NotRigid {
        x: f64,
        y: f64,
        z: f64,
        qw: f64,
        qx: f64,
        qy: f64,
        qz: f64,
    },
}

/// Why no PointCloud2 topic could be chosen.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum CloudTopicProblem {
    NotFound(String),
    None,
    Several,
}

impl std::fmt::Display for CloudTopicProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CloudTopicProblem::NotFound(topic) => {
                write!(f, "no PointCloud2 messages on topic {topic}")
            }
            CloudTopicProblem::None => {
                write!(f, "no PointCloud2 topic, nor LiDAR packets travmap reads")
            }
            CloudTopicProblem::Several => {
                write!(
                    f,
                    "several PointCloud2 topics, choose one with --cloud-topic (or merge several LiDARs: --cloud-topic all, or the topics one by one)"
                )
            }
        }
    }
}

/// A log's topics for [`Error::LogCloudTopic`]: its cloud topics when it has any
/// (an empty list says nothing), then every topic.
fn topics_said(cloud_topics: &[String], all_topics: &[String]) -> String {
    let all = format!("all topics: [{}]", all_topics.join(", "));
    match cloud_topics.is_empty() {
        true => all,
        false => format!(
            "PointCloud2 and LiDAR topics: [{}]; {all}",
            cloud_topics.join(", ")
        ),
    }
}

/// Result with the library's error type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// A message that does not read ([`Error::LogMessageLost`]), kept as data so that
/// the pass that needs it can report it when the pass that met it cannot.
#[derive(Clone, Debug, thiserror::Error)]
#[error(
    "{}: message {ordinal} (on {topic}, log time {:.3} s) is damaged ({problem}): it is lost (--keep-going reads on past it)",
    path.display(),
    *log_time_ns as f64 * 1e-9
)]
pub struct LostMessage {
    pub path: PathBuf,
    pub ordinal: usize,
    pub topic: String,
    pub log_time_ns: u64,
    pub problem: String,
}

impl Error {
    /// A stretch of a log lost (a damaged chunk or message) that reading goes on
    /// past: with `--keep-going` a skip, not the end.
    pub fn is_lost_stretch(&self) -> bool {
        matches!(self, Error::LogChunk { .. } | Error::LogMessageLost(_))
    }

    /// A model's error said of `path`, the file the model was read from.
    pub fn of_model_file(mut self, path: &std::path::Path) -> Self {
        if let Error::Model { file, .. } | Error::ModelVersion { file, .. } = &mut self {
            *file = Some(path.to_path_buf());
        }
        self
    }

    /// The file the error is about, when there is one (for `--json` errors).
    pub fn path(&self) -> Option<&std::path::Path> {
        match self {
            Error::OptionFile { path, .. }
            | Error::Io { path, .. }
            | Error::NoSpace { path, .. }
            | Error::WriterStopped { path, .. }
            | Error::Write { path, .. }
            | Error::RecordSize { path, .. }
            | Error::EmptyScan { path, .. }
            | Error::Dataset { path, .. }
            | Error::NothingWritten { path, .. }
            | Error::LabelCount { path, .. }
            | Error::Parse { path, .. }
            | Error::MissingCalibration { path, .. }
            | Error::MissingPose { path, .. }
            | Error::MissingTime { path, .. }
            | Error::Sequence { path, .. }
            | Error::InputMissing { path }
            | Error::UnsupportedInput { path, .. }
            | Error::LogContainer { path, .. }
            | Error::LogRecord { path, .. }
            | Error::LogChunk { path, .. }
            | Error::LogUnreadableFrom { path, .. }
            | Error::LogCloudTopic { path, .. }
            | Error::NoPose { path, .. }
            | Error::LogNotBelowWorld { path, .. }
            | Error::LogCloud { path, .. }
            | Error::LogImage { path, .. }
            | Error::LogCamera { path, .. }
            | Error::LogPoseTopic { path, .. }
            | Error::LogLidarFrame { path, .. }
            | Error::UndecodableMessage { path, .. }
            | Error::LogEncoding { path, .. }
            | Error::Registration { path, .. }
            | Error::Transform { path, .. }
            | Error::Adaptation { path, .. }
            | Error::SameInputTwice { second: path, .. } => Some(path),
            Error::Model { file, .. } | Error::ModelVersion { file, .. } => file.as_deref(),
            Error::OutputIsInput { output, .. }
            | Error::OutputIsDirectory { output }
            | Error::OutputIsSpecial { output, .. }
            | Error::OutputWriteProtected { output, .. }
            | Error::OutputInsideInput { output, .. }
            | Error::SameOutputTwice { first: output, .. }
            | Error::NoOutputDirectory { output, .. } => Some(output),
            Error::LogMessageLost(lost) => Some(&lost.path),
            _ => None,
        }
    }

    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    pub fn parse(path: impl Into<PathBuf>, line: usize, message: impl Into<String>) -> Self {
        Error::Parse {
            path: path.into(),
            line,
            message: message.into(),
        }
    }
}

thread_local! {
    static CONTAINING_PANICS: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
    /// Where the last contained panic on this thread happened.
    static CONTAINED_AT: std::cell::RefCell<String> = const { std::cell::RefCell::new(String::new()) };
}

/// Runs `f`, turning a panic inside it into `Err(message and location)`, printed by
/// nobody.
///
/// For third-party readers that panic on malformed input instead of returning an
/// error (the `parquet` crate does, on corrupt metadata: apache/arrow-rs#9742). The
/// panic hook installed here stays silent only on a thread inside this function,
/// so panics anywhere else still print, and still abort under a fuzzer.
pub fn contain_panics<T>(f: impl FnOnce() -> T) -> std::result::Result<T, String> {
    static QUIET_HOOK: std::sync::Once = std::sync::Once::new();
    QUIET_HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if CONTAINING_PANICS.with(|c| c.get()) {
                let at = info.location().map(|l| {
                    // A registry path from the crate's name on: parquet-60.1.0/src/...
                    let file = l.file();
                    let from_crate = file
                        .find(".crates.io-")
                        .and_then(|i| file[i..].find('/').map(|j| &file[i + j + 1..]));
                    format!("{}:{}", from_crate.unwrap_or(file), l.line())
                });
                CONTAINED_AT.with(|c| *c.borrow_mut() = at.unwrap_or_default());
            } else {
                previous(info);
            }
        }));
    });
    let outer = CONTAINING_PANICS.with(|c| c.replace(true));
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    CONTAINING_PANICS.with(|c| c.set(outer));
    result.map_err(|payload| {
        let message = payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic without a message".into());
        let at = CONTAINED_AT.with(|c| std::mem::take(&mut *c.borrow_mut()));
        format!("{message}, at {at}")
    })
}

/// Where in a log reading stopped, in words a user can check against `mcap cat`:
/// the count of messages read before the problem (none: nothing to say).
/// What rewrites a file with a damaged chunk, when a common tool does.
fn recover_hint(path: &std::path::Path) -> &'static str {
    match path.extension().is_some_and(|e| e == "mcap") {
        true => "; `mcap recover` rewrites what can be read",
        false => "",
    }
}

fn messages_before(ordinal: usize) -> String {
    match ordinal {
        0 => String::new(),
        1 => "after 1 message: ".into(),
        n => format!("after {n} messages: "),
    }
}
