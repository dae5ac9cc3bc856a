//! What commands print: the `--json` records ([`travmap_run::report`] builds them),
//! the `wrote ...` line, counts in words and notices.

use std::path::Path;

use anyhow::Result;
use travmap_core::Config;
use travmap_method::classifier::SvmModel;
use travmap_run::DriveRun;
use travmap_run::report::json::{error_record, frame_record, summary_record};
pub use travmap_run::report::json::{
    input_json, model_json, path_text, setting_word, with_summary,
};
use travmap_run::scoring::evaluation::EvaluationReport;
use travmap_run::scoring::remarks::{FitRemedies, drive_notices};
pub use travmap_run::scoring::remarks::{counted, fit_said, other_rule_said};

/// Prints a `frame` record ([`travmap_run::report::json`]).
pub fn print_json_frame(fields: serde_json::Value) -> Result<()> {
    print_json_line(&frame_record(fields))
}

/// Prints the `summary` record of `command` over `selections`.
pub fn print_json_summary(
    command: &str,
    selections: &[DriveRun],
    fields: serde_json::Value,
) -> Result<()> {
    print_json_line(&summary_record(command, selections, fields))
}

/// The line a command that wrote an MCAP ends with:
/// `wrote PATH (N frames, CONTENTS, M MB, R frames/s)`.
pub fn print_wrote(path: &Path, frames: usize, contents: &str, bytes: u64, seconds: f64) {
    println!(
        "wrote {} ({}, {contents}, {:.1} MB, {:.1} frames/s)",
        path.display(),
        counted(frames, "frame"),
        bytes as f64 / 1e6,
        frames as f64 / seconds
    );
}

/// An error under `--json`: one `error` record on stderr.
pub fn print_json_error(message: &str, file: Option<&Path>, exit_code: i32) {
    eprintln!("{}", error_record(message, file, exit_code));
}

fn print_json_line(value: &serde_json::Value) -> Result<()> {
    use std::io::Write;
    writeln!(std::io::stdout().lock(), "{value}")?;
    Ok(())
}

/// Says on stderr, in every mode (`-q`, `--json` too), what the run found of the
/// drives ([`drive_notices`]).
pub fn notice_drives(
    report: &EvaluationReport,
    model: &SvmModel,
    config: &Config,
    remedies: FitRemedies,
) {
    for said in drive_notices(report, model, config, remedies) {
        notice(&said);
    }
}

/// Prints `notice: TEXT` on stderr, unless this run said it already: a drive read
/// twice (adapted to, then scored) says what it found once.
pub fn notice(text: &str) {
    say_once(&format!("notice: {text}"));
}

/// Prints `line` on stderr unless this run printed it already.
pub fn say_once(line: &str) {
    static SAID: std::sync::Mutex<std::collections::BTreeSet<String>> =
        std::sync::Mutex::new(std::collections::BTreeSet::new());
    let mut said = SAID.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    if said.insert(line.to_string()) {
        eprintln!("{line}");
    }
}
