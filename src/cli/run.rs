//! `travmap run`: the filtered grid of every frame, as a table, text pictures or
//! JSON lines.

use std::io::Write;

use anyhow::Result;
use clap::Args;
use serde_json::json;
use travmap_method::grid::CellClass;
use travmap_run::scoring::evaluation::Evaluation;
use travmap_run::scoring::remarks::FitRemedies;

use super::{
    Inputs, ModelArg, Outcome, fit_said, frame_count, model_json, notice_drives, outcome,
    path_text, print_json_frame, print_json_summary,
};

/// Predict the filtered traversability grid of every frame.
#[derive(Args)]
#[command(
    after_long_help = "Examples (SEQ: a KITTI sequence folder, e.g. ../shared/data/semantickitti-00/sequences/00):\n  travmap run SEQ\n  travmap run drive.mcap --cloud-topic /points --ascii\n  travmap run SEQ --json | jq .frame"
)]
pub struct RunArgs {
    #[command(flatten)]
    inputs: Inputs,
    #[command(flatten)]
    model: ModelArg,
    /// Draw each grid as text ('.' traversable, '#' not, ' ' unknown; x right, y up).
    #[arg(long)]
    ascii: bool,
}

pub fn run(args: RunArgs) -> Result<Outcome> {
    let config = args.model.config(&args.inputs.settings)?;
    let output = args.inputs.output;
    let (model, model_name) = args.inputs.settings.load_model(&config)?;
    let mut selections = args.inputs.open(&config, model.reads_images(&config))?;
    // `run` prints no scores: labels it does not need cannot stop it.
    for selection in &mut selections {
        selection.source.set_read_labels(false);
    }
    let mut stdout = std::io::stdout().lock();
    if !output.json {
        if !output.quiet {
            writeln!(
                stdout,
                "model: {model_name} ({} support vectors)",
                model.support_vector_count()
            )?;
        }
        writeln!(
            stdout,
            "{:>6} {:>10} {:>6} {:>11} {:>11} {:>9} {:>10}",
            "frame", "stamp_s", "cells", "predictable", "traversable", "non-trav", "latency_ms"
        )?;
    }
    let bar = output.progress(frame_count(&selections), "predicting");
    let mut evaluation = Evaluation::default();
    let mut frames = 0usize;
    for selection in &selections {
        selection.run::<anyhow::Error>(&config, Some(&model), |result| {
            bar.inc(1);
            frames += 1;
            evaluation.add(&result);
            let grid = result.filtered.as_deref().unwrap_or(&[]);
            let count = |class: CellClass| grid.iter().filter(|c| **c == class).count();
            let (traversable, non_traversable) = (
                count(CellClass::Traversable),
                count(CellClass::NonTraversable),
            );
            if output.json {
                let cells: Vec<i8> = grid.iter().map(|c| c.occupancy()).collect();
                print_json_frame(json!({
                    "input": path_text(selection.source.path()),
                    "frame": result.index,
                    "stamp_ns": result.stamp_ns,
                    "cell_size_m": result.layout.cell_size_m,
                    "cells_per_side": result.layout.cells_per_side,
                    "min_corner_in_world": result.layout.min_corner_in_world(),
                    "cells": cells,
                    "timings": result.timings,
                    "dropped_points": result.dropped_points,
                    "remission": result.remission,
                    "without_remission": result.without_remission,
                }))?;
            } else {
                bar.print_beside(|| -> Result<()> {
                    writeln!(
                        stdout,
                        "{:>6} {:>10.3} {:>6} {:>11} {:>11} {:>9} {:>10.2}",
                        result.index,
                        result.stamp_ns as f64 * 1e-9,
                        grid.len(),
                        traversable + non_traversable,
                        traversable,
                        non_traversable,
                        result.timings.latency_ms
                    )?;
                    if args.ascii {
                        write_ascii_grid(&mut stdout, grid, result.layout.cells_per_side)?;
                    }
                    Ok(())
                })?;
            }
            Ok(())
        })?;
    }
    bar.finish();
    let report = evaluation.report();
    if output.json {
        let remedies = FitRemedies::of(&selections, false, None);
        notice_drives(&report, &model, &config, remedies);
        print_json_summary(
            "run",
            &selections,
            json!({
                "config": config,
                "model": model_json(&model, &model_name),
                "frames": frames,
                "timings": report.timings,
                "dropped_points": report.dropped_points,
                "frames_without_remission": report.frames_without_remission,
                "frames_with_images": report.frames_with_images,
                "cells_with_appearance": report.cells_with_appearance,
                "fit": report.fit,
            }),
        )?;
        return Ok(outcome(&selections));
    }
    if !output.quiet {
        let latency = report.timings.latency_ms;
        match frames {
            0 => writeln!(stdout, "no frame was read")?,
            _ => writeln!(
                stdout,
                "median latency {:.2} ms per frame (p95 {:.2} ms)",
                latency.median, latency.p95
            )?,
        }
        writeln!(stdout, "{}", fit_said(&report.fit))?;
    }
    let remedies = FitRemedies::of(&selections, false, None);
    notice_drives(&report, &model, &config, remedies);
    Ok(outcome(&selections))
}

/// Rows from north (max y) down, so the picture reads like a map with x to the right.
fn write_ascii_grid(out: &mut impl Write, grid: &[CellClass], cells_per_side: usize) -> Result<()> {
    for row in grid.chunks(cells_per_side).rev() {
        let line: String = row.iter().map(|c| c.symbol()).collect();
        writeln!(out, "  |{line}|")?;
    }
    Ok(())
}
