//! Pictures of a frame, like the paper's figures: the ground-truth grid, the filtered
//! prediction and the errors side by side, north up, x to the right, the vehicle's
//! cell outlined in white.

use travmap_core::frame::RgbImage;
use travmap_method::grid::CellClass;
use travmap_method::pipeline::FrameResult;

/// Colours of the panels.
pub mod colour {
    pub const UNKNOWN: [u8; 3] = [40, 40, 40];
    pub const TRAVERSABLE: [u8; 3] = [60, 170, 75];
    pub const NON_TRAVERSABLE: [u8; 3] = [200, 60, 50];
    /// Errors panel: right predictions, false positives (predicted traversable, not
    /// so), false negatives (predicted non-traversable, traversable).
    pub const CORRECT: [u8; 3] = [200, 200, 200];
    pub const FALSE_POSITIVE: [u8; 3] = [255, 140, 0];
    pub const FALSE_NEGATIVE: [u8; 3] = [40, 120, 255];
    pub const BACKGROUND: [u8; 3] = [255, 255, 255];
    pub const VEHICLE: [u8; 3] = [255, 255, 255];
}

/// Pixels between panels.
pub const GAP_PX: u32 = 8;

pub fn class_colour(class: CellClass) -> [u8; 3] {
    match class {
        CellClass::Unknown => colour::UNKNOWN,
        CellClass::Traversable => colour::TRAVERSABLE,
        CellClass::NonTraversable => colour::NON_TRAVERSABLE,
    }
}

pub fn error_colour(predicted: CellClass, truth: CellClass) -> [u8; 3] {
    use CellClass::{NonTraversable as N, Traversable as T, Unknown as U};
    match (predicted, truth) {
        (U, _) | (_, U) => colour::UNKNOWN,
        (T, N) => colour::FALSE_POSITIVE,
        (N, T) => colour::FALSE_NEGATIVE,
        _ => colour::CORRECT,
    }
}

/// Where a cell's square starts in a panel (north up): (x, y) pixel of its top-left.
pub fn cell_origin_px(col: usize, row: usize, cells_per_side: usize, cell_px: u32) -> (u32, u32) {
    (
        col as u32 * cell_px,
        (cells_per_side - 1 - row) as u32 * cell_px,
    )
}

/// Ground truth, prediction and errors of one frame, `cell_px` pixels per cell.
/// Without ground truth the first and last panels are unknown everywhere.
pub fn render(result: &FrameResult, cell_px: u32) -> RgbImage {
    let l = result.layout.cells_per_side;
    let panel = l as u32 * cell_px;
    let (width, height) = (3 * panel + 2 * GAP_PX, panel);
    let mut rgb: Vec<u8> = std::iter::repeat_n(colour::BACKGROUND, (width * height) as usize)
        .flatten()
        .collect();
    let unknown = vec![CellClass::Unknown; l * l];
    let truth = result.ground_truth.as_deref().unwrap_or(&unknown);
    let predicted = result.filtered.as_deref().unwrap_or(&unknown);
    let mut fill = |x0: u32, y0: u32, size: u32, c: [u8; 3], outline_only: bool| {
        for y in y0..y0 + size {
            for x in x0..x0 + size {
                let edge = x == x0 || y == y0 || x == x0 + size - 1 || y == y0 + size - 1;
                if !outline_only || edge {
                    let at = 3 * (y * width + x) as usize;
                    rgb[at..at + 3].copy_from_slice(&c);
                }
            }
        }
    };
    for cell in 0..l * l {
        let (col, row) = result.layout.col_row(cell);
        let (x, y) = cell_origin_px(col, row, l, cell_px);
        fill(x, y, cell_px, class_colour(truth[cell]), false);
        fill(
            x + panel + GAP_PX,
            y,
            cell_px,
            class_colour(predicted[cell]),
            false,
        );
        fill(
            x + 2 * (panel + GAP_PX),
            y,
            cell_px,
            error_colour(predicted[cell], truth[cell]),
            false,
        );
    }
    // The vehicle: the sensor's cell, outlined.
    let [min_x, min_y] = result.layout.min_corner_in_world();
    let sensor = result.layout.cell_of_local(
        result.sensor_in_world[0] - min_x,
        result.sensor_in_world[1] - min_y,
    );
    if let Some(cell) = sensor {
        let (col, row) = result.layout.col_row(cell);
        let (x, y) = cell_origin_px(col, row, l, cell_px);
        for p in 0..3 {
            fill(x + p * (panel + GAP_PX), y, cell_px, colour::VEHICLE, true);
        }
    }
    RgbImage { width, height, rgb }
}

/// PNG bytes of an RGB image.
pub fn encode_png(image: &RgbImage) -> Vec<u8> {
    let mut bytes = Vec::new();
    let mut encoder = png::Encoder::new(&mut bytes, image.width, image.height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    // Writing a well-formed image into memory cannot fail.
    let mut writer = encoder.write_header().expect("PNG header in memory");
    writer
        .write_image_data(&image.rgb)
        .expect("PNG data in memory");
    writer.finish().expect("PNG end in memory");
    bytes
}
