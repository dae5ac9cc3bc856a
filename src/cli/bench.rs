//! `travmap bench`: per-stage latency (median, p95) and throughput on 1 thread and
//! all cores; with `--tools`, the subcommands' own throughput (`travmap-bench`,
//! the `bench-tools` feature).

use std::io::Write;

use anyhow::Result;
use clap::Args;
use serde_json::json;
use travmap_run::scoring::benchmark::benchmark;

use super::{Inputs, ModelArg, Outcome, model_json, outcome, print_json_summary, with_summary};

/// Per-stage latency (median, p95) and throughput on 1 thread and all cores.
#[derive(Args)]
#[command(mut_arg("sequences", super::one_input))]
#[command(
    after_long_help = "Examples (SEQ: a KITTI sequence folder, e.g. ../shared/data/semantickitti-00/sequences/00):\n  travmap bench SEQ --repeats 30\n  travmap bench SEQ --tools --json"
)]
pub struct BenchArgs {
    #[command(flatten)]
    inputs: Inputs,
    #[command(flatten)]
    model: ModelArg,
    /// Times each measurement is repeated.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u16).range(1..=1000))]
    repeats: u16,
    /// Also time the subcommands (convert, annotate, dataset, adapt) on this input, each
    /// as a child process on 1 thread and on all cores: frames/s, MB/s, peak RSS.
    #[arg(long)]
    tools: bool,
    /// With --tools: runs of each tool per thread count (the median is reported).
    #[arg(long, default_value_t = 3, requires = "tools", value_parser = clap::value_parser!(u16).range(1..=100))]
    tool_repeats: u16,
}

pub fn bench(args: BenchArgs) -> Result<Outcome> {
    let config = &args.inputs.settings.load()?;
    let output = args.inputs.output;
    let repeats = usize::from(args.repeats);
    // The tools first, before the model is loaded, while this process is small (a
    // child starts with its parent's peak memory as its own:
    // `child_runs::wait_with_peak_rss`); their table at once, so that minutes of
    // runs survive the method's bench failing.
    let tool_repeats = usize::from(args.tool_repeats);
    let tools = args
        .tools
        .then(|| tools::time(&args, config, tool_repeats))
        .transpose()?;
    let (model, model_name) = args.model.load(config)?;
    let selection = args.inputs.open_one(config, model.reads_images(config))?;
    if let (Some(tools), false) = (&tools, output.json) {
        let out = &mut std::io::stdout().lock();
        tools::print_tools_table(out, &selection.describe(), tools, tool_repeats)?;
    }
    let report = benchmark(&selection, config, &model, repeats)?;
    if output.json {
        let fields = json!({"config": config, "model": model_json(&model, &model_name)});
        let mut fields = with_summary(fields, &report)?;
        if let Some(tools) = &tools {
            fields["tools"] = serde_json::to_value(tools)?;
        }
        print_json_summary("bench", std::slice::from_ref(&selection), fields)?;
        return Ok(outcome(std::slice::from_ref(&selection)));
    }
    let mut out = std::io::stdout().lock();
    if !output.quiet {
        writeln!(out, "input: {}", selection.describe())?;
    }
    writeln!(
        out,
        "{} timed frames x {} repeats; n = {} scans of {:.0} points, {} x {} grid of {} m ({:.0} predictable cells, {:.0} points in grid); {model_name}, {} support vectors",
        report.timed_frames,
        report.repeats,
        config.integration.scans,
        report.mean_points_per_scan,
        config.grid.cells_per_side(),
        config.grid.cells_per_side(),
        config.grid.cell_size_m,
        report.predictable_cells,
        report.points_in_grid,
        report.support_vectors
    )?;
    writeln!(
        out,
        "{:<34} {:>9} {:>9}",
        "stage (1 thread, frame by frame)", "median ms", "p95 ms"
    )?;
    let t = &report.timings;
    for (name, spread) in [
        ("read + image decode (not in latency)", t.read_ms),
        (
            "registration (--poses registration)",
            report.registration_ms,
        ),
        ("integrate", t.integrate_ms),
        ("grid", t.grid_ms),
        ("geometric features", t.features_ms),
        ("appearance: projection + voting", t.appearance_ms),
        ("classify", t.classify_ms),
        ("filter", t.filter_ms),
        ("latency: scan in to filtered grid", t.latency_ms),
    ] {
        writeln!(out, "{name:<34} {:>9.3} {:>9.3}", spread.median, spread.p95)?;
    }
    writeln!(
        out,
        "{:<34} {:>9.3} {:>9.3}   latency = {:.1}x the floor",
        "floor: move + count in cells",
        report.floor_ms.median,
        report.floor_ms.p95,
        report.latency_over_floor
    )?;
    if report.registration_lost > 0 {
        writeln!(
            out,
            "  ({} scans over the repeats did not register; the map started again from each)",
            report.registration_lost
        )?;
    }
    writeln!(
        out,
        "{:<34} {:>9}",
        "write", "not in this table: see `bench --tools`"
    )?;
    writeln!(
        out,
        "throughput (whole selection, rayon across frames): {:.1} frames/s on 1 thread, {:.1} frames/s on {} threads ({:.2}x)",
        report.one_thread.frames_per_second,
        report.all_cores.frames_per_second,
        report.all_cores.threads,
        report.speedup
    )?;
    Ok(outcome(std::slice::from_ref(&selection)))
}

/// `--tools`: the subcommands timed as child processes (`travmap-bench`), or,
/// built without the `bench-tools` feature, refused.
#[cfg(feature = "bench-tools")]
mod tools {
    use anyhow::Result;
    pub use travmap_bench::{ToolRow, print_tools_table};

    pub fn time(
        args: &super::BenchArgs,
        config: &travmap_core::Config,
        repeats: usize,
    ) -> Result<Vec<ToolRow>> {
        let input = args.inputs.open_one(config, false)?;
        let model = args.model.model.as_deref().map(std::path::Path::new);
        travmap_bench::bench_tools(&args.inputs.child_flags(), &input, model, repeats)
    }
}

#[cfg(not(feature = "bench-tools"))]
mod tools {
    use anyhow::Result;

    /// No rows can be made without the feature.
    #[derive(serde::Serialize)]
    pub enum ToolRow {}

    pub fn time(_: &super::BenchArgs, _: &travmap_core::Config, _: usize) -> Result<Vec<ToolRow>> {
        let why = "--tools: this travmap was built without the bench-tools feature";
        Err(crate::cli::usage(why.into()))
    }

    pub fn print_tools_table(
        _: &mut impl std::io::Write,
        _: &str,
        _: &[ToolRow],
        _: usize,
    ) -> Result<()> {
        Ok(())
    }
}
