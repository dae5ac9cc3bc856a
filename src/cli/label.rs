//! `travmap label`: the cells the model is least sure of, answered by a person on a
//! page served on 127.0.0.1 (or from the drive's ground truth), into a labels file
//! that `train --prior` learns a model for the robot from.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, ValueEnum};
use serde_json::json;
use travmap_label::{Answerer, Session, serve};
use travmap_method::asking::{AskBy, Spread};
use travmap_run::labelling::{AskOptions, ask};
use travmap_run::report::tables::model_line;

use super::{
    Inputs, ModelArg, Outcome, check_output, counted, frame_count, model_json, note_extension,
    outcome, path_text, print_json_summary,
};

/// Label the cells the model is least sure of, on a page in the browser
///
/// Runs the model over the drives, chooses the cells it is least sure of (spread over
/// frames and places), and serves a page on 127.0.0.1 where a person answers them:
/// traversable, not, or can't tell, by click or key. Every answer is saved at once
/// into the labels file (a Parquet cell table); reopening the same drives with the
/// same file resumes. `travmap train LABELS --prior MODEL` then learns a model for
/// the robot.
#[derive(Args)]
#[command(
    after_long_help = "Examples:\n  travmap label drive.mcap -o labels.parquet\n  travmap label drive.mcap -o labels.parquet --ask 200 --model offroad\n  travmap train labels.parquet --prior road -o my_robot.json\n  travmap label SEQ -o labels.parquet --answers-from-ground-truth   (a labelled drive: the loop without a person)"
)]
pub struct LabelArgs {
    #[command(flatten)]
    inputs: Inputs,
    /// The labels file (Parquet): written after every answer; an existing one from
    /// the same drives, model and --ask is resumed.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    model: ModelArg,
    /// How many cells to ask about.
    #[arg(long, value_name = "CELLS", default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..=100_000))]
    ask: u64,
    /// Which cells to ask about: those the model is least sure of (the smallest
    /// margins), or cells at random (the baseline it is measured against).
    #[arg(long, value_enum, default_value_t = AskByArg::Margin)]
    ask_by: AskByArg,
    /// No two asked cells closer than this, metres: answers about one patch of ground
    /// say one thing.
    #[arg(long, value_name = "METRES", default_value_t = Spread::default().spacing_m, value_parser = super::parse_finite)]
    ask_spacing: f64,
    /// The seed of `--ask-by random`.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Answer every asked cell from the drive's own labels, as a perfect labeller
    /// would, and serve no page: the whole loop in a script (needs labelled drives).
    #[arg(long)]
    answers_from_ground_truth: bool,
    /// The port to serve the page on, on 127.0.0.1 (0: a free one).
    #[arg(long, default_value_t = 0)]
    port: u16,
}

#[derive(Clone, Copy, ValueEnum)]
enum AskByArg {
    Margin,
    Random,
}

pub fn label(args: LabelArgs) -> Result<Outcome> {
    let config = &args.model.config(&args.inputs.settings)?;
    let output = args.inputs.output;
    let labels_path = args.output.as_path();
    check_output(
        labels_path,
        &args.inputs.files(ModelArg::file(config).as_deref()),
    )?;
    note_extension(labels_path, "parquet", "a Parquet file");
    let (model, model_name) = args.inputs.settings.load_model(config)?;
    let answerer = match args.answers_from_ground_truth {
        true => Answerer::GroundTruth,
        false => Answerer::Person,
    };
    let mut drives = args.inputs.open(
        config,
        model.reads_images(config) || answerer == Answerer::Person,
    )?;
    let grid_config = config.for_training_cells();
    for drive in &mut drives {
        drive
            .source
            .set_read_labels(answerer == Answerer::GroundTruth);
        // Camera images are shown to the person where the drive has them.
        drive
            .source
            .set_read_images(answerer == Answerer::Person || model.reads_images(config));
    }
    if answerer == Answerer::GroundTruth {
        for drive in &drives {
            if !drive.has_labels()? {
                anyhow::bail!(
                    "--answers-from-ground-truth needs labelled drives; {} has none (looked for {})",
                    drive.source.path().display(),
                    drive.source.where_labels_are_read()
                );
            }
        }
    }
    let (by, asked_by) = match args.ask_by {
        AskByArg::Margin => (AskBy::Margin, "margin"),
        AskByArg::Random => (AskBy::Random { seed: args.seed }, "random"),
    };
    let options = AskOptions {
        budget: args.ask as usize,
        by,
        spread: Spread {
            spacing_m: args.ask_spacing.max(0.0),
            ..Spread::default()
        },
    };
    let bar = output.progress(2 * frame_count(&drives), "choosing cells");
    let questions = ask(&drives, &grid_config, &model, options, &mut || bar.inc(1))?;
    bar.finish();
    let candidates = questions.candidates;
    let record = model_json(&model, &model_name);
    let mut session = Session::open(
        questions,
        labels_path,
        &grid_config,
        record.clone(),
        asked_by,
        answerer,
    )?;
    if !output.quiet && !output.json {
        println!("{}", model_line(&model, &model_name));
        let asked = &session.questions;
        println!(
            "asking about {} in {} (the {} of {} predicted cells){}",
            counted(asked.cells.len(), "cell"),
            counted(asked.frames.len(), "frame"),
            match by {
                AskBy::Margin => "least sure",
                AskBy::Random { .. } => "random ones",
            },
            candidates,
            match session.progress().answered {
                0 => String::new(),
                n => format!("; {n} answered before, in {}", labels_path.display()),
            }
        );
    }
    let progress = match answerer {
        Answerer::GroundTruth => session.answer_from_ground_truth()?,
        Answerer::Person => {
            let quiet = output.quiet || output.json;
            serve(
                session,
                args.port,
                |served| {
                    // The address is the one thing a person needs, even with -q.
                    eprintln!(
                        "open {} to label (Ctrl-C or Done to stop; every answer is saved as it is given)",
                        served.url
                    );
                },
                |progress| {
                    if !quiet {
                        eprintln!(
                            "{} of {} answered, {} labelled cells in {}",
                            progress.answered,
                            progress.asked,
                            progress.labelled,
                            labels_path.display()
                        );
                    }
                },
            )?
        }
    };
    if output.json {
        let fields = json!({
            "output": path_text(labels_path),
            "config": config,
            "model": record,
            "asked_by": asked_by,
            "answered_by": match answerer { Answerer::Person => "person", Answerer::GroundTruth => "ground truth" },
            "candidates": candidates,
            "progress": progress,
        });
        print_json_summary("label", &drives, fields)?;
    } else if !output.quiet {
        println!(
            "wrote {}: {} labelled ({} of {} asked cells answered, {} can't tell, {} painted); learn from it with `travmap train {} --prior {} -o robot.json`",
            labels_path.display(),
            counted(progress.labelled, "cell"),
            progress.answered,
            progress.asked,
            progress.skipped,
            progress.painted,
            labels_path.display(),
            config.classifier.model,
        );
    }
    Ok(outcome(&drives))
}
