//! `travmap bench`: per-stage latency (median, p95) and throughput on 1 thread and
//! all cores; with `--tools`, the subcommands' own throughput (`travmap-bench`,
//! the `bench-tools` feature).

use std::io::Write;

use anyhow::Result;
use clap::Args;
use serde_json::json;
use travmap_run::report::tables::stage_table;
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
    let config = &args.model.config(&args.inputs.settings)?;
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
    let (model, model_name) = args.inputs.settings.load_model(config)?;
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
    write!(out, "{}", stage_table(&report, config, &model_name))?;
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
