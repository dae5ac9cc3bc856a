//! `travmap bench --tools`, outside the binary's own code (the `bench-tools`
//! feature): the subcommands themselves (`convert`, `annotate`,
//! `dataset`, `adapt`) run as child processes of this executable on the bench's input, on one
//! thread and on all cores; frames/s, MB/s written, times real time and the child's
//! peak memory. Unlike the method table these include the disk, decoding,
//! compression and writing. On a log of LiDAR packets the convert row is the decode
//! row: packets cut into scans and written as PointCloud2.

use std::ffi::OsString;
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use serde::Serialize;
use travmap_run::DriveRun;
use travmap_run::scoring::evaluation::Spread;

mod child_runs;

use child_runs::{ChildRun, TemporaryDirectory, run_child, synced_write_seconds};

/// How the bench's input is read, as the flags a child travmap takes.
#[derive(Clone, Debug, Default)]
pub struct ChildFlags {
    /// The bench's `--frames`, when given.
    pub frames: Option<std::ops::Range<usize>>,
    /// The LiDAR topics, calibrations and frames (all a log's `convert` takes).
    pub sensors: Vec<OsString>,
    /// Everything that says how the input is read: the sensors' flags, the world
    /// frame, camera and pose topics, the scan rate and the configuration.
    pub reading: Vec<OsString>,
    /// The configuration alone (for the MCAP the convert row wrote).
    pub settings: Vec<OsString>,
}

/// Which file a row's tool reads.
#[derive(Clone, Copy)]
enum ToolInput {
    /// The bench's input, with its `--frames`.
    Given,
    /// The MCAP the `convert` row wrote from the bench's input.
    Converted,
}

/// One row of the tools table: a subcommand, what it reads and what it writes.
struct ToolSpec {
    tool: &'static str,
    input: ToolInput,
    /// `annotate`: whether the input's messages are copied through
    /// (`--no-passthrough` when not).
    passthrough: Option<bool>,
    /// The file it writes, in the temporary directory.
    output_name: &'static str,
}

/// The inputs `convert` reads (a log converted whole).
const CONVERTIBLE: [&str; 3] = ["kitti", "log", "packets"];

/// The file the `convert` row writes and the `Converted` rows read.
const CONVERTED: &str = "converted.mcap";

/// The rows, in order: `convert` first, since the MCAP-input rows read what it wrote.
const ROWS: [ToolSpec; 7] = [
    ToolSpec {
        tool: "convert",
        input: ToolInput::Given,
        passthrough: None,
        output_name: CONVERTED,
    },
    ToolSpec {
        tool: "annotate",
        input: ToolInput::Given,
        passthrough: Some(true),
        output_name: "annotated.mcap",
    },
    ToolSpec {
        tool: "annotate",
        input: ToolInput::Given,
        passthrough: Some(false),
        output_name: "annotated.mcap",
    },
    ToolSpec {
        tool: "annotate",
        input: ToolInput::Converted,
        passthrough: Some(true),
        output_name: "annotated.mcap",
    },
    ToolSpec {
        tool: "annotate",
        input: ToolInput::Converted,
        passthrough: Some(false),
        output_name: "annotated.mcap",
    },
    ToolSpec {
        tool: "dataset",
        input: ToolInput::Given,
        passthrough: None,
        output_name: "cells.parquet",
    },
    // The self-supervised adaptation: a pass over the drive on the training grid,
    // then the fits; its MB/s are of the model file.
    ToolSpec {
        tool: "adapt",
        input: ToolInput::Given,
        passthrough: None,
        output_name: "adapted.json",
    },
];

impl ToolSpec {
    /// Whether this row converts the bench's input (of `given_kind`), a log, whole.
    fn converts_whole_log(&self, given_kind: &str) -> bool {
        let log = matches!(given_kind, "log" | "packets");
        self.tool == "convert" && matches!(self.input, ToolInput::Given) && log
    }

    /// The file this row's tool reads (`given` of `given_kind`, or the MCAP the
    /// convert row wrote), or why the row is skipped.
    fn input<'a>(
        &self,
        given: &'a Path,
        given_kind: &str,
        converted: Option<&'a Path>,
    ) -> std::result::Result<&'a Path, String> {
        match self.input {
            ToolInput::Given if self.tool == "convert" && !CONVERTIBLE.contains(&given_kind) => {
                Err(format!(
                    "convert is timed on KITTI input and logs, not on {given_kind} input"
                ))
            }
            ToolInput::Given => Ok(given),
            ToolInput::Converted => converted
                .ok_or_else(|| "needs the MCAP the convert row writes (KITTI input)".into()),
        }
    }

    /// The command line of this row's tool reading `input` into `output`, quiet:
    /// the bench's `--frames` for its own input (not a log's convert: a log is
    /// converted whole); the configuration and how to read logs for every tool that
    /// takes them (`convert` only the LiDAR topics and calibrations); the model for
    /// `annotate`, and as the prior for `adapt`.
    fn arguments(
        &self,
        input: &Path,
        output: &Path,
        inputs: &ChildFlags,
        given_kind: &str,
        model: Option<&Path>,
    ) -> Vec<OsString> {
        let mut arguments: Vec<OsString> =
            vec![self.tool.into(), input.into(), "-o".into(), output.into()];
        arguments.extend(self.reading_arguments(inputs, given_kind, model));
        // The row times the work: a bench's few frames hold fewer footprint cells
        // than adapt asks of a drive before it trusts one.
        if self.tool == "adapt" {
            arguments.extend(["--set".into(), "adapt.min_footprint_cells=0".into()]);
        }
        if self.passthrough == Some(false) {
            arguments.push("--no-passthrough".into());
        }
        arguments
    }

    /// `travmap run` on this row's input, frames, configuration and model: the method
    /// alone, writing nothing (the row's roofline); None for convert, which runs no
    /// method.
    fn method_arguments(
        &self,
        input: &Path,
        inputs: &ChildFlags,
        given_kind: &str,
        model: Option<&Path>,
    ) -> Option<Vec<OsString>> {
        if self.tool == "convert" {
            return None;
        }
        let mut arguments: Vec<OsString> = vec!["run".into(), input.into()];
        arguments.extend(self.reading_arguments(inputs, given_kind, model));
        Some(arguments)
    }

    /// What the row's tool and its method run share: quiet, the frames, how to read
    /// the input, and the model.
    fn reading_arguments(
        &self,
        inputs: &ChildFlags,
        given_kind: &str,
        model: Option<&Path>,
    ) -> Vec<OsString> {
        let whole_log = self.converts_whole_log(given_kind);
        let mut arguments: Vec<OsString> = vec!["-q".into()];
        if let (ToolInput::Given, Some(frames), false) = (self.input, &inputs.frames, whole_log) {
            let end = match frames.end {
                usize::MAX => String::new(),
                end => end.to_string(),
            };
            let range = format!("{}..{end}", frames.start);
            arguments.extend(["--frames".into(), range.into()]);
        }
        match (self.tool, self.input) {
            ("convert", _) if whole_log => arguments.extend(inputs.sensors.iter().cloned()),
            ("convert", _) => {}
            (_, ToolInput::Given) => arguments.extend(inputs.reading.iter().cloned()),
            (_, ToolInput::Converted) => arguments.extend(inputs.settings.iter().cloned()),
        }
        if let ("annotate" | "adapt", Some(model)) = (self.tool, model) {
            arguments.extend(["--model".into(), model.into()]);
        }
        arguments
    }
}

/// Seconds as the milliseconds every `--json` duration is.
fn seconds_as_ms<S: serde::Serializer, T: Copy + Into<Option<f64>>>(
    seconds: &T,
    serializer: S,
) -> Result<S::Ok, S::Error> {
    use serde::Serialize;
    (*seconds).into().map(|s| s * 1e3).serialize(serializer)
}

/// A tool on one thread count: medians over the repeats.
#[derive(Serialize)]
pub struct ToolTiming {
    /// `RAYON_NUM_THREADS` of the child.
    threads: usize,
    #[serde(serialize_with = "seconds_as_ms", rename = "wall_ms")]
    wall_s: f64,
    /// Selected frames per second of wall time (the child's start to its exit).
    frames_per_second: f64,
    /// Bytes of the output file (1 MB = 10^6 bytes) per second of wall time.
    megabytes_per_second: f64,
    /// The frames' recorded time per second of wall time; None without stamps.
    recorded_s_per_wall_s: Option<f64>,
    /// The child's peak resident set (`ru_maxrss`), MiB; None where the platform
    /// does not report it.
    peak_rss_mib: Option<f64>,
    /// The roofline: `travmap run` on the same frames and threads, the method alone
    /// (None for convert), ...
    #[serde(serialize_with = "seconds_as_ms", rename = "method_ms")]
    method_s: Option<f64>,
    /// ... and the wall time over the larger of that and the row's
    /// `synced_write_s`.
    roofline_ratio: Option<f64>,
}

/// A row's measurement, or why it was not taken.
#[derive(Serialize)]
#[serde(untagged)]
pub enum ToolOutcome {
    Timed {
        one_thread: ToolTiming,
        all_cores: ToolTiming,
        /// all_cores / one_thread frames per second.
        speedup: f64,
    },
    Skipped {
        skipped: String,
    },
}

/// One row of the tools table, as `--json` reports it.
#[derive(Serialize)]
pub struct ToolRow {
    tool: &'static str,
    /// What the tool read: `kitti`, `log` or `scans` (the bench's input), or `mcap`
    /// (the file the convert row wrote from it).
    input: &'static str,
    /// `annotate`: whether the input's messages were copied through.
    passthrough: Option<bool>,
    /// Frames the tool read: the bench's selection (a log's every frame for
    /// convert), and the time they span as recorded.
    frames: usize,
    #[serde(serialize_with = "seconds_as_ms", rename = "recorded_ms")]
    recorded_s: Option<f64>,
    /// Seconds `dd conv=fsync` took to write the tool's output size to the same
    /// folder: the disk's part of the roofline.
    #[serde(serialize_with = "seconds_as_ms", rename = "synced_write_ms")]
    synced_write_s: Option<f64>,
    #[serde(flatten)]
    outcome: ToolOutcome,
}

impl ToolRow {
    /// How the table names the row: the command, less its paths.
    fn label(&self) -> String {
        let flag = match self.passthrough {
            Some(false) => " --no-passthrough",
            _ => "",
        };
        format!("{} {}{flag}", self.tool, self.input)
    }
}

/// Every row of the tools table (convert, annotate, dataset, adapt) on `selection`
/// (read as `inputs` say), each run `repeats` times on one thread and on all cores;
/// `model` goes to `annotate`.
pub fn bench_tools(
    inputs: &ChildFlags,
    selection: &DriveRun,
    model: Option<&Path>,
    repeats: usize,
) -> Result<Vec<ToolRow>> {
    let executable = std::env::current_exe().context("cannot find travmap's own executable")?;
    let all_cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let directory = TemporaryDirectory::create()?;
    let given = selection.source.path();
    let given_kind = selection.source.kind().name();
    let source = &selection.source;
    let selected = source.frames_in(&selection.frames);
    let mut converted: Option<PathBuf> = None;
    let mut rows = Vec::new();
    for spec in &ROWS {
        let output = directory.0.join(spec.output_name);
        let frames = match spec.converts_whole_log(given_kind) {
            true => source.frames(),
            false => selected.clone(),
        };
        let recorded_s = source.recorded_seconds(&frames);
        let mut synced_write_s = None;
        let outcome = match spec.input(given, given_kind, converted.as_deref()) {
            Err(skipped) => ToolOutcome::Skipped { skipped },
            Ok(input) => {
                let arguments = spec.arguments(input, &output, inputs, given_kind, model);
                let method = spec.method_arguments(input, inputs, given_kind, model);
                let runs = |arguments: &[OsString], threads, output| {
                    (0..repeats.max(1))
                        .map(|_| run_child(&executable, arguments, threads, output))
                        .collect::<Result<Vec<_>>>()
                };
                let median = |values: Vec<f64>| Spread::of(&values).median;
                let mut time = |threads| -> Result<ToolTiming> {
                    let tool_runs = runs(&arguments, threads, Some(&output))?;
                    let bytes = median(tool_runs.iter().map(|r| r.output_bytes as f64).collect());
                    if synced_write_s.is_none() {
                        synced_write_s = synced_write_seconds(&directory.0, bytes as u64);
                    }
                    let method_s = match &method {
                        Some(method) => {
                            let method_runs = runs(method, threads, None)?;
                            Some(median(method_runs.iter().map(|r| r.wall_s).collect()))
                        }
                        None => None,
                    };
                    let timing = ToolTiming::of(&tool_runs, threads, frames.len(), recorded_s);
                    Ok(timing.against(method_s, synced_write_s))
                };
                let (one_thread, all_cores) = (time(1)?, time(all_cores)?);
                ToolOutcome::Timed {
                    speedup: all_cores.frames_per_second / one_thread.frames_per_second,
                    one_thread,
                    all_cores,
                }
            }
        };
        let input_kind = match spec.input {
            ToolInput::Given => given_kind,
            ToolInput::Converted => "mcap",
        };
        // The MCAP rows read KITTI converted; a log converted is the log again.
        if spec.tool == "convert" && given_kind == "kitti" {
            converted = matches!(outcome, ToolOutcome::Timed { .. }).then_some(output);
        }
        rows.push(ToolRow {
            tool: spec.tool,
            input: input_kind,
            passthrough: spec.passthrough,
            frames: frames.len(),
            recorded_s,
            synced_write_s,
            outcome,
        });
    }
    Ok(rows)
}

/// The tools table of `rows` on `input` (as a person reads it): one line per row, 1
/// thread and all cores side by side.
pub fn print_tools_table(
    out: &mut impl Write,
    input: &str,
    rows: &[ToolRow],
    repeats: usize,
) -> Result<()> {
    let all_cores = rows
        .iter()
        .find_map(|row| match &row.outcome {
            ToolOutcome::Timed { all_cores, .. } => Some(format!("{} thr", all_cores.threads)),
            ToolOutcome::Skipped { .. } => None,
        })
        .unwrap_or_else(|| "all".into());
    let frames = (rows.iter().map(|row| row.frames)).min().unwrap_or(0);
    writeln!(
        out,
        "tools on {input} ({frames} frames; a log's convert: all of them; each a child process; median of {repeats} runs; wall time from start to exit; x real time: recorded time / wall time; the child's peak RSS; roofline on {all_cores}: `travmap run` of the same frames, the method alone, and `dd conv=fsync` of as many bytes into the same folder, x roofline the wall time over the larger):"
    )?;
    writeln!(
        out,
        "{:<34} {:>17} {:>17} {:>17} {:>17} {:>7} {:>26}",
        "tool input",
        "frames/s",
        "x real time",
        "MB/s written",
        "peak RSS MiB",
        "speedup",
        "roofline"
    )?;
    writeln!(
        out,
        "{:<34} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>7} {:>8} {:>8} {:>8}",
        "",
        "1 thr",
        all_cores,
        "1 thr",
        all_cores,
        "1 thr",
        all_cores,
        "1 thr",
        all_cores,
        "",
        "run s",
        "fsync s",
        "x"
    )?;
    let figure = |value: Option<f64>, decimals: usize| {
        value.map_or("-".to_string(), |v| format!("{v:.decimals$}"))
    };
    for row in rows {
        let label = row.label();
        match &row.outcome {
            ToolOutcome::Timed {
                one_thread,
                all_cores,
                speedup,
            } => writeln!(
                out,
                "{label:<34} {:>8.1} {:>8.1} {:>8} {:>8} {:>8.1} {:>8.1} {:>8} {:>8} {:>6.2}x {:>8} {:>8} {:>8}",
                one_thread.frames_per_second,
                all_cores.frames_per_second,
                figure(one_thread.recorded_s_per_wall_s, 1),
                figure(all_cores.recorded_s_per_wall_s, 1),
                one_thread.megabytes_per_second,
                all_cores.megabytes_per_second,
                figure(one_thread.peak_rss_mib, 0),
                figure(all_cores.peak_rss_mib, 0),
                speedup,
                figure(all_cores.method_s, 2),
                figure(row.synced_write_s, 2),
                figure(all_cores.roofline_ratio, 2),
            )?,
            ToolOutcome::Skipped { skipped } => writeln!(out, "{label:<34} skipped: {skipped}")?,
        }
    }
    Ok(())
}

impl ToolTiming {
    /// Medians of `runs` on `threads` threads, each over `frames` frames recorded
    /// over `recorded_s`.
    fn of(runs: &[ChildRun], threads: usize, frames: usize, recorded_s: Option<f64>) -> Self {
        let median = |values: Vec<f64>| Spread::of(&values).median;
        let wall_s = median(runs.iter().map(|r| r.wall_s).collect());
        let output_bytes = median(runs.iter().map(|r| r.output_bytes as f64).collect());
        let rss: Vec<f64> = runs.iter().filter_map(|r| r.peak_rss_mib).collect();
        Self {
            threads,
            wall_s,
            frames_per_second: frames as f64 / wall_s,
            megabytes_per_second: output_bytes * 1e-6 / wall_s,
            recorded_s_per_wall_s: recorded_s.map(|recorded_s| recorded_s / wall_s),
            peak_rss_mib: (!rss.is_empty()).then(|| median(rss)),
            method_s: None,
            roofline_ratio: None,
        }
    }

    /// This timing held against its roofline: the method alone (`method_s`) and the
    /// synced write of its output (`synced_write_s`), whichever takes longer.
    fn against(self, method_s: Option<f64>, synced_write_s: Option<f64>) -> Self {
        let roofline_s = method_s.into_iter().chain(synced_write_s).reduce(f64::max);
        Self {
            method_s,
            roofline_ratio: roofline_s.map(|roofline_s| self.wall_s / roofline_s),
            ..self
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flags(texts: &[&str]) -> Vec<OsString> {
        texts.iter().map(OsString::from).collect()
    }

    /// `bench seq --frames 2..=4 --set grid.size_m=16 --cloud-topic /points`, as the
    /// command line hands it on (its own test: `src/cli/mod.rs`).
    fn given() -> ChildFlags {
        ChildFlags {
            frames: Some(2..5),
            sensors: flags(&["--cloud-topic", "/points"]),
            reading: flags(&["--cloud-topic", "/points", "--set", "grid.size_m=16"]),
            settings: flags(&["--set", "grid.size_m=16"]),
        }
    }

    #[test]
    fn each_row_gets_the_flags_its_tool_takes() {
        let inputs = given();
        let command = |row: usize, input: &str| {
            ROWS[row]
                .arguments(
                    Path::new(input),
                    Path::new("out"),
                    &inputs,
                    "kitti",
                    Some(Path::new("m.json")),
                )
                .iter()
                .map(|a| a.to_string_lossy().into_owned())
                .collect::<Vec<_>>()
                .join(" ")
        };
        assert_eq!(command(0, "seq"), "convert seq -o out -q --frames 2..5");
        let open_ended = ChildFlags {
            frames: Some(3..usize::MAX),
            ..ChildFlags::default()
        };
        let arguments = ROWS[0].arguments(
            Path::new("seq"),
            Path::new("out"),
            &open_ended,
            "kitti",
            None,
        );
        assert_eq!(arguments[5..], ["--frames", "3.."]);
        // A log is converted whole, with its LiDAR topics and calibrations.
        let log = ROWS[0].arguments(
            Path::new("d.mcap"),
            Path::new("out"),
            &inputs,
            "packets",
            None,
        );
        assert_eq!(log[4..], ["-q", "--cloud-topic", "/points"]);
        assert_eq!(
            command(2, "seq"),
            "annotate seq -o out -q --frames 2..5 --cloud-topic /points --set grid.size_m=16 --model m.json --no-passthrough"
        );
        // convert wrote only the selected frames.
        assert_eq!(
            command(3, "c.mcap"),
            "annotate c.mcap -o out -q --set grid.size_m=16 --model m.json"
        );
        assert_eq!(
            command(5, "seq"),
            "dataset seq -o out -q --frames 2..5 --cloud-topic /points --set grid.size_m=16"
        );
        assert_eq!(
            command(6, "seq"),
            "adapt seq -o out -q --frames 2..5 --cloud-topic /points --set grid.size_m=16 --model m.json --set adapt.min_footprint_cells=0"
        );
    }
}
