//! `travmap annotate`: the annotated MCAP (predicted and ground-truth grids, the
//! classified cloud, metrics, the input's messages copied through).

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, ValueEnum};
use serde_json::json;
use travmap_method::layers::Layer;
use travmap_outputs::annotation;
use travmap_outputs::annotation::{AnnotationOptions, CloudPoints, DRIVE_MAP_EVERY};
use travmap_run::report::tables::model_line;
use travmap_run::scoring::remarks::FitRemedies;

use super::adapt::AdaptFlag;
use super::convert::CompressionArg;
use super::{
    Inputs, ModelArg, Outcome, check_output, counted, fit_said, frame_count, model_json,
    note_extension, notice_drives, outcome, path_text, print_json_summary, print_wrote,
    with_summary,
};

/// Write the annotated MCAP: predicted and ground-truth grids, classified cloud, metrics.
#[derive(Args)]
#[command(mut_arg("sequences", super::one_input))]
#[command(
    after_long_help = "Examples (SEQ: a KITTI sequence folder, e.g. ../shared/data/semantickitti-00/sequences/00):\n  travmap annotate drive.mcap -o annotated.mcap\n  travmap annotate rosbag2_folder/ -o a.mcap --static-map\n  travmap annotate SEQ -o a.mcap --adapt"
)]
pub struct AnnotateArgs {
    #[command(flatten)]
    inputs: Inputs,
    /// Where to write the MCAP.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    model: ModelArg,
    #[command(flatten)]
    adapt: AdaptFlag,
    #[command(flatten)]
    compression: CompressionArg,
    /// Do not copy the input's messages into the output.
    #[arg(long)]
    no_passthrough: bool,
    /// Also write the final fused map once, at the end, on /map: an OccupancyGrid as
    /// nav2's map_server serves it (0 traversable, 100 not, -1 unseen), offered
    /// transient-local so that a replayed bag feeds a static map layer.
    #[arg(long)]
    static_map: bool,
    /// The points on /travmap/cloud, each with its cell's class (and ground
    /// truth): the frame's scan inside the grid, the whole scan (-1 outside the
    /// grid), or no cloud.
    #[arg(long, value_enum, default_value_t = CloudArg::Grid)]
    cloud: CloudArg,
    /// Frames between two fused maps of the drive so far on /travmap/drive_map (each
    /// covers the drive's bounding box; a map of B bytes waits at least B / 32 KiB
    /// frames, so that long drives do not fill the file with maps); 0: only the
    /// final map, after the last frame.
    #[arg(long, value_name = "FRAMES", default_value_t = DRIVE_MAP_EVERY)]
    drive_map_every: usize,
    /// The float layers of /travmap/grid_map (grid_map_msgs/msg/GridMap), comma
    /// separated: traversability (calibrated P), elevation, elevation_range, unsure,
    /// ground_truth (frames with labels); `none` writes no GridMap.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = LayerArg::ALL)]
    layers: Vec<LayerArg>,
    /// Height of the drawn grids relative to the sensor, metres.
    #[arg(long, default_value_t = -1.73, allow_negative_numbers = true, value_parser = super::parse_finite)]
    grid_height: f64,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum LayerArg {
    Traversability,
    Elevation,
    ElevationRange,
    Unsure,
    GroundTruth,
    None,
}

impl LayerArg {
    const ALL: [LayerArg; 5] = [
        LayerArg::Traversability,
        LayerArg::Elevation,
        LayerArg::ElevationRange,
        LayerArg::Unsure,
        LayerArg::GroundTruth,
    ];

    fn layer(self) -> Option<Layer> {
        match self {
            LayerArg::Traversability => Some(Layer::Traversability),
            LayerArg::Elevation => Some(Layer::Elevation),
            LayerArg::ElevationRange => Some(Layer::ElevationRange),
            LayerArg::Unsure => Some(Layer::Unsure),
            LayerArg::GroundTruth => Some(Layer::GroundTruth),
            LayerArg::None => None,
        }
    }
}

impl std::fmt::Display for LayerArg {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let value = self.to_possible_value().expect("no variant is skipped");
        f.write_str(value.get_name())
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum CloudArg {
    Grid,
    All,
    None,
}

pub fn annotate(args: AnnotateArgs) -> Result<Outcome> {
    let config = &args.model.config(&args.inputs.settings)?;
    let (output, output_path) = (args.inputs.output, args.output.as_path());
    check_output(
        output_path,
        &args.inputs.files(ModelArg::file(config).as_deref()),
    )?;
    note_extension(output_path, "mcap", "an MCAP file");
    let options = AnnotationOptions {
        compression: args.compression.compression(),
        passthrough: !args.no_passthrough,
        grid_height_m: args.grid_height,
        static_map: args.static_map,
        cloud: match args.cloud {
            CloudArg::Grid => CloudPoints::Grid,
            CloudArg::All => CloudPoints::All,
            CloudArg::None => CloudPoints::None,
        },
        drive_map_every: args.drive_map_every,
        layers: args.layers.iter().filter_map(|l| l.layer()).collect(),
    };
    let (model, model_name) = (args.adapt).apply(
        &args.inputs,
        config,
        args.inputs.settings.load_model(config)?,
        &output,
    )?;
    // Images only where the model reads them; they are copied through either way.
    let selection = args.inputs.open_one(config, model.reads_images(config))?;
    let mut metadata = BTreeMap::from([
        (
            "travmap_version".to_string(),
            env!("CARGO_PKG_VERSION").to_string(),
        ),
        ("config".to_string(), serde_json::to_string(config)?),
        ("model".to_string(), model_name.clone()),
        ("model_sha256".to_string(), model.sha256_hex()),
        (
            "model_rule".to_string(),
            model.config.ground_truth.rule.name().to_string(),
        ),
        ("input".to_string(), selection.describe()),
    ]);
    // An adapted model says how: self-supervised, from which prior and cells.
    if let Some(adaptation) = &model.training.adaptation {
        metadata.insert("adaptation".into(), serde_json::to_string(adaptation)?);
    }
    let selections = [selection];
    let bar = output.progress(frame_count(&selections), "annotating");
    let summary = annotation::annotate(
        &selections[0],
        config,
        &model,
        metadata,
        output_path,
        &options,
        &|| bar.inc(1),
    )?;
    let seconds = bar.finish();
    if output.json {
        let model = model_json(&model, &model_name);
        let fields = json!({"output": path_text(output_path), "config": config, "model": model, "elapsed_ms": seconds * 1e3});
        let fields = with_summary(fields, &summary)?;
        print_json_summary("annotate", &selections, fields)?;
    } else if !output.quiet {
        println!("{}", model_line(&model, &model_name));
        let copied = format!("{} messages copied through", summary.passthrough_messages);
        print_wrote(
            output_path,
            summary.frames,
            &copied,
            summary.output_bytes,
            seconds,
        );
        if let Some(s) = summary.evaluation.scores {
            println!(
                "{} with ground truth: Acc {:.1} mIoU {:.1} F1 {:.1} (filtered)",
                counted(summary.evaluation.scored_frames, "frame"),
                100.0 * s.accuracy,
                100.0 * s.miou,
                100.0 * s.f1
            );
        }
        println!("{}", fit_said(&summary.evaluation.fit));
    }
    let remedies = FitRemedies::of(&selections, true, None);
    notice_drives(&summary.evaluation, &model, config, remedies);
    Ok(outcome(&selections))
}
