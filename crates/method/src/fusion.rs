//! Fusion: every frame's filtered prediction (and ground truth) into one map of the
//! whole drive, each cell fused over every frame that saw it.
//!
//! A frame's grid lies on the drive's lattice (its corner a whole number of cells
//! from the drive frame's origin, [`GridLayout`]), so its cells are the map's cells. Each observation of a
//! cell adds evidence `s * w_distance * w_margin`:
//! - `s` is +1 for traversable, -1 for not (the filtered class);
//! - `w_distance = 1 / (1 + (r / R)^2)`, r the cell centre's distance from the
//!   sensor in x-y and R = [`DISTANCE_SCALE_M`]: near cells have more points and
//!   better features;
//! - `w_margin = clamp(|margin|, MIN_MARGIN_WEIGHT, 1)`, the classifier's margin
//!   (decision value minus threshold): a confident cell counts more; a cell the
//!   outlier filter flipped counts the least.
//!
//! The evidence E of a cell is the sum, read as log-odds: P(traversable) =
//! 1 / (1 + e^-E); the class is traversable for E > 0, not for E < 0, unknown where
//! no frame saw the cell. Sums are kept in fixed point (micro-units, i64), so the map
//! is the same bits whatever order the frames come in. Ground truth fuses by votes:
//! the majority class of the frames whose ground truth labels the cell (ties: not
//! traversable).
//!
//! The map is sparse: square tiles of [`TILE_CELLS`]^2 cells created where frames
//! see, so memory grows with the area driven, not with its bounding box.

use std::collections::HashMap;

use crate::grid::{CellClass, GridLayout};
use crate::pipeline::FrameResult;
use travmap_core::posing::DriveFrame;

/// R in the distance weight, metres.
pub const DISTANCE_SCALE_M: f64 = 6.0;
/// The weight of an observation with no margin to speak of, or flipped by the filter.
pub const MIN_MARGIN_WEIGHT: f64 = 0.1;
/// Cells per tile side.
pub const TILE_CELLS: i64 = 32;
/// Fixed-point units of evidence per 1.
const UNITS: f64 = 1e6;

/// What one frame says about its cells: the method's filtered classes, the
/// classifier's margins, and ground truth where labelled.
pub struct FrameObservation<'a> {
    pub layout: &'a GridLayout,
    pub sensor_in_world: [f64; 3],
    pub filtered: &'a [CellClass],
    pub margins: &'a [f32],
    pub ground_truth: Option<&'a [CellClass]>,
}

/// One tile's cells, row-major.
#[derive(Clone)]
struct Tile {
    evidence: Vec<i64>,
    observations: Vec<u32>,
    truth_traversable: Vec<u32>,
    truth_not: Vec<u32>,
}

impl Tile {
    fn new() -> Self {
        let cells = (TILE_CELLS * TILE_CELLS) as usize;
        Self {
            evidence: vec![0; cells],
            observations: vec![0; cells],
            truth_traversable: vec![0; cells],
            truth_not: vec![0; cells],
        }
    }
}

/// A fused cell.
#[derive(Clone, Debug, PartialEq)]
pub struct FusedCell {
    /// Lattice key: `floor(x / r)`, `floor(y / r)` in the drive frame.
    pub key: [i64; 2],
    /// The cell centre in the world, metres.
    pub x_m: f64,
    pub y_m: f64,
    /// Summed evidence (log-odds of traversable).
    pub evidence: f64,
    /// P(traversable) from the evidence.
    pub probability: f64,
    /// Frames whose prediction covered the cell.
    pub observations: u32,
    pub class: CellClass,
    /// Fused ground truth; unknown where no labelled frame labelled the cell.
    pub ground_truth: CellClass,
}

/// Where a drive map's cells lie: squares of `cell_size_m` whose key (0, 0) has its
/// min corner at the drive frame's origin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lattice {
    pub cell_size_m: f64,
    pub drive: DriveFrame,
}

impl Lattice {
    /// World x, y of the min corner of the cell with key `key`.
    pub fn corner_in_world(&self, key: [i64; 2]) -> [f64; 2] {
        let [x, y, _] = self.drive.origin_in_world;
        [
            x + key[0] as f64 * self.cell_size_m,
            y + key[1] as f64 * self.cell_size_m,
        ]
    }

    /// A world x, y in cells from key (0, 0)'s corner (fractional).
    pub fn in_cells(&self, x_m: f64, y_m: f64) -> [f64; 2] {
        let [x, y, _] = self.drive.origin_in_world;
        [(x_m - x) / self.cell_size_m, (y_m - y) / self.cell_size_m]
    }
}

/// The fused map of a drive.
pub struct DriveMap {
    lattice: Lattice,
    tiles: HashMap<[i64; 2], Tile>,
    frames: usize,
    /// The lowest and highest keys of the cells a prediction covered, kept as frames
    /// come so that a map published every few frames costs its own size, not a walk
    /// over the whole drive.
    observed_bounds: Option<([i64; 2], [i64; 2])>,
}

impl DriveMap {
    pub fn new(cell_size_m: f64, drive: DriveFrame) -> Self {
        Self {
            lattice: Lattice { cell_size_m, drive },
            tiles: HashMap::new(),
            frames: 0,
            observed_bounds: None,
        }
    }

    pub fn cell_size_m(&self) -> f64 {
        self.lattice.cell_size_m
    }

    /// Where the map's cells lie.
    pub fn lattice(&self) -> Lattice {
        self.lattice
    }

    /// Frames fused so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Bytes the tiles hold.
    pub fn memory_bytes(&self) -> usize {
        let per_tile = (TILE_CELLS * TILE_CELLS) as usize * (8 + 4 + 4 + 4);
        self.tiles.len() * (per_tile + std::mem::size_of::<Tile>() + 16)
    }

    /// The evidence of one observation (see the module's comment).
    fn weight(distance_m: f64, margin: f32, class: CellClass) -> f64 {
        let distance = 1.0 / (1.0 + (distance_m / DISTANCE_SCALE_M).powi(2));
        let agrees = CellClass::of_margin(margin) == class;
        let confidence = if agrees {
            (margin.abs() as f64).clamp(MIN_MARGIN_WEIGHT, 1.0)
        } else {
            MIN_MARGIN_WEIGHT
        };
        distance * confidence
    }

    /// The tile holding cell `key`, and the cell's index in it.
    fn locate(key: [i64; 2]) -> ([i64; 2], usize) {
        let tile = [key[0].div_euclid(TILE_CELLS), key[1].div_euclid(TILE_CELLS)];
        let local = key[1].rem_euclid(TILE_CELLS) * TILE_CELLS + key[0].rem_euclid(TILE_CELLS);
        (tile, local as usize)
    }

    /// Fuses one result of the method; a result without a prediction (no model)
    /// adds its ground truth only.
    pub fn add_result(&mut self, result: &FrameResult) {
        let cells = result.layout.cell_count();
        let unknown = vec![CellClass::Unknown; cells];
        let no_margins = vec![f32::NAN; cells];
        self.add(&FrameObservation {
            layout: &result.layout,
            sensor_in_world: result.sensor_in_world,
            filtered: result.filtered.as_deref().unwrap_or(&unknown),
            margins: result.margins.as_deref().unwrap_or(&no_margins),
            ground_truth: result.ground_truth.as_deref(),
        });
    }

    /// Fuses one frame.
    pub fn add(&mut self, frame: &FrameObservation) {
        let layout = frame.layout;
        let side = layout.cells_per_side;
        for row in 0..side {
            for col in 0..side {
                let cell = row * side + col;
                let class = frame.filtered[cell];
                let truth = frame
                    .ground_truth
                    .map_or(CellClass::Unknown, |truth| truth[cell]);
                if class == CellClass::Unknown && truth == CellClass::Unknown {
                    continue;
                }
                let key = [
                    layout.first_cell_key[0] + col as i64,
                    layout.first_cell_key[1] + row as i64,
                ];
                let (x, y) = self.centre(key);
                let (tile_key, local) = Self::locate(key);
                let tile = self.tiles.entry(tile_key).or_insert_with(Tile::new);
                if class != CellClass::Unknown {
                    let distance_m =
                        (x - frame.sensor_in_world[0]).hypot(y - frame.sensor_in_world[1]);
                    let sign = if class == CellClass::Traversable {
                        1.0
                    } else {
                        -1.0
                    };
                    let evidence = sign * Self::weight(distance_m, frame.margins[cell], class);
                    tile.evidence[local] += (evidence * UNITS).round() as i64;
                    tile.observations[local] += 1;
                    let (low, high) = self.observed_bounds.get_or_insert((key, key));
                    for axis in 0..2 {
                        low[axis] = low[axis].min(key[axis]);
                        high[axis] = high[axis].max(key[axis]);
                    }
                }
                match truth {
                    CellClass::Traversable => tile.truth_traversable[local] += 1,
                    CellClass::NonTraversable => tile.truth_not[local] += 1,
                    CellClass::Unknown => {}
                }
            }
        }
        self.frames += 1;
    }

    /// World x, y of the centre of the cell with lattice key `key`.
    fn centre(&self, key: [i64; 2]) -> (f64, f64) {
        let [x, y] = self.lattice.corner_in_world(key);
        let half = 0.5 * self.lattice.cell_size_m;
        (x + half, y + half)
    }

    /// Every cell some frame saw or labelled, ordered by key (y, then x).
    pub fn cells(&self) -> Vec<FusedCell> {
        let mut cells: Vec<FusedCell> = self.each_cell().collect();
        cells.sort_by_key(|c| (c.key[1], c.key[0]));
        cells
    }

    /// Every cell some frame saw or labelled, in no particular order: for a reader
    /// that places each cell by its key and needs no list of them.
    pub fn each_cell(&self) -> impl Iterator<Item = FusedCell> + '_ {
        self.tiles.iter().flat_map(move |(tile_key, tile)| {
            (0..(TILE_CELLS * TILE_CELLS) as usize)
                .filter_map(move |local| self.fused(*tile_key, tile, local))
        })
    }

    /// Cell `local` of a tile, if some frame saw or labelled it.
    fn fused(&self, tile_key: [i64; 2], tile: &Tile, local: usize) -> Option<FusedCell> {
        let (observations, up, down) = (
            tile.observations[local],
            tile.truth_traversable[local],
            tile.truth_not[local],
        );
        if observations == 0 && up == 0 && down == 0 {
            return None;
        }
        let key = [
            tile_key[0] * TILE_CELLS + local as i64 % TILE_CELLS,
            tile_key[1] * TILE_CELLS + local as i64 / TILE_CELLS,
        ];
        let evidence = tile.evidence[local] as f64 / UNITS;
        let class = match (observations, tile.evidence[local]) {
            (0, _) | (_, 0) => CellClass::Unknown,
            (_, e) if e > 0 => CellClass::Traversable,
            _ => CellClass::NonTraversable,
        };
        let ground_truth = match (up, down) {
            (0, 0) => CellClass::Unknown,
            (up, down) if up > down => CellClass::Traversable,
            _ => CellClass::NonTraversable,
        };
        let (x_m, y_m) = self.centre(key);
        Some(FusedCell {
            key,
            x_m,
            y_m,
            evidence,
            probability: 1.0 / (1.0 + (-evidence).exp()),
            observations,
            class,
            ground_truth,
        })
    }

    /// The smallest and largest keys of the cells a prediction covered; None before
    /// any did.
    pub fn observed_bounds(&self) -> Option<([i64; 2], [i64; 2])> {
        self.observed_bounds
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use travmap_core::posing::DriveFrame;

    const T: CellClass = CellClass::Traversable;
    const N: CellClass = CellClass::NonTraversable;
    const U: CellClass = CellClass::Unknown;

    fn layout(first_cell_key: [i64; 2]) -> GridLayout {
        GridLayout {
            cell_size_m: 1.0,
            cells_per_side: 2,
            first_cell_key,
            drive: DriveFrame::default(),
        }
    }

    #[test]
    fn evidence_is_the_weighted_sum_of_the_observations() {
        let mut map = DriveMap::new(1.0, DriveFrame::default());
        // The sensor at the centre of cell (0, 0): distance 0, weight = |margin|.
        let grid = layout([0, 0]);
        map.add(&FrameObservation {
            layout: &grid,
            sensor_in_world: [0.5, 0.5, 0.0],
            filtered: &[T, N, U, T],
            margins: &[0.5, -2.0, f32::NAN, -0.3],
            ground_truth: Some(&[T, N, N, U]),
        });
        // The same cells again from cell (-1, 0)'s corner: cell (0, 0) is 1 m away.
        let moved = layout([-1, 0]);
        map.add(&FrameObservation {
            layout: &moved,
            sensor_in_world: [-0.5, 0.5, 0.0],
            filtered: &[U, T, U, U],
            margins: &[f32::NAN, 0.25, f32::NAN, f32::NAN],
            ground_truth: None,
        });
        let cells = map.cells();
        let at = |key: [i64; 2]| cells.iter().find(|c| c.key == key).unwrap().clone();
        // (0, 0): 0.5 from the first frame, 0.25 / (1 + (1/6)^2) from the second.
        let expected = 0.5 + 0.25 / (1.0 + 1.0 / 36.0);
        assert!((at([0, 0]).evidence - expected).abs() < 1e-6);
        assert_eq!((at([0, 0]).observations, at([0, 0]).class), (2, T));
        // (1, 0): distance 1 m, margin -2 clamps to 1.
        assert!((at([1, 0]).evidence + 1.0 / (1.0 + 1.0 / 36.0)).abs() < 1e-6);
        assert_eq!(at([1, 0]).class, N);
        // (1, 1): filtered traversable against its margin: the least weight.
        let flipped = MIN_MARGIN_WEIGHT / (1.0 + 2.0 / 36.0);
        assert!((at([1, 1]).evidence - flipped).abs() < 1e-6);
        // (0, 1): ground truth only.
        assert_eq!((at([0, 1]).class, at([0, 1]).ground_truth), (U, N));
        assert!((at([0, 0]).probability - 1.0 / (1.0 + (-expected).exp())).abs() < 1e-6);
    }

    #[test]
    fn the_map_is_the_same_whatever_order_the_frames_come_in() {
        type Frame = (GridLayout, [f64; 3], Vec<CellClass>, Vec<f32>);
        let frames: Vec<Frame> = (0..6)
            .map(|i| {
                let classes = (0..4)
                    .map(|c| if (i + c) % 3 == 0 { N } else { T })
                    .collect();
                let margins = (0..4)
                    .map(|c| ((i * 7 + c * 3) % 11) as f32 / 7.0 - 0.7)
                    .collect();
                (
                    layout([i % 3 - 1, i / 2]),
                    [i as f64 * 0.3, 0.7, 0.0],
                    classes,
                    margins,
                )
            })
            .collect();
        let fuse = |order: &[usize]| {
            let mut map = DriveMap::new(1.0, DriveFrame::default());
            for &i in order {
                let (layout, sensor, classes, margins) = &frames[i];
                map.add(&FrameObservation {
                    layout,
                    sensor_in_world: *sensor,
                    filtered: classes,
                    margins,
                    ground_truth: Some(classes),
                });
            }
            map.cells()
        };
        let forward = fuse(&[0, 1, 2, 3, 4, 5]);
        assert_eq!(forward, fuse(&[5, 3, 1, 0, 4, 2]));
        assert_eq!(forward, fuse(&[2, 4, 0, 5, 1, 3]));
    }

    #[test]
    fn tiles_are_made_only_where_frames_see() {
        let mut map = DriveMap::new(1.0, DriveFrame::default());
        for first in [[0, 0], [10_000, -10_000]] {
            map.add(&FrameObservation {
                layout: &layout(first),
                sensor_in_world: [0.0; 3],
                filtered: &[T; 4],
                margins: &[1.0; 4],
                ground_truth: None,
            });
        }
        // Two tiles, not the 313 x 313 of the bounding box.
        assert_eq!(map.tiles.len(), 2);
        assert_eq!(map.observed_bounds(), Some(([0, -10_000], [10_001, 1])));
    }
}
