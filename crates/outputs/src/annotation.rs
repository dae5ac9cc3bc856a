//! `travmap annotate`: the method's results as an MCAP that Foxglove, rerun and
//! rosbags open.
//!
//! Per frame, in the world frame (`map` for KITTI input): the filtered prediction and
//! the ground truth as `nav_msgs/msg/OccupancyGrid` (0 traversable, 100 not, -1
//! unknown), the frame's scan (by default its points inside the grid; see
//! [`CloudPoints`]) as a PointCloud2 with each point's cell
//! class, and `travmap_msgs/msg/FrameMetrics`; every few frames
//! ([`AnnotationOptions::drive_map_every`]) and after the last, the fused map of the
//! drive so far on `/travmap/drive_map` (an
//! OccupancyGrid: 100 x P(not traversable), -1 unseen). Per frame too, the same grid
//! as a `grid_map_msgs/msg/GridMap` of float layers on `/travmap/grid_map`
//! (`travmap_method::layers`: the calibrated P(traversable), the ground's elevation and its range,
//! the cells the model is unsure of, the ground truth), and the same layers as
//! `foxglove_msgs/msg/Grid` on `/travmap/grid`. With poses from registration,
//! `/tf` carries them. By default the input's own messages are
//! copied through (for KITTI input: what `convert` writes), so the file stands alone.
//! A metadata record `travmap` holds the version, the effective config and the
//! model's hash. The file is written atomically.

use std::collections::BTreeMap;
use std::path::Path;

use serde::Serialize;

use crate::conversion::{
    EncodedFrame, KittiFrameWriter, encode_kitti_frame, transform_from_pose, write_log_messages,
};
use crate::drive_map::{GridValues, occupancy_grid};
use crate::writing::McapSink;
use travmap_core::config::Config;
use travmap_core::error::{Error, Result};
use travmap_core::frame::Frame;
use travmap_core::posing::Posing;
use travmap_formats::mcap::writer::Compression;
use travmap_formats::ros::{
    Float32MultiArray, FoxgloveGrid, FoxgloveVector2, FrameMetrics, GridMap, GridMapInfo, Header,
    MapMetaData, MultiArrayDimension, MultiArrayLayout, OccupancyGrid, PackedElementField,
    PointCloud2, PointField, Pose, Quaternion, TfMessage, Time, TransformStamped, Vector3,
    datatype,
};
use travmap_io::Recorded;
use travmap_method::classifier::SvmModel;
use travmap_method::grid::CellClass;
use travmap_method::layers::{Layer, layer_values};
use travmap_method::pipeline::FrameResult;
use travmap_run::scoring::evaluation::{Evaluation, EvaluationReport, Fit};
use travmap_run::scoring::metrics::Confusion;
use travmap_run::{DriveRun, RunEvent};

pub const PREDICTION_TOPIC: &str = "/travmap/prediction";
pub const GROUND_TRUTH_TOPIC: &str = "/travmap/ground_truth";
pub const CLOUD_TOPIC: &str = "/travmap/cloud";
pub const METRICS_TOPIC: &str = "/travmap/metrics";
/// The fused map of the drive so far ([`travmap_method::fusion`]).
pub const DRIVE_MAP_TOPIC: &str = "/travmap/drive_map";
/// Each frame's float layers, as grid_map publishes them.
pub const GRID_MAP_TOPIC: &str = "/travmap/grid_map";
/// The same layers as `foxglove_msgs/msg/Grid`, which Foxglove's 3D panel colours
/// with no extension (ROS 2 CDR like every other channel, so that rosbags and
/// ROS-only readers open the file too).
pub const FOXGLOVE_GRID_TOPIC: &str = "/travmap/grid";
/// foxglove's NumericType FLOAT32.
const FOXGLOVE_FLOAT32: u8 = 7;
/// With [`AnnotationOptions::static_map`]: the final map once, as map_server serves it.
pub const STATIC_MAP_TOPIC: &str = "/map";
/// The default of [`AnnotationOptions::drive_map_every`].
pub const DRIVE_MAP_EVERY: usize = 10;

/// What the maps on [`DRIVE_MAP_TOPIC`] may add to each frame, on average: a map of
/// B bytes is followed by at least B / this frames. A map covers the drive's bounding
/// box, so at a fixed cadence their sum grew with the cube of a long drive's extent;
/// this keeps it linear in the frames. About 2 % of a frame annotated with its
/// passthrough scan. On the first 3,000 poses of KITTI sequence 00 the maps reach
/// the 320 KB that slows the default cadence after frame 790: 165 maps, 85 MB,
/// instead of 300 and 228 MB.
pub const DRIVE_MAP_BYTES_PER_FRAME: usize = 32 * 1024;

/// When the next map on [`DRIVE_MAP_TOPIC`] is due.
#[derive(Clone, Debug)]
struct DriveMapCadence {
    every: usize,
    since_last: usize,
    wait: usize,
}

impl DriveMapCadence {
    fn new(every: usize) -> Self {
        Self {
            every,
            since_last: 0,
            wait: every,
        }
    }

    /// Counts a frame; whether a map is due after it.
    fn frame(&mut self) -> bool {
        self.since_last += 1;
        self.every > 0 && self.since_last >= self.wait
    }

    /// A map of `bytes` was written after the last frame.
    fn wrote(&mut self, bytes: usize) {
        self.since_last = 0;
        self.wait = self.every.max(bytes / DRIVE_MAP_BYTES_PER_FRAME);
    }

    /// Frames came since the last map: the final one is still to write.
    fn final_due(&self) -> bool {
        self.since_last > 0
    }
}

#[derive(Clone, Debug)]
pub struct AnnotationOptions {
    pub compression: Compression,
    /// Copy the input's messages into the output.
    pub passthrough: bool,
    /// Height of the drawn grids relative to the sensor, metres (KITTI's HDL-64E sits
    /// 1.73 m above the road).
    pub grid_height_m: f64,
    /// Also write the final fused map once, at the end, on [`STATIC_MAP_TOPIC`].
    pub static_map: bool,
    /// What [`CLOUD_TOPIC`] holds.
    pub cloud: CloudPoints,
    /// Frames between two maps on [`DRIVE_MAP_TOPIC`] (default [`DRIVE_MAP_EVERY`]);
    /// 0: only the final one. Each covers the drive's bounding box so far, so on a
    /// long drive they grow with the square of its extent, and a large one waits
    /// longer ([`DRIVE_MAP_BYTES_PER_FRAME`]).
    pub drive_map_every: usize,
    /// The layers of [`GRID_MAP_TOPIC`] (none: no GridMap).
    pub layers: Vec<Layer>,
}

#[derive(Clone, Debug, Serialize)]
pub struct AnnotationSummary {
    pub frames: usize,
    pub passthrough_messages: usize,
    pub output_bytes: u64,
    /// Its figures stand beside the others in a `--json` summary.
    #[serde(flatten)]
    pub evaluation: EvaluationReport,
}

fn grid_message(
    result: &FrameResult,
    classes: &[CellClass],
    world_frame: &str,
    height_m: f64,
) -> OccupancyGrid {
    let [x, y] = result.layout.min_corner_in_world();
    let stamp = Time::from_ns(result.stamp_ns);
    OccupancyGrid {
        header: Header {
            stamp,
            frame_id: world_frame.into(),
        },
        info: MapMetaData {
            map_load_time: stamp,
            resolution: result.layout.cell_size_m as f32,
            width: result.layout.cells_per_side as u32,
            height: result.layout.cells_per_side as u32,
            origin: Pose {
                position: Vector3 {
                    x,
                    y,
                    z: result.sensor_in_world[2] + height_m,
                },
                orientation: Quaternion::default(),
            },
        },
        data: classes.iter().map(|&c| c.occupancy()).collect(),
    }
}

/// A frame's layers as a GridMap, placed as its OccupancyGrids are (centred on
/// theirs, `height_m` above the sensor): grid_map's order, column-major from the cell of
/// largest x and y; NaN where a layer has no value.
fn grid_map_message(
    result: &FrameResult,
    layers: &[Layer],
    world_frame: &str,
    height_m: f64,
) -> GridMap {
    let layout = &result.layout;
    let side = layout.cells_per_side;
    let size_m = side as f64 * layout.cell_size_m;
    let [min_x, min_y] = layout.min_corner_in_world();
    let pose_z = result.sensor_in_world[2] + height_m;
    let layers: Vec<(Layer, Vec<f32>)> = (layers.iter())
        .filter_map(|&layer| Some((layer, layer_values(result, layer, pose_z)?)))
        .collect();
    // grid_map's index (i, j): i along -x, j along -y; stored column-major, j outer.
    let data = layers
        .iter()
        .map(|(_, by_cell)| {
            let mut values = Vec::with_capacity(side * side);
            for j in 0..side {
                for i in 0..side {
                    let (col, row) = (side - 1 - i, side - 1 - j);
                    values.push(by_cell[row * side + col]);
                }
            }
            Float32MultiArray {
                layout: MultiArrayLayout {
                    dim: vec![
                        MultiArrayDimension {
                            label: "column_index".into(),
                            size: side as u32,
                            stride: (side * side) as u32,
                        },
                        MultiArrayDimension {
                            label: "row_index".into(),
                            size: side as u32,
                            stride: side as u32,
                        },
                    ],
                    data_offset: 0,
                },
                data: values,
            }
        })
        .collect();
    GridMap {
        header: Header {
            stamp: Time::from_ns(result.stamp_ns),
            frame_id: world_frame.into(),
        },
        info: GridMapInfo {
            resolution: layout.cell_size_m,
            length_x: size_m,
            length_y: size_m,
            pose: Pose {
                position: Vector3 {
                    x: min_x + size_m / 2.0,
                    y: min_y + size_m / 2.0,
                    z: pose_z,
                },
                orientation: Quaternion::default(),
            },
        },
        layers: layers.iter().map(|(l, _)| l.name().to_string()).collect(),
        basic_layers: vec![Layer::Traversability.name().to_string()],
        data,
        outer_start_index: 0,
        inner_start_index: 0,
    }
}

/// A frame's layers as a `foxglove_msgs/msg/Grid`: row-major from the grid's min
/// corner (its pose), each cell the layers' float32 values side by side.
fn foxglove_grid_message(
    result: &FrameResult,
    layers: &[Layer],
    world_frame: &str,
    height_m: f64,
) -> FoxgloveGrid {
    let layout = &result.layout;
    let side = layout.cells_per_side;
    let [min_x, min_y] = layout.min_corner_in_world();
    let pose_z = result.sensor_in_world[2] + height_m;
    let layers: Vec<(Layer, Vec<f32>)> = (layers.iter())
        .filter_map(|&layer| Some((layer, layer_values(result, layer, pose_z)?)))
        .collect();
    let cell_stride = 4 * layers.len();
    let mut data = Vec::with_capacity(cell_stride * side * side);
    for cell in 0..side * side {
        for (_, values) in &layers {
            data.extend_from_slice(&values[cell].to_le_bytes());
        }
    }
    FoxgloveGrid {
        timestamp: Time::from_ns(result.stamp_ns),
        frame_id: world_frame.into(),
        pose: Pose {
            position: Vector3 {
                x: min_x,
                y: min_y,
                z: pose_z,
            },
            orientation: Quaternion::default(),
        },
        column_count: side as u32,
        cell_size: FoxgloveVector2 {
            x: layout.cell_size_m,
            y: layout.cell_size_m,
        },
        row_stride: (cell_stride * side) as u32,
        cell_stride: cell_stride as u32,
        fields: (layers.iter().enumerate())
            .map(|(k, (layer, _))| PackedElementField {
                name: layer.name().into(),
                offset: 4 * k as u32,
                r#type: FOXGLOVE_FLOAT32,
            })
            .collect(),
        data,
    }
}

/// The points of a frame's `/travmap/cloud`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CloudPoints {
    /// The frame's own scan's points inside the grid: each point once over the
    /// drive (the window's older scans were written with their own frames).
    Grid,
    /// Every point of the frame's scan; outside the grid class -1 (unknown).
    All,
    /// No cloud.
    None,
}

/// The frame's points in world coordinates (float64: a world in UTM coordinates keeps
/// them to the millimetre) with `class` (and `ground_truth`) int8: the occupancy
/// values of their cells (0 traversable, 100 not, -1 unknown).
fn cloud_message(
    result: &FrameResult,
    classes: &[CellClass],
    world_frame: &str,
    which: CloudPoints,
) -> Option<PointCloud2> {
    let layout = &result.layout;
    let [min_x, min_y] = layout.min_corner_in_drive();
    let occupancy = |cell: Option<usize>| {
        let of = |grid: &[CellClass]| cell.and_then(|c| grid.get(c)).map_or(-1, |c| c.occupancy());
        let truth = result.ground_truth.as_deref().map_or(-1, of);
        [of(classes) as u8, truth as u8, 0, 0]
    };
    let points = match which {
        CloudPoints::Grid => result.cells.newest_len(),
        CloudPoints::All => result.scan_in_drive.len(),
        CloudPoints::None => 0,
    };
    let mut data = Vec::with_capacity(points * CLOUD_POINT_STEP);
    let mut put = |xyz: [f64; 3], cell: Option<usize>| {
        for v in xyz {
            data.extend_from_slice(&v.to_le_bytes());
        }
        data.extend_from_slice(&occupancy(cell));
        data.extend_from_slice(&[0; CLOUD_POINT_STEP - 28]);
    };
    match which {
        CloudPoints::None => return None,
        CloudPoints::Grid => {
            for cell in 0..layout.cell_count() {
                for &p in result.cells.newest(cell) {
                    put(layout.grid_point_in_world(p), Some(cell));
                }
            }
        }
        CloudPoints::All => {
            for p in result.scan_in_drive.iter() {
                let cell = layout.cell_of_local(p[0] as f64 - min_x, p[1] as f64 - min_y);
                let in_drive = p.map(f64::from);
                put(layout.drive.point_in_world(in_drive), cell);
            }
        }
    }
    let mut fields = vec![
        PointField::scalar("x", 0, datatype::FLOAT64),
        PointField::scalar("y", 8, datatype::FLOAT64),
        PointField::scalar("z", 16, datatype::FLOAT64),
        PointField::scalar("class", 24, datatype::INT8),
    ];
    if result.ground_truth.is_some() {
        fields.push(PointField::scalar("ground_truth", 25, datatype::INT8));
    }
    Some(PointCloud2 {
        header: Header {
            stamp: Time::from_ns(result.stamp_ns),
            frame_id: world_frame.into(),
        },
        height: 1,
        width: points as u32,
        fields,
        is_bigendian: false,
        point_step: CLOUD_POINT_STEP as u32,
        row_step: data.len() as u32,
        data,
        is_dense: true,
    })
}

/// x, y, z float64, class and ground truth int8, six bytes that keep points 8-byte
/// aligned (viewers read the floats in place).
const CLOUD_POINT_STEP: usize = 32;

fn metrics_message(result: &FrameResult, classes: &[CellClass], world_frame: &str) -> FrameMetrics {
    let count = |class: CellClass| classes.iter().filter(|&&c| c == class).count() as u32;
    let confusion = result
        .ground_truth
        .as_ref()
        .map(|truth| Confusion::of_grids(classes, truth));
    let c = confusion.unwrap_or_default();
    let scores = confusion.map(|c| c.scores());
    FrameMetrics {
        header: Header {
            stamp: Time::from_ns(result.stamp_ns),
            frame_id: world_frame.into(),
        },
        frame_index: result.index as u32,
        predictable_cells: count(CellClass::Traversable) + count(CellClass::NonTraversable),
        traversable_cells: count(CellClass::Traversable),
        non_traversable_cells: count(CellClass::NonTraversable),
        has_ground_truth: confusion.is_some(),
        true_positives: c.tp as u32,
        true_negatives: c.tn as u32,
        false_positives: c.fp as u32,
        false_negatives: c.r#fn as u32,
        unpredictable_with_ground_truth: c.unknown as u32,
        accuracy: scores.map_or(f32::NAN, |s| s.accuracy as f32),
        miou: scores.map_or(f32::NAN, |s| s.miou as f32),
        f1: scores.map_or(f32::NAN, |s| s.f1 as f32),
        latency_ms: result.timings.latency_ms as f32,
        dropped_points: result.dropped_points as u32,
        unsure_cells: result.margins.as_deref().map_or(0, |m| Fit::counts(m).1) as u32,
    }
}

/// Annotates `selection` into `output`; `metadata` goes into the `travmap` record.
pub fn annotate(
    selection: &DriveRun,
    config: &Config,
    model: &SvmModel,
    metadata: BTreeMap<String, String>,
    output: &Path,
    options: &AnnotationOptions,
    on_frame: &(dyn Fn() + Sync),
) -> Result<AnnotationSummary> {
    let mut sink = McapSink::create(output, options.compression)?;
    let mut passthrough_messages = 0;
    // A KITTI frame's messages are made from the frame as the method's reader reads
    // it (not read a second time), and written as they come, ahead of its results.
    let mut kitti_passthrough = None;
    // A folder of scans or a site cloud has no messages to pass through.
    let recorded = selection.source.recorded();
    let (passthrough_kitti, passthrough_log) = match &recorded {
        _ if !options.passthrough => (None, None),
        Recorded::Kitti(sequence) => (Some(sequence), None),
        Recorded::Log(drive) => (None, Some(drive)),
        Recorded::FramesOnly => (None, None),
    };
    if let Some(sequence) = passthrough_kitti {
        kitti_passthrough = Some(KittiFrameWriter::new(sequence));
    }
    if let Some(drive) = passthrough_log {
        sink.copy_chunks_by_time();
        passthrough_messages = write_log_messages(&mut sink, drive, true, &|_, _| {})?.messages;
    }
    let encode_passthrough = |frame: &Frame| match passthrough_kitti {
        Some(sequence) => encode_kitti_frame(sequence, frame, 0),
        None => Ok(None),
    };
    let world_frame = selection.source.world_frame().to_string();
    let posing = selection.source.posing();
    // Estimated poses go on /tf, unless passthrough writes KITTI's recorded ones there.
    let kitti_tf = passthrough_kitti.is_some();
    let write_estimated_tf = posing == Posing::Registration && !kitti_tf;
    let sensor_frame = selection.source.sensor_frame().to_string();
    let mut evaluation = Evaluation::default();
    let mut frames = 0;
    let mut last_stamp_ns = 0;
    let mut cadence = DriveMapCadence::new(options.drive_map_every);
    let on_handed = |handed: RunEvent<'_, Option<EncodedFrame>>| {
        let (result, drive_map) = match handed {
            RunEvent::Read(encoded) => {
                return match (&mut kitti_passthrough, encoded) {
                    (Some(writer), Some(frame)) => writer.write(&mut sink, frame),
                    _ => Ok(()),
                };
            }
            RunEvent::Result(result, drive_map) => (result, drive_map),
        };
        let classes = result.filtered.as_deref().unwrap_or(&[]);
        let stamp = result.stamp_ns;
        if write_estimated_tf {
            let tf = TfMessage {
                transforms: vec![TransformStamped {
                    header: Header {
                        stamp: Time::from_ns(stamp),
                        frame_id: world_frame.clone(),
                    },
                    child_frame_id: sensor_frame.clone(),
                    transform: transform_from_pose(&result.world_from_velodyne),
                }],
            };
            sink.write("/tf", stamp, &tf)?;
        }
        sink.write(
            PREDICTION_TOPIC,
            stamp,
            &grid_message(&result, classes, &world_frame, options.grid_height_m),
        )?;
        if let Some(truth) = &result.ground_truth {
            sink.write(
                GROUND_TRUTH_TOPIC,
                stamp,
                &grid_message(&result, truth, &world_frame, options.grid_height_m),
            )?;
        }
        if !options.layers.is_empty() {
            let layers = grid_map_message(
                &result,
                &options.layers,
                &world_frame,
                options.grid_height_m,
            );
            sink.write(GRID_MAP_TOPIC, stamp, &layers)?;
            let grid = foxglove_grid_message(
                &result,
                &options.layers,
                &world_frame,
                options.grid_height_m,
            );
            sink.write(FOXGLOVE_GRID_TOPIC, stamp, &grid)?;
        }
        if let Some(cloud) = cloud_message(&result, classes, &world_frame, options.cloud) {
            sink.write(CLOUD_TOPIC, stamp, &cloud)?;
        }
        sink.write(
            METRICS_TOPIC,
            stamp,
            &metrics_message(&result, classes, &world_frame),
        )?;
        evaluation.add(&result);
        last_stamp_ns = stamp;
        frames += 1;
        if cadence.frame() {
            let grid = occupancy_grid(
                drive_map,
                &world_frame,
                stamp,
                options.grid_height_m,
                GridValues::Probability,
            )?;
            cadence.wrote(grid.data.len());
            sink.write(DRIVE_MAP_TOPIC, stamp, &grid)?;
        }
        on_frame();
        Ok(())
    };
    let drive_map = selection.run_mapped_beside::<Error, _>(
        config,
        Some(model),
        &encode_passthrough,
        on_handed,
    )?;
    if frames == 0 {
        let inputs = selection.source.path().display().to_string();
        return Err(travmap_io::nothing_read(
            output,
            inputs,
            &selection.source.skipped(),
        ));
    }
    if let Some(writer) = &kitti_passthrough {
        let written = &writer.summary;
        passthrough_messages = written.frames * 2 + written.images * 2 + 1;
    }
    if cadence.final_due() {
        let grid = occupancy_grid(
            &drive_map,
            &world_frame,
            last_stamp_ns,
            options.grid_height_m,
            GridValues::Probability,
        )?;
        sink.write(DRIVE_MAP_TOPIC, last_stamp_ns, &grid)?;
    }
    if options.static_map {
        // At z 0 in the world frame, as a map layer expects; offered transient-local so
        // that a replayed bag hands it to subscribers that join late, as map_server does.
        let map = occupancy_grid(
            &drive_map,
            &world_frame,
            last_stamp_ns,
            0.0,
            GridValues::Trinary,
        )?;
        sink.write_latched(STATIC_MAP_TOPIC, last_stamp_ns, &map)?;
    }
    let mut metadata = metadata;
    metadata.insert("poses".into(), posing.describe().into());
    let skipped = selection.source.skipped();
    if !skipped.is_empty() {
        // serde_json cannot fail on a list of plain structs.
        metadata.insert(
            "skipped_frames".into(),
            serde_json::to_string(&skipped).unwrap_or_default(),
        );
    }
    sink.write_metadata("travmap", metadata)?;
    sink.finish()?;
    Ok(AnnotationSummary {
        frames,
        passthrough_messages,
        output_bytes: std::fs::metadata(output)
            .map_err(|e| Error::io(output, e))?
            .len(),
        evaluation: evaluation.report(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The frames (1-based) after which a map is written, each map `bytes(frame)` long.
    fn written(every: usize, frames: usize, bytes: impl Fn(usize) -> usize) -> Vec<usize> {
        let mut cadence = DriveMapCadence::new(every);
        let mut at = Vec::new();
        for frame in 1..=frames {
            if cadence.frame() {
                cadence.wrote(bytes(frame));
                at.push(frame);
            }
        }
        at
    }

    #[test]
    fn small_maps_keep_the_asked_cadence() {
        assert_eq!(written(10, 35, |_| 2_000), [10, 20, 30]);
        assert!(written(0, 35, |_| 2_000).is_empty());
        let mut cadence = DriveMapCadence::new(10);
        assert!(!cadence.final_due());
        (0..10).for_each(|_| _ = cadence.frame());
        cadence.wrote(2_000);
        assert!(
            !cadence.final_due(),
            "the last frame's map is the final one"
        );
        cadence.frame();
        assert!(cadence.final_due());
    }

    #[test]
    fn a_large_map_waits_for_its_bytes_to_spread_over_frames() {
        // 1 MiB maps: 32 frames apart, whatever was asked below that.
        assert_eq!(written(10, 100, |_| 1 << 20), [10, 42, 74]);
        // A map growing with the square of the frames (a straight drive's bounding
        // box): every map but the last is paid for by the frames after it, at most
        // the budget each (one more per map for the rounding).
        let bytes = |frame: usize| frame * frame / 10;
        let at = written(10, 20_000, bytes);
        let before_last: usize = at[..at.len() - 1].iter().map(|&f| bytes(f)).sum();
        assert!(
            before_last <= (20_000 + at.len()) * DRIVE_MAP_BYTES_PER_FRAME,
            "{before_last} bytes of maps in 20,000 frames"
        );
        // At a fixed cadence, 40 times as many bytes.
        let fixed: usize = (1..=2_000).map(|k| bytes(10 * k)).sum();
        assert!(fixed > 40 * before_last, "{fixed} against {before_last}");
        assert!(at.windows(2).all(|w| w[1] - w[0] >= 10));
    }
}
