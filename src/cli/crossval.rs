//! `travmap crossval`: the spatially-blocked held-out evaluation.

use std::io::Write;

use anyhow::Result;
use clap::Args;
use serde_json::json;
use travmap::drive::Selection;
use travmap::training::crossval::{CrossValidationReport, cross_validate};

use super::eval::write_table;
use super::{Inputs, Outcome, outcome, print_json_summary};

/// Held-out accuracy by spatially-blocked cross-validation over the frames.
#[derive(Args)]
pub struct CrossvalArgs {
    #[command(flatten)]
    inputs: Inputs,
}

pub fn crossval(args: CrossvalArgs) -> Result<Outcome> {
    let config = &args.inputs.settings.load()?;
    let output = args.inputs.output;
    let selections = args.inputs.open(config.appearance.enabled)?;
    let bar = output.progress(config.training.folds as u64, "cross-validating");
    let report: CrossValidationReport = cross_validate(&selections, config, &|message| {
        bar.set_message(message.to_string());
        bar.inc(1);
    })?;
    bar.finish();
    let sources: Vec<String> = selections.iter().map(Selection::describe).collect();
    if output.json {
        print_json_summary(
            "crossval",
            &selections,
            json!({"config": config, "report": report}),
        )?;
        return Ok(outcome(&selections));
    }
    let mut out = std::io::stdout().lock();
    writeln!(out, "inputs: {}", sources.join("; "))?;
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
            f.training_seconds
        )?;
    }
    write_table(&mut out, &report.evaluation, false)?;
    Ok(outcome(&selections))
}
