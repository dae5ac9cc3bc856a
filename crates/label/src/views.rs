//! What the page shows of an asked frame: a bird's-eye view of its points (coloured
//! by height or by remission), the model's call of every cell, and the camera image
//! with a cell's outline where the drive has a camera.

use nalgebra::Point3;
use serde::Serialize;
use travmap_core::frame::RgbImage;
use travmap_method::features::FEATURE_COUNT;
use travmap_method::grid::CellClass;
use travmap_outputs::palette::{ramp, robust_range};
use travmap_run::labelling::AskedFrame;

/// Pixels per cell side in the bird's-eye view (0.05 m a pixel for 0.4 m cells).
pub const PIXELS_PER_CELL: u32 = 8;

/// How the bird's-eye view colours points.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Colouring {
    Height,
    Remission,
}

/// A frame as the page draws it: its grid, the model's call of each cell
/// (`t`raversable, `n`ot, `.` unknown) and which cells hold features.
#[derive(Serialize)]
pub struct FrameView {
    pub source: String,
    pub frame: usize,
    pub cells_per_side: usize,
    pub cell_size_m: f64,
    pub pixels_per_cell: u32,
    /// One character per cell, row-major from row 0 (the grid's south edge).
    pub calls: String,
    pub has_camera: bool,
    pub has_remission: bool,
}

pub fn frame_view(frame: &AskedFrame) -> FrameView {
    let result = &frame.result;
    let calls = (0..result.layout.cell_count())
        .map(|cell| {
            let call = result.predicted.as_ref().map(|p| p[cell]);
            match call {
                _ if !result.features.predictable[cell] => '.',
                Some(CellClass::Traversable) => 't',
                Some(CellClass::NonTraversable) => 'n',
                _ => '.',
            }
        })
        .collect();
    FrameView {
        source: frame.source.clone(),
        frame: result.index,
        cells_per_side: result.layout.cells_per_side,
        cell_size_m: result.layout.cell_size_m,
        pixels_per_cell: PIXELS_PER_CELL,
        calls,
        has_camera: frame.camera.is_some(),
        has_remission: remission_column(frame).is_some(),
    }
}

/// The column of `remission_mean` in the frame's features, when it has one.
fn remission_column(frame: &AskedFrame) -> Option<usize> {
    (frame.result.features.dimension > FEATURE_COUNT).then_some(FEATURE_COUNT)
}

/// The frame's newest scan from above, north up, [`PIXELS_PER_CELL`] pixels a cell.
pub fn bird_eye(frame: &AskedFrame, colouring: Colouring) -> RgbImage {
    let result = &frame.result;
    let layout = &result.layout;
    let side = layout.cells_per_side as u32 * PIXELS_PER_CELL;
    let mut rgb = vec![24u8; (side * side * 3) as usize];
    let scale = PIXELS_PER_CELL as f64 / layout.cell_size_m;
    let cells = 0..layout.cell_count();
    let remission = match colouring {
        Colouring::Remission => remission_column(frame),
        Colouring::Height => None,
    };
    let value_of_cell = |cell: usize| remission.map(|column| result.features.cell(cell)[column]);
    let (low, high) = match remission {
        Some(_) => robust_range(
            cells
                .clone()
                .filter(|&c| result.features.predictable[c])
                .filter_map(value_of_cell)
                .filter(|v| v.is_finite())
                .collect(),
        ),
        None => robust_range(
            (cells.clone())
                .flat_map(|c| result.cells.newest(c).iter().map(|p| p[2]))
                .collect(),
        ),
    };
    for cell in cells {
        let cell_value = value_of_cell(cell);
        for p in result.cells.newest(cell) {
            let value = cell_value.unwrap_or(p[2]);
            let colour = ramp((value - low) / (high - low));
            let x = (p[0] as f64 * scale) as i64;
            let y = side as i64 - 1 - (p[1] as f64 * scale) as i64;
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (x, y) = (x + dx, y - dy);
                if (0..side as i64).contains(&x) && (0..side as i64).contains(&y) {
                    let at = 3 * (y as usize * side as usize + x as usize);
                    rgb[at..at + 3].copy_from_slice(&colour);
                }
            }
        }
    }
    RgbImage {
        width: side,
        height: side,
        rgb,
    }
}

/// The outline of `cell` on the ground in the frame's camera image (pixels, x right,
/// y down), when the drive has a camera and all four corners lie before it.
pub fn cell_in_image(frame: &AskedFrame, cell: usize) -> Option<Vec<[f64; 2]>> {
    let camera = frame.camera.as_ref()?;
    let result = &frame.result;
    let layout = &result.layout;
    // The cell's ground: its lowest point of the newest scan.
    let points = result.cells.newest(cell);
    let ground = points.iter().map(|p| p[2]).min_by(f32::total_cmp)?;
    let (col, row) = layout.col_row(cell);
    let size = layout.cell_size_m as f32;
    let corners = [(0, 0), (1, 0), (1, 1), (0, 1)].map(|(dx, dy)| {
        let grid = [(col + dx) as f32 * size, (row + dy) as f32 * size, ground];
        let [x, y, z] = layout.grid_point_in_world(grid);
        let in_velodyne = result
            .world_from_velodyne
            .inverse_transform_point(&Point3::new(x, y, z));
        camera.project([in_velodyne.x, in_velodyne.y, in_velodyne.z])
    });
    corners.into_iter().collect()
}
