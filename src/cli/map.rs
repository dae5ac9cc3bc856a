//! `travmap map`: the whole drive as one fused map (PNG, and its cells as Parquet).

use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::{Args, ValueEnum};
use serde_json::json;
use travmap_io::SourceOptions;
use travmap_outputs::atomic::Staged;
use travmap_outputs::drive_map::{render_drive_map, write_map_cells};
use travmap_outputs::nav2_map::{Nav2Mode, gis_world_file, image_path, write_nav2_map};
use travmap_outputs::preflight::check_distinct_outputs;
use travmap_outputs::rendering::encode_png;
use travmap_run::report::tables::model_line;
use travmap_run::scoring::evaluation::Evaluation;
use travmap_run::scoring::metrics::Confusion;
use travmap_run::scoring::remarks::FitRemedies;

use super::{
    Inputs, ModelArg, Outcome, PaletteArg, check_output, counted, fit_said, frame_count,
    model_json, note_extension, notice_drives, outcome, path_text, print_json_summary, usage,
};

/// Fuse every frame's prediction (and ground truth) into one map of the drive.
#[derive(Args)]
#[command(mut_arg("sequences", |a| super::one_input(a).help(
    "A KITTI odometry / SemanticKITTI sequence directory, a recorded log (MCAP, ROS 1 bag, rosbag2 directory or .db3), a folder of .pcd / .bin scans, or one saved point cloud of a site (.pcd or .ply)"
)))]
#[command(
    after_long_help = "Examples (SEQ: a KITTI sequence folder, e.g. ../shared/data/semantickitti-00/sequences/00):\n  travmap map SEQ -o map.png\n  travmap map drive.mcap -o map.png --nav2 site.yaml\n  travmap map drive.mcap --nav2 site.yaml\n  travmap map site.las -o site.png --cells cells.parquet"
)]
pub struct MapArgs {
    #[command(flatten)]
    inputs: Inputs,
    /// The PNG to write: the fused map with the trajectory (and, with ground truth,
    /// the fused ground truth and the errors). A map needs at least one of -o,
    /// --cells and --nav2.
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Also write the fused cells as a Parquet table.
    #[arg(long, value_name = "PARQUET")]
    cells: Option<PathBuf>,
    /// Also write a nav2 map_server map: this YAML and the image it names beside it
    /// (site.yaml -> site.pgm; site.png with --nav2-mode scale).
    #[arg(long, value_name = "YAML")]
    nav2: Option<PathBuf>,
    /// trinary: free / occupied / unknown as map_saver writes them; scale:
    /// P(not traversable) as grey levels for costmaps that read costs.
    #[arg(long, value_enum, default_value_t = Nav2ModeArg::Trinary, requires = "nav2")]
    nav2_mode: Nav2ModeArg,
    #[command(flatten)]
    model: ModelArg,
    /// Pixels per cell side (1 to 64).
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=64))]
    cell_pixels: u32,
    #[command(flatten)]
    palette: PaletteArg,
}

#[derive(Clone, Copy, ValueEnum)]
enum Nav2ModeArg {
    Trinary,
    Scale,
}

impl Nav2ModeArg {
    fn mode(self) -> Nav2Mode {
        match self {
            Self::Trinary => Nav2Mode::Trinary,
            Self::Scale => Nav2Mode::Scale,
        }
    }
}

pub fn map(args: MapArgs) -> Result<Outcome> {
    let cell_px = args.cell_pixels;
    let config = args.model.config(&args.inputs.settings)?;
    let (output, output_path) = (args.inputs.output, args.output.as_deref());
    let inputs = args.inputs.files(ModelArg::file(&config).as_deref());
    let nav2_mode = args.nav2_mode.mode();
    let nav2_image = args.nav2.as_deref().map(|yaml| image_path(yaml, nav2_mode));
    // The image's own name would be its YAML's and its image's at once.
    if let (Some(yaml), Some(image)) = (&args.nav2, &nav2_image)
        && yaml == image
    {
        return Err(usage(format!(
            "--nav2 takes the map's YAML, which names the image written beside it: --nav2 {}",
            yaml.with_extension("yaml").display()
        )));
    }
    let outputs: Vec<&Path> = [output_path, args.cells.as_deref()]
        .into_iter()
        .chain([args.nav2.as_deref(), nav2_image.as_deref()])
        .flatten()
        .collect();
    let Some(&first_output) = outputs.first() else {
        return Err(usage(
            "map writes a picture (-o map.png), the fused cells (--cells cells.parquet) or a nav2 map (--nav2 site.yaml): give at least one".into(),
        ));
    };
    check_distinct_outputs(&outputs)?;
    for path in &outputs {
        check_output(path, &inputs)?;
    }
    let (model, model_name) = args.inputs.settings.load_model(&config)?;
    // One saved point cloud is a site: tiles of the grid's size.
    let site_tile_m = Some(config.grid.size_m);
    let options = SourceOptions {
        site_tile_m,
        ..args.inputs.source_options(&config)?
    };
    let selection = args
        .inputs
        .open_one_as(&options, &config, model.reads_images(&config))?;
    let config = &config;
    let georeference = selection.source.georeference();
    if let (Some(image), Some(georeference)) = (&nav2_image, &georeference) {
        // The world file and .prj a georeferenced map gets beside its image.
        if georeference.is_planar() {
            check_output(&gis_world_file(image), &inputs)?;
        }
        if georeference.crs_wkt.is_some() {
            check_output(&image.with_extension("prj"), &inputs)?;
        }
    }
    if let Some(path) = output_path {
        note_extension(path, "png", "a PNG image");
    }
    let selections = [selection];
    let bar = output.progress(frame_count(&selections), "mapping");
    let mut trajectory = Vec::new();
    let mut per_frame = Evaluation::default();
    let map = selections[0].run_mapped::<anyhow::Error>(config, Some(&model), |result, _| {
        trajectory.push([result.sensor_in_world[0], result.sensor_in_world[1]]);
        per_frame.add(&result);
        bar.inc(1);
        Ok(())
    })?;
    let seconds = bar.finish();
    let cells = map.cells();
    let (lattice, frames, memory_bytes) = (map.lattice(), map.frames(), map.memory_bytes());
    let cell_size_m = lattice.cell_size_m;
    if frames == 0 {
        let selection = &selections[0];
        let skipped = selection.source.skipped();
        return Err(travmap_io::nothing_read(first_output, selection.describe(), &skipped).into());
    }
    // The cells are the map from here on: its tiles (most of a site map's memory) go.
    drop(map);
    let mut staged = Staged::default();
    if let Some(path) = output_path {
        let palette = args.palette.palette();
        let picture = render_drive_map(&cells, &trajectory, &lattice, cell_px, &palette)?;
        staged.write(path, &encode_png(&picture))?;
    }
    if let Some(path) = &args.cells {
        let metadata = vec![
            ("travmap.config".into(), serde_json::to_string(config)?),
            (
                "travmap.model".into(),
                model_json(&model, &model_name).to_string(),
            ),
        ];
        write_map_cells(&mut staged, path, &cells, metadata)?;
    }
    let world_frame = selections[0].source.world_frame();
    let nav2 = args
        .nav2
        .as_deref()
        .map(|yaml| {
            write_nav2_map(
                &mut staged,
                yaml,
                &cells,
                &lattice,
                world_frame,
                nav2_mode,
                georeference.as_ref(),
            )
        })
        .transpose()?;
    staged.commit()?;
    let fused = Confusion::of_drive_map(&cells);
    let fused_scores = fused.scores_if_predicted();
    let per_frame = per_frame.report();
    notice_drives(
        &per_frame,
        &model,
        config,
        FitRemedies::of(&selections, false, None),
    );
    let seen = cells.iter().filter(|c| c.observations > 0).count();
    let area_m2 = seen as f64 * cell_size_m.powi(2);
    if output.json {
        let fields = json!({
            "output": path_text(output_path.unwrap_or(first_output)),
            "outputs": outputs.iter().copied().chain(nav2.iter().flat_map(|n| n.gis_files.iter().map(PathBuf::as_path))).map(path_text).collect::<Vec<_>>(),
            "cells_output": args.cells.as_deref().map(path_text),
            "nav2": nav2,
            "model": model_json(&model, &model_name),
            "config": config,
            "frames": frames,
            "cells": cells.len(),
            "seen_cells": seen,
            "area_m2": area_m2,
            "memory_bytes": memory_bytes,
            "fused_confusion": fused,
            "fused_scores": fused_scores,
            "per_frame_scores": per_frame.scores,
            "fit": per_frame.fit,
            "elapsed_ms": seconds * 1e3,
        });
        print_json_summary("map", &selections, fields)?;
    } else if !output.quiet {
        println!("{}", model_line(&model, &model_name));
        println!(
            "{} fused into {}, {area_m2:.0} m2 (map {:.1} KiB)",
            counted(frames, "frame"),
            counted(seen, "cell"),
            memory_bytes as f64 / 1024.0
        );
        if let Some(path) = output_path {
            println!("wrote {} (the map's picture)", path.display());
        }
        if let Some(path) = &args.cells {
            println!(
                "wrote {} ({}, Parquet)",
                path.display(),
                counted(cells.len(), "cell")
            );
        }
        if let Some(nav2) = &nav2 {
            println!(
                "wrote {} and {} (nav2 map_server, {}: {} x {} cells of {} m, origin ({:.2}, {:.2}) in frame {})",
                nav2.yaml.display(),
                nav2.image.display(),
                serde_json::to_value(nav2.mode)?
                    .as_str()
                    .unwrap_or_default(),
                nav2.width,
                nav2.height,
                nav2.resolution_m,
                nav2.origin[0],
                nav2.origin[1],
                nav2.frame
            );
            for file in &nav2.gis_files {
                println!("wrote {} (the image's georeference)", file.display());
            }
        }
        if let (Some(fused), Some(frames)) = (fused_scores, per_frame.scores) {
            println!(
                "fused map (each world cell once): Acc {:.1} mIoU {:.1} F1 {:.1}; per frame: Acc {:.1} mIoU {:.1} F1 {:.1}",
                fused.accuracy * 100.0,
                fused.miou * 100.0,
                fused.f1 * 100.0,
                frames.accuracy * 100.0,
                frames.miou * 100.0,
                frames.f1 * 100.0
            );
        }
        println!("{}", fit_said(&per_frame.fit));
    }
    Ok(outcome(&selections))
}
