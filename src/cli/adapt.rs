//! `travmap adapt`: a model adapted to the ground of the given drives, learnt from
//! the drives themselves (no labels read); `annotate --adapt` and `eval --adapt`
//! adapt in memory first ([`adapted_model`]).

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use serde_json::json;
use travmap_core::Config;
use travmap_method::classifier::SvmModel;
use travmap_outputs::atomic::write_atomically;
use travmap_run::DriveRun;
use travmap_training::adaptation::{Adapted, adapt as adapt_model};

use super::{
    Inputs, ModelArg, Outcome, Output, check_output, counted, frame_count, model_json,
    note_extension, notice, outcome, path_text, print_json_summary, setting_word, with_summary,
};

/// Adapt a model to the ground the given drives cover, from the drives alone
///
/// The cells the vehicle drove over are traversable, obstacles and what the prior
/// (--model) confidently rejects are not; labels in the inputs are never read.
#[derive(Args)]
#[command(
    after_long_help = "Examples (SEQ: a KITTI sequence folder, e.g. ../shared/data/semantickitti-00/sequences/00):\n  travmap adapt drive.mcap -o adapted.json\n  travmap adapt drive.mcap -o adapted.json --model prior.json"
)]
pub struct AdaptArgs {
    #[command(flatten)]
    inputs: Inputs,
    /// Where to write the adapted model (JSON), which every command's --model takes.
    #[arg(short, long)]
    output: PathBuf,
    /// The prior model to adapt (default: the embedded model).
    #[command(flatten)]
    model: ModelArg,
}

pub fn adapt(args: AdaptArgs) -> Result<Outcome> {
    let config = &args.model.config(&args.inputs.settings)?;
    let output = &args.inputs.output;
    let model_path = args.output.as_path();
    check_output(
        model_path,
        &args.inputs.files(ModelArg::file(config).as_deref()),
    )?;
    note_extension(model_path, "json", "a travmap model (JSON)");
    let (prior, prior_name) = args.inputs.settings.load_model(config)?;
    let started = std::time::Instant::now();
    let (adapted, selections) = adapted_model(&args.inputs, config, &prior, &prior_name, output)?;
    // The run's own time: a kept prior's file records its own training's.
    let elapsed_ms = started.elapsed().as_secs_f64() * 1e3;
    write_atomically(model_path, &adapted.model.to_json())?;
    let model = &adapted.model;
    let summary = model.training.adaptation.as_ref();
    if output.json {
        // The self-label counts at the top, beside what was fitted and the check's
        // verdict (the model file's record of its inputs is the summary's `inputs`).
        let fields = json!({
            "output": path_text(model_path),
            "model": model_json(model, &model_path.display().to_string()),
            "prior": {"name": prior_name, "sha256": prior.sha256_hex()},
            "support_vectors": adapted.fitted().support_vector_count(),
            "fitted_cells": summary.map(|s| s.fitted_cells),
            "learner": summary.map(|s| s.learner),
            "self_supervised": summary.map(|s| s.self_supervised),
            "hybrid": summary.map(|s| &s.hybrid),
            "fallback": summary.map(|s| &s.fallback),
            "check": summary.and_then(|s| s.check.as_ref()),
            "elapsed_ms": elapsed_ms,
            "config": config,
        });
        let fields = with_summary(fields, &adapted.counts)?;
        print_json_summary("adapt", &selections, fields)?;
    } else if !output.quiet {
        let counts = &adapted.counts;
        println!(
            "self-labelled {}: {} footprint cells, {} negative cells, {} unknown (distinct world cells); no labels read",
            counted(counts.frames, "frame"),
            counts.footprint_cells,
            counts.negative_cells,
            counts.unknown_cells
        );
        let fitted = adapted.fitted();
        match summary.and_then(|s| s.check.as_ref()) {
            Some(check) if !check.adapted => {
                println!("kept {prior_name} as it was: {}", check.why);
            }
            _ => println!(
                "adapted {}{prior_name} (adapt.learner {}, C {} gamma {}): {} support vectors on {} cells",
                match adapted.fallback_fitted {
                    true => "the fallback without remission of ",
                    false => "",
                },
                setting_word(&config.adapt.learner),
                fitted.c,
                fitted.gamma,
                fitted.support_vector_count(),
                summary.map_or(0, |s| s.fitted_cells)
            ),
        }
        println!("wrote {}", model_path.display());
    }
    Ok(outcome(&selections))
}

/// The prior adapted to the drives of `inputs` (opened afresh, without labels),
/// with a progress bar and the notices on stderr; and the drives as read (with the
/// frames `--keep-going` skipped).
pub fn adapted_model(
    inputs: &Inputs,
    config: &Config,
    prior: &SvmModel,
    prior_name: &str,
    output: &Output,
) -> Result<(Adapted, Vec<DriveRun>)> {
    let mut selections = inputs.open(config, config.appearance.enabled)?;
    let bar = output.progress(frame_count(&selections), "adapting");
    let adapted = adapt_model(&mut selections, config, prior, prior_name, &mut || {
        bar.inc(1)
    })?;
    bar.finish();
    for said in &adapted.notices {
        notice(said);
    }
    Ok((adapted, selections))
}

/// `--adapt` of the commands that classify drives.
#[derive(Args)]
pub struct AdaptFlag {
    /// Adapt the model (--model, or the embedded one) to these drives first, from the
    /// drives alone (as `travmap adapt` does; labels, if any, are read only to score).
    #[arg(long)]
    pub adapt: bool,
}

impl AdaptFlag {
    /// `model` (named `name`), adapted to the drives of `inputs` when asked.
    pub fn apply(
        &self,
        inputs: &Inputs,
        config: &Config,
        (model, name): (SvmModel, String),
        output: &Output,
    ) -> Result<(SvmModel, String)> {
        if !self.adapt {
            return Ok((model, name));
        }
        let (adapted, _) = adapted_model(inputs, config, &model, &name, output)?;
        // A kept prior is the model it was (its line says adaptation kept it).
        let name = match adapted.replaced_prior() {
            true => format!("{name}, adapted to these drives"),
            false => name,
        };
        Ok((adapted.model, name))
    }
}
