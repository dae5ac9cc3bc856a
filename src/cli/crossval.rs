//! `travmap crossval`: held-out scores. With one input, spatially-blocked
//! cross-validation; with several, each input held out in turn (a scene the model
//! has never seen), unless `--spatial`.

use std::io::Write;

use anyhow::Result;
use clap::Args;
use serde_json::json;
use travmap_run::DriveRun;
use travmap_training::crossval::{
    CrossValidationReport, LeaveOneOutReport, cross_validate, leave_one_input_out,
};

use super::{Inputs, Outcome, outcome, print_json_summary, with_summary};
use travmap_run::report::tables::score_table;

/// Held-out scores: spatially-blocked CV over one input's frames, or each of several
/// inputs held out in turn.
#[derive(Args)]
#[command(
    after_long_help = "Examples (SEQ: a KITTI sequence folder, e.g. ../shared/data/semantickitti-00/sequences/00):\n  travmap crossval SEQ\n  travmap crossval seq00 seq07 --json"
)]
pub struct CrossvalArgs {
    #[command(flatten)]
    inputs: Inputs,
    /// With several inputs, pool them into spatially-blocked CV instead of holding
    /// out each input in turn.
    #[arg(long)]
    spatial: bool,
}

pub fn crossval(args: CrossvalArgs) -> Result<Outcome> {
    let config = &args.inputs.settings.load()?;
    let output = args.inputs.output;
    let selections = args.inputs.open(config, config.appearance.enabled)?;
    if selections.len() > 1 && !args.spatial {
        let bar = output.progress(selections.len() as u64, "holding out");
        let report = leave_one_input_out(&selections, config, &|message| {
            bar.set_message(message.to_string());
            bar.inc(1);
        })?;
        bar.finish();
        print_leave_one_out(&report, &selections, config, output.json)?;
        return Ok(outcome(&selections));
    }
    let bar = output.progress(config.training.folds as u64, "cross-validating");
    let report: CrossValidationReport = cross_validate(&selections, config, &|message| {
        bar.set_message(message.to_string());
        bar.inc(1);
    })?;
    bar.finish();
    let sources: Vec<String> = selections.iter().map(DriveRun::describe).collect();
    if output.json {
        let fields = with_summary(json!({"config": config}), &report)?;
        print_json_summary("crossval", &selections, fields)?;
        return Ok(outcome(&selections));
    }
    let mut out = std::io::stdout().lock();
    if !output.quiet {
        writeln!(out, "inputs: {}", sources.join("; "))?;
    }
    writeln!(
        out,
        "spatially-blocked {}-fold cross-validation, {} m world blocks; each fold's model has its own grid search",
        config.training.folds, report.block_size_m
    )?;
    for f in &report.folds {
        writeln!(
            out,
            "  fold {}: trained on {} cells (test blocks hold {}), C {} gamma {}, {} support vectors, {:.1} s",
            f.fold,
            f.training_cells,
            f.test_cells,
            f.c,
            f.gamma,
            f.support_vectors,
            f.training_ms / 1e3
        )?;
    }
    write!(out, "{}", score_table(&report.evaluation, false))?;
    if let Some(first) = report.camera_ablation.first() {
        let c = &first.evaluation.confusion;
        writeln!(
            out,
            "camera ablation (the paper's), the same cross-validation scored on the {} labelled cells a camera saw:",
            c.tp + c.tn + c.fp + c.r#fn + c.unknown
        )?;
        for row in &report.camera_ablation {
            let scores = row.evaluation.scores.map_or("n/a".into(), |s| {
                format!(
                    "Acc {:.1} mIoU {:.1} F1 {:.1} TNR {:.1}",
                    100.0 * s.accuracy,
                    100.0 * s.miou,
                    100.0 * s.f1,
                    100.0 * s.tnr
                )
            });
            writeln!(out, "  {:<6} {scores}", row.features)?;
        }
    }
    Ok(outcome(&selections))
}

fn print_leave_one_out(
    report: &LeaveOneOutReport,
    selections: &[DriveRun],
    config: &travmap_core::Config,
    json: bool,
) -> Result<()> {
    if json {
        let fields = with_summary(json!({"config": config}), report)?;
        return print_json_summary("crossval", selections, fields);
    }
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "leave-one-input-out: each input scored by a model trained (with its own grid search) on the others"
    )?;
    for held in &report.held_out {
        writeln!(
            out,
            "held out {}: trained on {} cells, C {} gamma {}, {} support vectors",
            held.input, held.training_cells, held.c, held.gamma, held.support_vectors
        )?;
        write!(out, "{}", score_table(&held.evaluation, false))?;
    }
    writeln!(out, "pooled over every held-out frame:")?;
    write!(out, "{}", score_table(&report.pooled, false))?;
    Ok(())
}
