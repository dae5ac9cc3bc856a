//! Stage 3, feature groups beyond the paper's 20 (docs/method.md "Features beyond the
//! paper"): what geometry alone misses. Each group is a config switch
//! (`features.groups`) and follows the 20 in a fixed order.
//!
//! - remission: mean, standard deviation (population) and median (the upper one for
//!   an even count) of the cell's points' remission on a 0..1 scale;
//! - context: from the cell's neighbourhood, with `mean_z` the mean height of a
//!   cell's points and `min_z` their lowest: the largest and the mean height step
//!   `|mean_z(n) - mean_z(c)|` to the predictable 8-neighbours (0 without any), how
//!   many of the 8 are predictable, the cell centre's horizontal range from the
//!   sensor, and the height of `mean_z(c)` above the lowest `min_z` of the 5 x 5
//!   block around it (cells with any point).
//!
//! Input: [`CellPoints`] and the predictable mask; output: values written into each
//! predictable cell's row. One pass over the points, one over the grid; scratch
//! buffers are allocated once per frame.

use crate::grid::CellPoints;
use travmap_core::config::FeatureGroup;

/// Names of the remission values, in order.
pub const REMISSION_NAMES: [&str; 3] = ["remission_mean", "remission_std", "remission_median"];

/// Names of the context values, in order.
pub const CONTEXT_NAMES: [&str; 5] = [
    "height_step_max_m",
    "height_step_mean_m",
    "occupied_neighbours",
    "range_m",
    "height_above_local_min_m",
];

/// The groups of `groups` in the order their values follow the paper's 20.
pub fn ordered(groups: &[FeatureGroup]) -> Vec<FeatureGroup> {
    [FeatureGroup::Remission, FeatureGroup::Context]
        .into_iter()
        .filter(|g| groups.contains(g))
        .collect()
}

/// The names of a group's values.
pub fn names(group: FeatureGroup) -> &'static [&'static str] {
    match group {
        FeatureGroup::Remission => &REMISSION_NAMES,
        FeatureGroup::Context => &CONTEXT_NAMES,
    }
}

/// Remission statistics (mean, standard deviation, upper median) of two cells at
/// once, zeros for an empty one; `scratch` is reused across cells. Each sum is a chain
/// of dependent f64 additions, so a cell alone waited out the latency of each; two
/// cells' chains run side by side, each adding in its own order: the same sums.
pub fn remission_of_two(cells: [&[f32]; 2], scratch: &mut Vec<i32>) -> [[f32; 3]; 2] {
    let counts = cells.map(|values| values.len() as f64);
    let sums = two_sums(cells, |_, v| v as f64);
    let means = [sums[0] / counts[0], sums[1] / counts[1]];
    let squares = two_sums(cells, |side, v| (v as f64 - means[side]).powi(2));
    let mut statistics = [[0f32; 3]; 2];
    for side in 0..2 {
        if cells[side].is_empty() {
            continue;
        }
        scratch.clear();
        scratch.extend(
            cells[side]
                .iter()
                .map(|&v| total_order_flip(v.to_bits() as i32)),
        );
        let middle = scratch.len() / 2;
        let (_, &mut median, _) = scratch.select_nth_unstable(middle);
        let variance = squares[side] / counts[side];
        statistics[side] = [
            means[side] as f32,
            variance.sqrt() as f32,
            f32::from_bits(total_order_flip(median) as u32),
        ];
    }
    statistics
}

/// The transform `f32::total_cmp` makes at every comparison, made once per value:
/// of a value's bits, an integer in its order; of that integer, the bits again.
fn total_order_flip(bits: i32) -> i32 {
    bits ^ (((bits >> 31) as u32) >> 1) as i32
}

/// `sum over v of term(side, v)` for the values of each side, in their order.
fn two_sums(cells: [&[f32]; 2], term: impl Fn(usize, f32) -> f64) -> [f64; 2] {
    // As `Iterator::sum` does: from -0.0, which adds nothing.
    let mut sums = [-0.0f64; 2];
    let common = cells[0].len().min(cells[1].len());
    for (&a, &b) in cells[0][..common].iter().zip(&cells[1][..common]) {
        sums[0] += term(0, a);
        sums[1] += term(1, b);
    }
    for (side, values) in cells.iter().enumerate() {
        for &v in &values[common..] {
            sums[side] += term(side, v);
        }
    }
    sums
}

/// Writes the context values of every predictable cell at `offset` of its row of
/// `values` (row length `dimension`); `sensor_in_grid` is the sensor's xy relative
/// to the grid's min corner.
pub fn context(
    cells: &CellPoints,
    predictable: &[bool],
    sensor_in_grid: [f64; 2],
    values: &mut [f32],
    dimension: usize,
    offset: usize,
) {
    let layout = &cells.layout;
    let side = layout.cells_per_side;
    let cell_count = layout.cell_count();
    let mut mean_z = vec![0f64; cell_count];
    let mut min_z = vec![f64::INFINITY; cell_count];
    for (cell, (mean, min)) in mean_z.iter_mut().zip(&mut min_z).enumerate() {
        let points = &cells.points_in_grid[cells.cell_range(cell)];
        if !points.is_empty() {
            *mean = points.iter().map(|p| p[2] as f64).sum::<f64>() / points.len() as f64;
            *min = points
                .iter()
                .map(|p| p[2] as f64)
                .fold(f64::INFINITY, f64::min);
        }
    }
    let around = |cell: usize, reach: i64| {
        let (col, row) = layout.col_row(cell);
        let (col, row) = (col as i64, row as i64);
        (-reach..=reach)
            .flat_map(move |dr| (-reach..=reach).map(move |dc| (col + dc, row + dr)))
            .filter(move |&(c, r)| {
                (c, r) != (col, row)
                    && (0..side as i64).contains(&c)
                    && (0..side as i64).contains(&r)
            })
            .map(move |(c, r)| r as usize * side + c as usize)
    };
    for cell in (0..cell_count).filter(|&c| predictable[c]) {
        let (mut step_max, mut step_sum, mut neighbours) = (0f64, 0f64, 0usize);
        for n in around(cell, 1).filter(|&n| predictable[n]) {
            let step = (mean_z[n] - mean_z[cell]).abs();
            step_max = step_max.max(step);
            step_sum += step;
            neighbours += 1;
        }
        let local_min = around(cell, 2)
            .map(|n| min_z[n])
            .fold(min_z[cell], f64::min);
        let (col, row) = layout.col_row(cell);
        let centre = [
            (col as f64 + 0.5) * layout.cell_size_m,
            (row as f64 + 0.5) * layout.cell_size_m,
        ];
        let range_m = (centre[0] - sensor_in_grid[0]).hypot(centre[1] - sensor_in_grid[1]);
        let out = &mut values[cell * dimension + offset..cell * dimension + offset + 5];
        out.copy_from_slice(&[
            step_max as f32,
            (step_sum / neighbours.max(1) as f64) as f32,
            neighbours as f32,
            range_m as f32,
            (mean_z[cell] - local_min) as f32,
        ]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{GridBuffers, GridLayout, grid_points};
    use crate::integration::DriveScan;
    use travmap_core::geometry::Moments;
    use travmap_core::posing::DriveFrame;

    #[test]
    fn total_order_keys_order_as_total_cmp_and_give_the_value_back() {
        let values = [
            -1.5f32,
            -0.25,
            -0.0,
            0.0,
            1e-30,
            0.25,
            0.5,
            1.0,
            7.0,
            -7.0,
            f32::MIN_POSITIVE,
        ];
        let key = |v: f32| total_order_flip(v.to_bits() as i32);
        for a in values {
            assert_eq!(total_order_flip(key(a)) as u32, a.to_bits());
            for b in values {
                assert_eq!(key(a).cmp(&key(b)), a.total_cmp(&b));
            }
        }
    }

    #[test]
    fn remission_statistics_of_a_known_cell() {
        let mut scratch = Vec::new();
        let remission =
            |values: &[f32], scratch: &mut Vec<i32>| remission_of_two([values, &[]], scratch)[0];
        let [mean, std, median] = remission(&[0.4, 0.1, 0.3, 0.2], &mut scratch);
        assert!((mean - 0.25).abs() < 1e-6);
        assert!((std - 0.0125f32.sqrt()).abs() < 1e-6, "{std}");
        assert_eq!(median, 0.3, "the upper median of an even count");
        assert_eq!(remission(&[0.7], &mut scratch), [0.7, 0.0, 0.7]);
    }

    #[test]
    fn two_cells_at_once_are_each_cell_alone_to_the_bit() {
        let mut rng = travmap_core::random::SplitMix64(9);
        let mut scratch = Vec::new();
        for (n, m) in [(0, 5), (7, 0), (13, 13), (40, 3), (1, 90)] {
            let cell = |len: usize, rng: &mut travmap_core::random::SplitMix64| -> Vec<f32> {
                (0..len).map(|_| rng.uniform(0.0, 1.0) as f32).collect()
            };
            let (a, b) = (cell(n, &mut rng), cell(m, &mut rng));
            let alone = |values: &[f32]| {
                if values.is_empty() {
                    return [0.0; 3];
                }
                // The sequential statistics, as `Iterator::sum` gives them.
                let k = values.len() as f64;
                let mean = values.iter().map(|&v| v as f64).sum::<f64>() / k;
                let variance = values
                    .iter()
                    .map(|&v| (v as f64 - mean).powi(2))
                    .sum::<f64>()
                    / k;
                let mut sorted = values.to_vec();
                sorted.sort_by(f32::total_cmp);
                [
                    mean as f32,
                    variance.sqrt() as f32,
                    sorted[sorted.len() / 2],
                ]
            };
            let both = remission_of_two([&a, &b], &mut scratch);
            assert_eq!(both[0].map(f32::to_bits), alone(&a).map(f32::to_bits));
            assert_eq!(both[1].map(f32::to_bits), alone(&b).map(f32::to_bits));
        }
    }

    #[test]
    fn context_of_a_hand_made_neighbourhood() {
        // 5 x 5 cells of 1 m around (0.5, 0.5): the centre cell is (2, 2), its
        // corner at world (0, 0). Two points per occupied cell, so min_points 2.
        let layout = GridLayout::centred_on([0.5, 0.5], DriveFrame::default(), 1.0, 5);
        assert_eq!(layout.min_corner_in_drive(), [-2.0, -2.0]);
        let mut points = Vec::new();
        let mut put = |x: f32, y: f32, z: [f32; 2]| {
            points.push([x, y, z[0]]);
            points.push([x + 0.1, y + 0.1, z[1]]);
        };
        put(0.5, 0.5, [0.0, 0.2]); // the centre: mean z 0.1, min 0
        put(1.5, 0.5, [0.5, 0.7]); // east: mean 0.6, step 0.5
        put(0.5, 1.5, [-0.1, -0.1]); // north: mean -0.1, step 0.2
        put(-1.5, -1.5, [-1.0, -1.0]); // two cells away: only the 5 x 5 minimum
        let scan = DriveScan {
            index: 0,
            stamp_ns: 0,
            points_in_drive: points.into(),
            sensor_in_drive: [0.5, -2.5, 0.0],
            labels: None,
            remission: None,
            non_finite_remission: 0,
            moments: Moments::default(),
        };
        let cells = grid_points(&[scan], layout, &mut GridBuffers::default());
        let predictable: Vec<bool> = (0..25).map(|c| cells.point_count(c) >= 2).collect();
        let mut values = vec![0f32; 25 * 5];
        // The sensor at world (0.5, -2.5): 3 m south of the centre cell's centre.
        context(&cells, &predictable, [2.5, -0.5], &mut values, 5, 0);
        let centre = &values[12 * 5..13 * 5];
        let expected = [0.5, 0.35, 2.0, 3.0, 1.1];
        for (name, (got, want)) in CONTEXT_NAMES.iter().zip(centre.iter().zip(expected)) {
            assert!((got - want).abs() < 1e-6, "{name}: {got} vs {want}");
        }
        // East (3, 2): the centre (step 0.5) and, diagonally, north (step 0.7).
        let east = &values[13 * 5..14 * 5];
        assert!((east[0] - 0.7).abs() < 1e-6, "{east:?}");
        assert!((east[1] - 0.6).abs() < 1e-6 && east[2] == 2.0, "{east:?}");
        // Cells without enough points get no context.
        assert!(values[24 * 5..].iter().all(|v| *v == 0.0));
    }
}
