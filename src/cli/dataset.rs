//! `travmap dataset`: one Parquet row per predictable cell per frame, on the
//! training grid (`training.grid_size_m`), the cells `train` learns from.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use serde_json::json;
use travmap_core::config::ModelChoice;
use travmap_drive::{Fingerprints, Selection};
use travmap_outputs::dataset::DatasetWriter;

use super::{
    Inputs, Outcome, check_output, counted, frame_count, load_model, note_extension, outcome,
    path_text, print_json_summary, with_summary,
};

/// Write a Parquet table of cells to train on, one row per predictable cell per frame
///
/// Each row holds the cell's features, appearance, ground truth and (with --model) the
/// prediction, on the training grid.
#[derive(Args)]
#[command(
    after_long_help = "Examples (SEQ: a KITTI sequence folder, e.g. ../shared/data/semantickitti-00/sequences/00):\n  travmap dataset SEQ -o cells.parquet\n  travmap dataset drive.mcap -o cells.parquet --model model.json"
)]
pub struct DatasetArgs {
    #[command(flatten)]
    inputs: Inputs,
    /// Where to write the Parquet file.
    #[arg(short, long)]
    output: PathBuf,
    /// Add the prediction of this model: `road`, `offroad` or a model file (by
    /// default no prediction column values).
    #[arg(long, value_name = "MODEL")]
    model: Option<String>,
}

pub fn dataset(args: DatasetArgs) -> Result<Outcome> {
    let config = &args.inputs.settings.load()?;
    let output = args.inputs.output;
    let output_path = args.output.as_path();
    let choice = args.model.as_deref().map(ModelChoice::parse);
    let model_file = match &choice {
        Some(ModelChoice::File(path)) => Some(path.as_path()),
        _ => None,
    };
    check_output(output_path, &args.inputs.files(model_file))?;
    note_extension(output_path, "parquet", "a Parquet file");
    let mut selections = args.inputs.open(config.appearance.enabled)?;
    let model = match &choice {
        Some(choice) => Some(load_model(choice, config)?.0),
        None => None,
    };
    let grid_config = config.for_training_cells();
    // The footprint and pseudo_label columns follow each drive's trajectory.
    for selection in &mut selections {
        selection.follow_trajectory(&grid_config)?;
        // A model trained on the file knows its training scans by content.
        selection.fingerprint_scans = Fingerprints::Labelled;
    }
    let bar = output.progress(frame_count(&selections), "extracting cells");
    let mut writer = DatasetWriter::create(output_path, config)?;
    for selection in &selections {
        let source = selection.source.path().display().to_string();
        selection.run::<anyhow::Error>(&grid_config, model.as_ref(), |result| {
            writer.push_frame(&source, &result)?;
            bar.inc(1);
            Ok(())
        })?;
    }
    let inputs: Vec<String> = selections.iter().map(Selection::describe).collect();
    let skipped: Vec<_> = selections.iter().flat_map(|s| s.source.skipped()).collect();
    let summary = writer.finish(&inputs.join("; "), &skipped)?;
    let seconds = bar.finish();
    if output.json {
        let cells_per_s = summary.rows as f64 / seconds;
        let fields = json!({"output": path_text(output_path), "config": config, "elapsed_ms": seconds * 1e3, "cells_per_s": cells_per_s});
        let fields = with_summary(fields, &summary)?;
        print_json_summary("dataset", &selections, fields)?;
    } else if !output.quiet {
        println!(
            "wrote {}: {} from {} ({} labelled, {} with appearance), {:.0} cells/s",
            output_path.display(),
            counted(summary.rows, "cell"),
            counted(summary.frames, "frame"),
            summary.labelled_rows,
            summary.rows_with_appearance,
            summary.rows as f64 / seconds
        );
    }
    Ok(outcome(&selections))
}
