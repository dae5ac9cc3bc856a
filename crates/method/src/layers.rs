//! A frame's grid as float layers beyond its classes, for planners (a GridMap's
//! layers, the Python module's arrays): P(traversable) by the model's calibration,
//! the ground's elevation and its range, the cells the model is unsure of, and the
//! labels. Row-major from the grid's min corner, as the grid's cells; NaN where a
//! layer has no value.

use crate::grid::CellClass;
use crate::pipeline::FrameResult;

/// A margin this close to the boundary is a cell the model is unsure of (the fit
/// report's).
pub const UNSURE_MARGIN: f32 = 1.0;

/// A float layer, by the name a GridMap gives it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layer {
    /// P(traversable) by the model's calibration, before the outlier filter.
    Traversability,
    /// The ground's height under the cell (the lowest point of the frame's scan in
    /// it), metres above `reference_z_m` in the world.
    Elevation,
    /// Highest minus lowest point of the cell over the window, metres.
    ElevationRange,
    /// 1 where the model's margin lies within [`UNSURE_MARGIN`] of the boundary, 0
    /// elsewhere.
    Unsure,
    /// The labels: 1 traversable, 0 not.
    GroundTruth,
}

impl Layer {
    pub const ALL: [Layer; 5] = [
        Layer::Traversability,
        Layer::Elevation,
        Layer::ElevationRange,
        Layer::Unsure,
        Layer::GroundTruth,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Layer::Traversability => "traversability",
            Layer::Elevation => "elevation",
            Layer::ElevationRange => "elevation_range",
            Layer::Unsure => "unsure",
            Layer::GroundTruth => "ground_truth",
        }
    }
}

/// `layer` of every cell of `result`'s grid, row-major; elevations above
/// `reference_z_m` (world metres). None for a layer the frame has no values of (the
/// labels of a frame without ground truth).
pub fn layer_values(result: &FrameResult, layer: Layer, reference_z_m: f64) -> Option<Vec<f32>> {
    let cells = 0..result.layout.cell_count();
    let nan = f32::NAN;
    let values = match layer {
        Layer::Traversability => match &result.probabilities {
            Some(p) => p.clone(),
            None => vec![nan; cells.len()],
        },
        Layer::Elevation => cells
            .map(|cell| {
                let lowest = (result.cells.newest(cell).iter())
                    .map(|p| p[2])
                    .min_by(f32::total_cmp);
                lowest.map_or(nan, |z| {
                    let world_z = result.layout.grid_point_in_world([0.0, 0.0, z])[2];
                    (world_z - reference_z_m) as f32
                })
            })
            .collect(),
        Layer::ElevationRange => {
            let column = crate::features::FEATURE_NAMES
                .iter()
                .position(|n| *n == "zeta_difference")
                .expect("zeta_difference is a feature");
            cells
                .map(|cell| match result.features.predictable[cell] {
                    true => result.features.cell(cell)[column],
                    false => nan,
                })
                .collect()
        }
        Layer::Unsure => match &result.margins {
            Some(margins) => (margins.iter())
                .map(|m| match m.is_nan() {
                    true => nan,
                    false => f32::from(u8::from(m.abs() < UNSURE_MARGIN)),
                })
                .collect(),
            None => vec![nan; cells.len()],
        },
        Layer::GroundTruth => (result.ground_truth.as_ref())?
            .iter()
            .map(|class| match class {
                CellClass::Traversable => 1.0,
                CellClass::NonTraversable => 0.0,
                CellClass::Unknown => nan,
            })
            .collect(),
    };
    Some(values)
}
