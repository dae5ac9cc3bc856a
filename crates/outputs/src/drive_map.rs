//! The fused map of a drive ([`travmap_method::fusion`]) as outputs: a picture (the
//! map with the trajectory, a scale bar and the world axes; with ground truth, the
//! fused ground truth and the errors beside it), a Parquet table of its cells, and
//! a `nav_msgs/msg/OccupancyGrid` for annotated MCAP.

use std::io::BufWriter;
use std::path::Path;
use std::sync::Arc;

use parquet::basic::{Compression, ZstdLevel};
use parquet::column::writer::ColumnWriter;
use parquet::file::properties::WriterProperties;
use parquet::file::writer::SerializedFileWriter;

use crate::atomic::{AtomicFile, Staged, parquet_failure, sync_output, write_failure};
use crate::figure::{Panel, Swatch, blank, compose, draw_text, fill_rect};
use crate::palette::Palette;
use travmap_core::error::{Error, Result};
use travmap_core::frame::RgbImage;
use travmap_formats::ros::{Header, MapMetaData, OccupancyGrid, Pose, Quaternion, Time, Vector3};
use travmap_method::fusion::{DriveMap, FusedCell, Lattice};
use travmap_method::grid::CellClass;

/// Cells of empty border around the map in the picture.
const BORDER_CELLS: i64 = 2;
/// Length of each world axis drawn at the origin, metres.
pub const AXIS_M: f64 = 2.0;

/// The most cells or pixels one dense image of a map may hold: 2^28 (256 MiB at a
/// byte each; a 53 km square at 0.4 m cells and 8 pixels a cell, 6.5 km). More is a
/// pose or a point far from the rest, not a drive.
pub const MAX_IMAGE_CELLS: u64 = 1 << 28;

/// Refuses a dense image of `size` units (cells or pixels) of `unit_m` metres, named
/// `what`, beyond [`MAX_IMAGE_CELLS`]; `hint` says what else to do.
pub fn check_image_size(
    what: &'static str,
    size: [u64; 2],
    (unit, unit_m): (&'static str, f64),
    hint: &'static str,
) -> Result<()> {
    if size[0].saturating_mul(size[1]) <= MAX_IMAGE_CELLS {
        return Ok(());
    }
    Err(Error::MapTooLarge {
        what,
        columns: size[0],
        rows: size[1],
        unit,
        width_m: size[0] as f64 * unit_m,
        height_m: size[1] as f64 * unit_m,
        limit: MAX_IMAGE_CELLS,
        hint,
    })
}

/// The cells' key range, padded with [`BORDER_CELLS`]: (lowest key, cells per side).
fn extent(cells: &[FusedCell]) -> ([i64; 2], [usize; 2]) {
    let bounds = cells.iter().fold(None, |bounds, cell| {
        let (low, high): ([i64; 2], [i64; 2]) = bounds.unwrap_or((cell.key, cell.key));
        Some((
            [low[0].min(cell.key[0]), low[1].min(cell.key[1])],
            [high[0].max(cell.key[0]), high[1].max(cell.key[1])],
        ))
    });
    padded_extent(bounds)
}

/// A key range (lowest, highest; None for no cells, read as the one cell 0, 0)
/// padded with [`BORDER_CELLS`]: (lowest key, cells per side).
fn padded_extent(bounds: Option<([i64; 2], [i64; 2])>) -> ([i64; 2], [usize; 2]) {
    let (low, high) = bounds.unwrap_or(([0, 0], [0, 0]));
    let low = [low[0] - BORDER_CELLS, low[1] - BORDER_CELLS];
    // Saturating: a key range no image holds is refused by its size, not wrapped.
    let side = |axis: usize| {
        (high[axis].saturating_add(BORDER_CELLS + 1))
            .saturating_sub(low[axis])
            .max(0) as usize
    };
    (low, [side(0), side(1)])
}

/// The layout of a drive map picture: where each world cell lands.
pub struct MapPicture {
    pub low_key: [i64; 2],
    pub cells: [usize; 2],
    pub cell_px: u32,
}

impl MapPicture {
    pub fn of(cells: &[FusedCell], cell_px: u32) -> Self {
        let (low_key, cells) = extent(cells);
        Self {
            low_key,
            cells,
            cell_px,
        }
    }

    fn panel_px(&self) -> (u32, u32) {
        (
            self.cells[0] as u32 * self.cell_px,
            self.cells[1] as u32 * self.cell_px,
        )
    }

    /// Top-left pixel of world cell `key` in the first panel (north up).
    pub fn cell_origin_px(&self, key: [i64; 2]) -> (u32, u32) {
        let col = (key[0] - self.low_key[0]) as u32;
        let row = (key[1] - self.low_key[1]) as u32;
        (
            col * self.cell_px,
            (self.cells[1] as u32 - 1 - row) * self.cell_px,
        )
    }

    /// The pixel of a world point (x, y metres) in the first panel, if inside.
    fn point_px(&self, x_m: f64, y_m: f64, lattice: &Lattice) -> Option<(u32, u32)> {
        let (width, height) = self.panel_px();
        let [col, row] = lattice.in_cells(x_m, y_m);
        let px = (col - self.low_key[0] as f64) * self.cell_px as f64;
        let from_bottom = (row - self.low_key[1] as f64) * self.cell_px as f64;
        let py = height as f64 - from_bottom;
        (px >= 0.0 && py >= 0.0 && px < width as f64 && py < height as f64)
            .then_some((px as u32, py as u32))
    }
}

/// The map picture of `cells` (on `lattice`), in `palette`'s colours: the fused
/// prediction, and with ground truth the fused ground truth and the errors, each under
/// its title; the trajectory (sensor positions, x-y metres in the world) in the
/// marker's colour, the world axes at its origin when the picture shows it
/// ([`AXIS_M`] long, their ends labelled), a scale bar and a legend below.
pub fn render_drive_map(
    cells: &[FusedCell],
    trajectory: &[[f64; 2]],
    lattice: &Lattice,
    cell_px: u32,
    palette: &Palette,
) -> Result<RgbImage> {
    let cell_size_m = lattice.cell_size_m;
    let picture = MapPicture::of(cells, cell_px);
    let with_truth = cells.iter().any(|c| c.ground_truth != CellClass::Unknown);
    let panels = if with_truth { 3 } else { 1 };
    let pixels_per_side = picture.cells.map(|n| n as u64 * cell_px as u64);
    check_image_size(
        "the drive map picture",
        [pixels_per_side[0] * panels as u64, pixels_per_side[1]],
        ("pixel", cell_size_m / cell_px as f64),
        "--frames chooses a stretch; --cell-pixels 1 draws a pixel a cell",
    )?;
    let (panel_w, panel_h) = picture.panel_px();
    let titles = ["fused map", "fused ground truth", "errors"];
    let mut images: Vec<RgbImage> = (0..panels)
        .map(|_| blank(panel_w, panel_h, palette.unknown))
        .collect();
    for cell in cells {
        let (x0, y0) = picture.cell_origin_px(cell.key);
        let colours = [
            palette.class(cell.class),
            palette.class(cell.ground_truth),
            palette.error(cell.class, cell.ground_truth),
        ];
        for (image, colour) in images.iter_mut().zip(colours) {
            fill_rect(image, x0 as i64, y0 as i64, cell_px, cell_px, colour);
        }
    }
    // Overlays on every panel: the trajectory, then the axes.
    // At most a step a pixel along the picture's diagonal and back, whatever the
    // distance (a trajectory point outside the picture is not drawn).
    let most_steps = 2 * (panel_w + panel_h) as usize;
    let steps = |length_m: f64| {
        ((length_m / cell_size_m * cell_px as f64).ceil() as usize * 2).min(most_steps)
    };
    let line = |images: &mut [RgbImage], from: [f64; 2], to: [f64; 2], width: u32, c: [u8; 3]| {
        let n = steps(((to[0] - from[0]).hypot(to[1] - from[1])).max(cell_size_m));
        for i in 0..=n {
            let t = i as f64 / n as f64;
            let (x, y) = (
                from[0] + t * (to[0] - from[0]),
                from[1] + t * (to[1] - from[1]),
            );
            if let Some((px, py)) = picture.point_px(x, y, lattice) {
                let half = (width / 2) as i64;
                for image in images.iter_mut() {
                    fill_rect(image, px as i64 - half, py as i64 - half, width, width, c);
                }
            }
        }
    };
    // The trajectory, in the marker's colour over an edge of its own.
    for (width, colour) in [(3, palette.marker_edge), (1, palette.marker)] {
        for pair in trajectory.windows(2) {
            line(&mut images, pair[0], pair[1], width, colour);
        }
        if let [only] = trajectory {
            line(&mut images, *only, *only, width, colour);
        }
    }
    for (end, name) in [([AXIS_M, 0.0], "x"), ([0.0, AXIS_M], "y")] {
        line(&mut images, [0.0, 0.0], end, 3, palette.marker_edge);
        line(&mut images, [0.0, 0.0], end, 1, palette.marker);
        if let Some((px, py)) = picture.point_px(end[0], end[1], lattice) {
            for image in images.iter_mut() {
                draw_text(
                    image,
                    px + 3,
                    py.saturating_sub(18),
                    name,
                    15.0,
                    palette.marker,
                );
            }
        }
    }
    let panels: Vec<Panel> = (titles.iter().zip(images))
        .map(|(title, image)| Panel {
            title: title.to_string(),
            image,
        })
        .collect();
    let mut legend: Vec<(Swatch, &str)> = match with_truth {
        true => palette.legend(),
        false => palette.legend().into_iter().take(3).collect(),
    }
    .into_iter()
    .map(|(colour, words)| (Swatch::Fill(colour), words))
    .collect();
    legend.push((Swatch::Line, "trajectory"));
    Ok(compose(
        &panels,
        &legend,
        cell_size_m / cell_px as f64,
        palette,
    ))
}

/// The fused cells as a Parquet table: one row per cell some frame saw or labelled,
/// staged to appear with the command's other outputs; `metadata` (key, JSON text)
/// says what made them (`travmap.config`, `travmap.model`).
pub fn write_map_cells(
    staged: &mut Staged,
    path: &Path,
    cells: &[FusedCell],
    metadata: Vec<(String, String)>,
) -> Result<()> {
    let schema = parquet::schema::parser::parse_message_type(
        "message travmap_run_map { REQUIRED DOUBLE x_m; REQUIRED DOUBLE y_m; \
         REQUIRED DOUBLE evidence; REQUIRED DOUBLE probability; REQUIRED INT32 observations; \
         OPTIONAL BOOLEAN predicted_traversable; OPTIONAL BOOLEAN ground_truth_traversable; }",
    )
    .expect("the map schema parses");
    let properties = WriterProperties::builder()
        .set_compression(Compression::ZSTD(ZstdLevel::default()))
        .set_created_by(concat!("travmap ", env!("CARGO_PKG_VERSION")).into())
        .set_key_value_metadata(Some(
            (metadata.into_iter())
                .map(|(key, value)| parquet::file::metadata::KeyValue::new(key, value))
                .collect(),
        ))
        .build();
    let (output, file) = AtomicFile::create(path)?;
    let fail = |e| parquet_failure(path, &output, e);
    let mut writer =
        SerializedFileWriter::new(BufWriter::new(file), Arc::new(schema), Arc::new(properties))
            .map_err(fail)?;
    let doubles: [Vec<f64>; 4] = [
        cells.iter().map(|c| c.x_m).collect(),
        cells.iter().map(|c| c.y_m).collect(),
        cells.iter().map(|c| c.evidence).collect(),
        cells.iter().map(|c| c.probability).collect(),
    ];
    let observations: Vec<i32> = cells.iter().map(|c| c.observations as i32).collect();
    let nullable = |class: fn(&FusedCell) -> CellClass| {
        let values: Vec<bool> = cells
            .iter()
            .map(class)
            .filter(|c| *c != CellClass::Unknown)
            .map(|c| c == CellClass::Traversable)
            .collect();
        let defined: Vec<i16> = cells
            .iter()
            .map(|c| (class(c) != CellClass::Unknown) as i16)
            .collect();
        (values, defined)
    };
    let booleans = [nullable(|c| c.class), nullable(|c| c.ground_truth)];
    let mut group = writer.next_row_group().map_err(fail)?;
    let mut index = 0;
    while let Some(mut column) = group.next_column().map_err(fail)? {
        let written = match column.untyped() {
            ColumnWriter::DoubleColumnWriter(w) => w.write_batch(&doubles[index], None, None),
            ColumnWriter::Int32ColumnWriter(w) => w.write_batch(&observations, None, None),
            ColumnWriter::BoolColumnWriter(w) => {
                let (values, defined) = &booleans[index - 5];
                w.write_batch(values, Some(defined), None)
            }
            _ => unreachable!("column {index} is not in the map schema"),
        };
        written.map_err(fail)?;
        column.close().map_err(fail)?;
        index += 1;
    }
    group.close().map_err(fail)?;
    let file = writer
        .into_inner()
        .map_err(fail)?
        .into_inner()
        .map_err(|e| write_failure(path, &output, Some(e.into_error()), None))?;
    sync_output(&file).map_err(|source| write_failure(path, &output, Some(source), None))?;
    staged.add(output);
    Ok(())
}

/// How a fused cell becomes an OccupancyGrid value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GridValues {
    /// 100 x P(not traversable), rounded: a costmap's view.
    Probability,
    /// 0 traversable, 100 not, -1 undecided: what nav2's map_server serves.
    Trinary,
}

/// The fused map as an OccupancyGrid in `frame_id` at height `height_m`: -1 where no
/// frame saw a cell, else the cell's value as `values` says.
pub fn occupancy_grid(
    map: &DriveMap,
    frame_id: &str,
    stamp_ns: u64,
    height_m: f64,
    values: GridValues,
) -> Result<OccupancyGrid> {
    let lattice = map.lattice();
    let cell_size_m = lattice.cell_size_m;
    let (low, size) = padded_extent(map.observed_bounds());
    check_image_size(
        "the drive map's OccupancyGrid",
        size.map(|n| n as u64),
        ("cell", cell_size_m),
        "--frames chooses a stretch",
    )?;
    let mut data = vec![-1i8; size[0] * size[1]];
    for cell in map.each_cell().filter(|c| c.observations > 0) {
        let col = (cell.key[0] - low[0]) as usize;
        let row = (cell.key[1] - low[1]) as usize;
        data[row * size[0] + col] = match (values, cell.class) {
            (GridValues::Probability, _) => (100.0 * (1.0 - cell.probability)).round() as i8,
            (GridValues::Trinary, CellClass::Traversable) => 0,
            (GridValues::Trinary, CellClass::NonTraversable) => 100,
            (GridValues::Trinary, CellClass::Unknown) => -1,
        };
    }
    let stamp = Time::from_ns(stamp_ns);
    let [x, y] = lattice.corner_in_world(low);
    Ok(OccupancyGrid {
        header: Header {
            stamp,
            frame_id: frame_id.to_string(),
        },
        info: MapMetaData {
            map_load_time: stamp,
            resolution: cell_size_m as f32,
            width: size[0] as u32,
            height: size[1] as u32,
            origin: Pose {
                position: Vector3 { x, y, z: height_m },
                orientation: Quaternion::default(),
            },
        },
        data,
    })
}
