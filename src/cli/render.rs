//! `travmap render`: ground truth, prediction and errors of frames as PNG pictures,
//! one file (`--frame N`) or one per frame into a directory (`--all`).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use serde_json::json;
use travmap_core::temporaries;
use travmap_outputs::atomic::Staged;
use travmap_outputs::rendering;
use travmap_run::report::tables::model_line;

use super::{
    Inputs, ModelArg, Outcome, PaletteArg, check_output, check_output_dir, counted, frame_count,
    model_json, outcome, path_text, print_json_summary, usage,
};

/// Draw ground truth, prediction and errors of a frame side by side as PNG.
#[derive(Args)]
#[command(mut_arg("sequences", super::one_input))]
#[command(
    after_long_help = "Examples (SEQ: a KITTI sequence folder, e.g. ../shared/data/semantickitti-00/sequences/00):\n  travmap render SEQ -o frame.png --frame 2\n  travmap render SEQ -o frames/ --all"
)]
pub struct RenderArgs {
    #[command(flatten)]
    inputs: Inputs,
    /// The PNG to write (with --frame) or the directory for one PNG per frame (--all).
    #[arg(short, long)]
    output: PathBuf,
    /// The frame to draw.
    #[arg(long, conflicts_with_all = ["all", "frames"], required_unless_present = "all")]
    frame: Option<usize>,
    /// Draw every selected frame (see --frames) into the output directory.
    #[arg(long)]
    all: bool,
    #[command(flatten)]
    model: ModelArg,
    /// Pixels per cell side (1 to 64; default: each panel at least 480 pixels wide,
    /// 16 a cell for the default 12 m grid).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=64))]
    cell_pixels: Option<u32>,
    #[command(flatten)]
    palette: PaletteArg,
    /// Draw the float layers a planner reads (P(traversable), elevation, its range,
    /// the unsure cells: annotate's /travmap/grid_map) instead of ground truth,
    /// prediction and errors.
    #[arg(long)]
    layers: bool,
}

pub fn render(mut args: RenderArgs) -> Result<Outcome> {
    match (args.frame, args.all) {
        (Some(frame), _) => args.inputs.frames = Some(frame..frame + 1),
        (None, true) => {}
        (None, false) => unreachable!("clap requires --frame unless --all"),
    }
    let palette = args.palette.palette();
    let config = &args.model.config(&args.inputs.settings)?;
    let (output, output_path) = (args.inputs.output, args.output.as_path());
    let inputs = args.inputs.files(ModelArg::file(config).as_deref());
    if args.all {
        check_output_dir(output_path, &inputs)?;
    } else {
        check_output(output_path, &inputs)?;
    }
    let (model, model_name) = args.inputs.settings.load_model(config)?;
    let selection = args.inputs.open_one(config, model.reads_images(config))?;
    if args.all
        && output_path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("png"))
    {
        return Err(usage(format!(
            "--all writes one PNG per frame into a directory; {} names a PNG file (give a directory, or --frame N for one picture)",
            output_path.display()
        )));
    }
    let created_dir = args.all && !output_path.exists();
    if created_dir {
        std::fs::create_dir(output_path)
            .with_context(|| format!("cannot create {}", output_path.display()))?;
        // A folder this run made is a temporary until its pictures are in place: a
        // signal removes it with them.
        temporaries::track(output_path);
    }
    let selections = [selection];
    let bar = output.progress(frame_count(&selections), "rendering");
    let mut written = Vec::new();
    let mut staged = Staged::default();
    let rendered = selections[0].run::<anyhow::Error>(config, Some(&model), |result| {
        let path = if args.all {
            output_path.join(format!("{:06}.png", result.index))
        } else {
            output_path.to_path_buf()
        };
        staged.write(
            &path,
            &rendering::encode_png(&{
                let cell_px = (args.cell_pixels)
                    .unwrap_or_else(|| rendering::default_cell_px(result.layout.cells_per_side));
                match args.layers {
                    true => rendering::render_layers(&result, cell_px, &palette),
                    false => rendering::render(&result, cell_px, &palette),
                }
            }),
        )?;
        written.push(path);
        bar.inc(1);
        Ok(())
    });
    let rendered = rendered.and_then(|()| match written.is_empty() {
        true => bail!("no frame was rendered"),
        false => Ok(staged.commit()?),
    });
    if created_dir {
        temporaries::forget(output_path);
        if rendered.is_err() {
            let _ = std::fs::remove_dir_all(output_path);
        }
    }
    rendered?;
    bar.finish();
    if output.json {
        let fields = json!({
            "output": path_text(output_path),
            "config": config,
            "model": model_json(&model, &model_name),
            "outputs": written.iter().map(|p| path_text(p)).collect::<Vec<_>>(),
        });
        print_json_summary("render", &selections, fields)?;
    } else if !output.quiet {
        println!("{}", model_line(&model, &model_name));
        println!(
            "wrote {}: ground truth | prediction | errors, each titled, with a scale bar and the legend of its colours",
            counted(written.len(), "picture")
        );
        for path in &written {
            println!("  {}", path.display());
        }
    }
    Ok(outcome(&selections))
}
