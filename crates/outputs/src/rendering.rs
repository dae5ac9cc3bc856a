//! Pictures of a frame, like the paper's figures: the ground-truth grid, the filtered
//! prediction and the errors side by side under their titles, north up, x to the
//! right, the sensor marked where it stands and faces, with a scale bar in metres and
//! a legend of every colour (`figure.rs`), in the colours of a [`Palette`].

use travmap_core::frame::RgbImage;
use travmap_method::grid::CellClass;
use travmap_method::pipeline::FrameResult;

use crate::figure::{Panel, Swatch, blank, compose, draw_sensor};
use crate::palette::{Palette, ramp, robust_range};
use travmap_method::layers::{Layer, layer_values};

/// The fewest pixels a panel of a frame is wide by default: a person reads it
/// without zooming.
pub const MIN_PANEL_PX: u32 = 480;

/// Pixels a cell by default: the panel at least [`MIN_PANEL_PX`] wide.
pub fn default_cell_px(cells_per_side: usize) -> u32 {
    MIN_PANEL_PX.div_ceil(cells_per_side.max(1) as u32).max(1)
}

/// Where a cell's square starts in a panel (north up): (x, y) pixel of its top-left.
pub fn cell_origin_px(col: usize, row: usize, cells_per_side: usize, cell_px: u32) -> (u32, u32) {
    (
        col as u32 * cell_px,
        (cells_per_side - 1 - row) as u32 * cell_px,
    )
}

/// The heading of the sensor's x axis in the world's x-y plane, radians
/// counter-clockwise from east.
fn heading_rad(result: &FrameResult) -> f64 {
    let x_axis = result.world_from_velodyne.rotation * nalgebra::Vector3::x();
    x_axis.y.atan2(x_axis.x)
}

/// Ground truth, prediction and errors of one frame, `cell_px` pixels a cell, in
/// `palette`'s colours. Without ground truth the first and last panels are unknown
/// everywhere.
pub fn render(result: &FrameResult, cell_px: u32, palette: &Palette) -> RgbImage {
    let l = result.layout.cells_per_side;
    let side = l as u32 * cell_px;
    let unknown = vec![CellClass::Unknown; l * l];
    let truth = result.ground_truth.as_deref().unwrap_or(&unknown);
    let predicted = result.filtered.as_deref().unwrap_or(&unknown);
    let colours: [&dyn Fn(usize) -> [u8; 3]; 3] = [
        &|cell| palette.class(truth[cell]),
        &|cell| palette.class(predicted[cell]),
        &|cell| palette.error(predicted[cell], truth[cell]),
    ];
    let [min_x, min_y] = result.layout.min_corner_in_world();
    let pixels_per_m = cell_px as f64 / result.layout.cell_size_m;
    let sensor_px = [
        (result.sensor_in_world[0] - min_x) * pixels_per_m,
        side as f64 - (result.sensor_in_world[1] - min_y) * pixels_per_m,
    ];
    let titles = ["ground truth", "prediction (filtered)", "errors"];
    let panels: Vec<Panel> = (titles.iter().zip(colours))
        .map(|(title, colour_of)| {
            let mut image = blank(side, side, palette.unknown);
            for cell in 0..l * l {
                let (col, row) = result.layout.col_row(cell);
                let (x, y) = cell_origin_px(col, row, l, cell_px);
                crate::figure::fill_rect(
                    &mut image,
                    x as i64,
                    y as i64,
                    cell_px,
                    cell_px,
                    colour_of(cell),
                );
            }
            let size_px = (1.6 * cell_px as f64).max(12.0);
            draw_sensor(
                &mut image,
                sensor_px[0],
                sensor_px[1],
                heading_rad(result),
                size_px,
                palette,
            );
            Panel {
                title: title.to_string(),
                image,
            }
        })
        .collect();
    let mut legend: Vec<(Swatch, &str)> = (palette.legend().into_iter())
        .map(|(colour, words)| (Swatch::Fill(colour), words))
        .collect();
    legend.push((Swatch::Sensor, "sensor, facing its x axis"));
    compose(&panels, &legend, 1.0 / pixels_per_m, palette)
}

/// The frame's float layers a planner reads (`travmap_method::layers`), a panel
/// each, coloured dark (low) to light (high) along [`ramp`]: P(traversable) from 0 to
/// 1, the ground's elevation and its range over the frame's own span (each title
/// says it), the cells the model is unsure of; cells without a value in `palette`'s
/// unknown.
pub fn render_layers(result: &FrameResult, cell_px: u32, palette: &Palette) -> RgbImage {
    let l = result.layout.cells_per_side;
    let side = l as u32 * cell_px;
    let pixels_per_m = cell_px as f64 / result.layout.cell_size_m;
    let sensor_z = result.sensor_in_world[2];
    let panel = |title: String, values: &[f32], low: f32, high: f32| {
        let mut image = blank(side, side, palette.unknown);
        for (cell, &v) in values.iter().enumerate() {
            if v.is_nan() {
                continue;
            }
            let (col, row) = result.layout.col_row(cell);
            let (x, y) = cell_origin_px(col, row, l, cell_px);
            let t = (v - low) / (high - low).max(f32::EPSILON);
            crate::figure::fill_rect(&mut image, x as i64, y as i64, cell_px, cell_px, ramp(t));
        }
        Panel { title, image }
    };
    let values = |layer: Layer, reference_z: f64| {
        layer_values(result, layer, reference_z).unwrap_or_else(|| vec![f32::NAN; l * l])
    };
    let finite = |v: &[f32]| {
        v.iter()
            .copied()
            .filter(|x| x.is_finite())
            .collect::<Vec<_>>()
    };
    let elevation = values(Layer::Elevation, sensor_z);
    let (low, high) = robust_range(finite(&elevation));
    let range = values(Layer::ElevationRange, 0.0);
    let (_, range_high) = robust_range(finite(&range));
    let panels = vec![
        panel(
            "P(traversable), 0 to 1".into(),
            &values(Layer::Traversability, 0.0),
            0.0,
            1.0,
        ),
        panel(
            format!("elevation, {low:.1} to {high:.1} m from the sensor"),
            &elevation,
            low,
            high,
        ),
        panel(
            format!("elevation range, 0 to {range_high:.1} m"),
            &range,
            0.0,
            range_high,
        ),
        panel(
            "unsure: |margin| < 1".into(),
            &values(Layer::Unsure, 0.0),
            0.0,
            1.0,
        ),
    ];
    let legend = [
        (Swatch::Fill(ramp(0.0)), "lowest of the panel's scale"),
        (Swatch::Fill(ramp(0.5)), "middle"),
        (Swatch::Fill(ramp(1.0)), "highest (unsure: yes)"),
        (Swatch::Fill(palette.unknown), "no value"),
    ];
    compose(&panels, &legend, 1.0 / pixels_per_m, palette)
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
