//! `travmap dataset`: one Parquet row per predictable cell per frame, on the
//! training grid (`training.grid_size_m`), the cells `train` learns from.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use serde_json::json;
use travmap_core::Config;
use travmap_core::temporaries;
use travmap_method::classifier::SvmModel;
use travmap_outputs::dataset::{
    DEFAULT_ROWS_PER_PART, DatasetFiles, DatasetSummary, DatasetWriter, check_dataset_folder,
};
use travmap_run::report::tables::model_line;
use travmap_run::{DriveRun, Fingerprints};

use super::{
    Inputs, ModelArg, Outcome, check_output, check_output_dir, counted, frame_count, model_json,
    note_extension, outcome, path_text, print_json_summary, with_summary,
};

/// Write a Parquet table of cells to train on, one row per predictable cell per frame
///
/// Each row holds the cell's features, appearance, ground truth and (with --model) the
/// prediction, on the training grid.
#[derive(Args)]
#[command(
    after_long_help = "Examples (SEQ: a KITTI sequence folder, e.g. ../shared/data/semantickitti-00/sequences/00):\n  travmap dataset SEQ -o cells.parquet\n  travmap dataset long_drive.mcap -o cells/\n  travmap dataset drive.mcap -o cells.parquet --model model.json"
)]
pub struct DatasetArgs {
    #[command(flatten)]
    inputs: Inputs,
    /// Where to write the cells: a folder (`cells/`, or one that exists) gets
    /// part-00000.parquet, ... that pyarrow.dataset, DuckDB and Polars read as one
    /// table; any other name, one Parquet file.
    #[arg(short, long)]
    output: PathBuf,
    /// Rows a part file of a folder holds (parts close at the end of the frame that
    /// reaches it); the memory a long drive takes stays that of one part.
    #[arg(long, value_name = "ROWS", default_value_t = DEFAULT_ROWS_PER_PART, value_parser = clap::value_parser!(u64).range(1..))]
    rows_per_part: u64,
    /// Add the prediction of this model: `road`, `offroad` or a model file (by
    /// default no prediction column values).
    #[arg(long, value_name = "MODEL")]
    model: Option<String>,
}

pub fn dataset(args: DatasetArgs) -> Result<Outcome> {
    let config = &args
        .inputs
        .settings
        .load_with_model(args.model.as_deref())?;
    let output = args.inputs.output;
    let output_path = args.output.as_path();
    // The model predicts only when one is asked for.
    let model_file = args.model.as_ref().and_then(|_| ModelArg::file(config));
    let model_file = model_file.as_deref();
    let layout = match output_path.is_dir() || path_text(output_path).ends_with('/') {
        true => DatasetFiles::Parts {
            rows_per_part: args.rows_per_part,
        },
        false => DatasetFiles::File,
    };
    match layout {
        DatasetFiles::File => {
            check_output(output_path, &args.inputs.files(model_file))?;
            note_extension(output_path, "parquet", "a Parquet file");
        }
        DatasetFiles::Parts { .. } => {
            check_output_dir(output_path, &args.inputs.files(model_file))?;
            check_dataset_folder(output_path)?;
        }
    }
    let mut selections = args.inputs.open(config, config.appearance.enabled)?;
    let model = match &args.model {
        Some(_) => Some(args.inputs.settings.load_model(config)?),
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
    // A folder this run makes is a temporary until its parts are in place.
    let created_dir = layout != DatasetFiles::File && !output_path.exists();
    if created_dir {
        std::fs::create_dir(output_path)
            .with_context(|| format!("cannot create {}", output_path.display()))?;
        temporaries::track(output_path);
    }
    let written = write_cells(
        &selections,
        &grid_config,
        model.as_ref().map(|(model, name)| (model, name.as_str())),
        output_path,
        layout,
        &|| bar.inc(1),
    );
    if created_dir {
        temporaries::forget(output_path);
        if written.is_err() {
            let _ = std::fs::remove_dir_all(output_path);
        }
    }
    let summary = written?;
    let seconds = bar.finish();
    if output.json {
        let cells_per_s = summary.rows as f64 / seconds;
        let files: Vec<String> = summary.files.iter().map(|f| path_text(f)).collect();
        let model = model.as_ref().map(|(model, name)| model_json(model, name));
        let fields = json!({"output": path_text(output_path), "outputs": files, "config": config, "model": model, "elapsed_ms": seconds * 1e3, "cells_per_s": cells_per_s});
        let fields = with_summary(fields, &summary)?;
        print_json_summary("dataset", &selections, fields)?;
    } else if !output.quiet {
        if let Some((model, name)) = &model {
            println!("{}", model_line(model, name));
        }
        let parts = match layout {
            DatasetFiles::File => String::new(),
            DatasetFiles::Parts { .. } => {
                format!(" in {}", counted(summary.files.len(), "part file"))
            }
        };
        println!(
            "wrote {}{parts}: {} from {} ({} labelled, {} with appearance), {:.0} cells/s",
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

/// The predictable cells of every frame of `selections` on the training grid, into
/// the dataset at `path`.
fn write_cells(
    selections: &[DriveRun],
    grid_config: &Config,
    model: Option<(&SvmModel, &str)>,
    path: &Path,
    layout: DatasetFiles,
    on_frame: &dyn Fn(),
) -> Result<DatasetSummary> {
    let record = model.map(|(model, name)| model_json(model, name).to_string());
    let mut writer = DatasetWriter::create(path, grid_config, layout, record)?;
    let model = model.map(|(model, _)| model);
    for selection in selections {
        let source = selection.source.path().display().to_string();
        selection.run::<anyhow::Error>(grid_config, model, |result| {
            writer.push_frame(&source, &result)?;
            on_frame();
            Ok(())
        })?;
    }
    let inputs: Vec<String> = selections.iter().map(DriveRun::describe).collect();
    let skipped: Vec<_> = selections.iter().flat_map(|s| s.source.skipped()).collect();
    Ok(writer.finish(&inputs.join("; "), &skipped)?)
}
