//! Stage 3, geometric features (METHOD.md section 4): 20 values per predictable cell,
//! followed by the values of the configured [`feature_groups`] (ours, not the paper's).
//!
//! Input: [`CellPoints`], the ground-plane normal of the integrated cloud and the
//! sensor's position. Output: [`FeatureGrid`], a flat row-major `cells x dimension`
//! f32 array and a predictable mask. One pass over each cell's points for the moments, one for the
//! extremes; scratch buffers are allocated once per frame, never per cell. Every
//! division is guarded so that no feature is NaN.

use crate::appearance::CellAppearance;
use crate::feature_groups;
use crate::grid::CellPoints;
use travmap_core::config::{FeatureConfig, FeatureGroup};
use travmap_core::geometry::{Moments, greater, least_reaching, lesser};

/// Feature names, in the order of the values of a cell.
pub const FEATURE_NAMES: [&str; FEATURE_COUNT] = [
    "linearity",
    "planarity",
    "sphericity",
    "anisotropy",
    "omnivariance",
    "eigenentropy",
    "eigenvalue_sum",
    "change_of_curvature",
    "angle_rad",
    "normal_x",
    "normal_y",
    "normal_z",
    "goodness_of_fit",
    "roughness",
    "unevenness",
    "surface_density",
    "zeta_difference",
    "internal_density",
    "curvity",
    "volume",
];

/// The paper's values per cell.
pub const FEATURE_COUNT: usize = 20;

/// Values per cell: the paper's 20 and those of `groups`.
pub fn feature_count(groups: &[FeatureGroup]) -> usize {
    FEATURE_COUNT
        + feature_groups::ordered(groups)
            .into_iter()
            .map(|g| feature_groups::names(g).len())
            .sum::<usize>()
}

/// Names of every value of a cell: the paper's 20, then those of `groups`.
pub fn feature_names(groups: &[FeatureGroup]) -> Vec<String> {
    let extra = feature_groups::ordered(groups)
        .into_iter()
        .flat_map(|g| feature_groups::names(g).iter());
    FEATURE_NAMES
        .iter()
        .chain(extra)
        .map(|n| n.to_string())
        .collect()
}

/// Per-cell features of one grid.
#[derive(Clone, Debug, PartialEq)]
pub struct FeatureGrid {
    /// Row-major `cell_count x dimension`; zeros for unpredictable cells.
    pub values: Vec<f32>,
    /// Values per cell: the paper's 20 and those of `groups`.
    pub dimension: usize,
    /// The groups computed (ordered): the configured ones, less remission when the
    /// cloud had no usable remission.
    pub groups: Vec<FeatureGroup>,
    /// Cells with at least `min_points` points.
    pub predictable: Vec<bool>,
    /// Appearance values (METHOD.md section 5) of the cells some image has covered.
    pub appearance: CellAppearance,
}

impl FeatureGrid {
    pub fn cell(&self, cell: usize) -> &[f32] {
        &self.values[cell * self.dimension..(cell + 1) * self.dimension]
    }

    /// The appearance values of a cell that an image has covered.
    pub fn appearance(&self, cell: usize) -> Option<&[f32]> {
        self.appearance.of(cell)
    }

    /// The same grid without the remission values (as a cloud without usable
    /// intensity has it); None when it has none.
    pub fn without_remission(&self) -> Option<FeatureGrid> {
        if !self.groups.contains(&FeatureGroup::Remission) {
            return None;
        }
        // Remission follows the paper's 20 (`feature_groups::ordered`).
        let columns = FEATURE_COUNT..FEATURE_COUNT + feature_groups::REMISSION_NAMES.len();
        let values = self
            .values
            .chunks_exact(self.dimension)
            .flat_map(|row| row[..columns.start].iter().chain(&row[columns.end..]))
            .copied()
            .collect();
        let groups = FeatureConfig {
            groups: self.groups.clone(),
            ..FeatureConfig::default()
        };
        Some(FeatureGrid {
            values,
            dimension: self.dimension - columns.len(),
            groups: groups.without_remission().groups,
            ..self.clone()
        })
    }
}

/// Computes the features of every cell with at least `min_points` points.
#[derive(Clone, Debug)]
pub struct FeatureExtractor {
    pub config: FeatureConfig,
    pub min_points: usize,
}

/// Per-frame scratch space of the per-cell computation.
struct Scratch {
    subcells: Vec<Moments>,
    /// Where `v / subcell_m` reaches 1, 2, .. per_side - 1 ([`least_reaching`]).
    subcell_edges: Vec<f64>,
    occupied_bins: Vec<bool>,
    remission: Vec<i32>,
}

impl Scratch {
    fn new(config: &FeatureConfig, cell_size_m: f64) -> Self {
        let per_side = config.subcells_per_side(cell_size_m);
        let subcell_m = cell_size_m / per_side as f64;
        Self {
            subcells: vec![Moments::default(); per_side * per_side],
            subcell_edges: (1..per_side)
                .map(|k| least_reaching(k as f64, subcell_m))
                .collect(),
            occupied_bins: vec![false; config.curvity_bins],
            remission: Vec::new(),
        }
    }
}

impl FeatureExtractor {
    /// The features of every cell; `sensor_in_drive` is where the sensor was.
    pub fn compute(
        &self,
        cells: &CellPoints,
        ground_normal: [f64; 3],
        sensor_in_drive: [f64; 3],
    ) -> FeatureGrid {
        let layout = &cells.layout;
        let cell_count = layout.cell_count();
        let mut scratch = Scratch::new(&self.config, layout.cell_size_m);
        let groups = match cells.remission {
            Some(_) => feature_groups::ordered(&self.config.groups),
            None => feature_groups::ordered(&self.config.without_remission().groups),
        };
        let dimension = feature_count(&groups);
        let remission_at = groups
            .contains(&FeatureGroup::Remission)
            .then_some(FEATURE_COUNT);
        let mut values = vec![0f32; cell_count * dimension];
        let mut predictable = vec![false; cell_count];
        for cell in 0..cell_count {
            let range = cells.cell_range(cell);
            if range.len() < self.min_points {
                continue;
            }
            predictable[cell] = true;
            let (col, row) = layout.col_row(cell);
            let cell_min = [
                col as f64 * layout.cell_size_m,
                row as f64 * layout.cell_size_m,
            ];
            let row = &mut values[cell * dimension..(cell + 1) * dimension];
            row[..FEATURE_COUNT].copy_from_slice(&self.cell_features(
                &cells.points_in_grid[range.clone()],
                &cells.range_m[range],
                cell_min,
                layout.cell_size_m,
                ground_normal,
                &mut scratch,
            ));
        }
        if let (Some(at), Some(remission)) = (remission_at, &cells.remission) {
            let width = feature_groups::REMISSION_NAMES.len();
            let predictable_cells: Vec<usize> =
                (0..cell_count).filter(|&c| predictable[c]).collect();
            for pair in predictable_cells.chunks(2) {
                let values_of = |k: usize| {
                    pair.get(k)
                        .map_or(&[][..], |&c| &remission[cells.cell_range(c)])
                };
                let statistics = feature_groups::remission_of_two(
                    [values_of(0), values_of(1)],
                    &mut scratch.remission,
                );
                for (&cell, statistics) in pair.iter().zip(statistics) {
                    let start = cell * dimension + at;
                    values[start..start + width].copy_from_slice(&statistics);
                }
            }
        }
        if groups.contains(&FeatureGroup::Context) {
            let [min_x, min_y] = layout.min_corner_in_drive();
            let sensor_in_grid = [sensor_in_drive[0] - min_x, sensor_in_drive[1] - min_y];
            let offset = dimension - feature_groups::CONTEXT_NAMES.len();
            feature_groups::context(
                cells,
                &predictable,
                sensor_in_grid,
                &mut values,
                dimension,
                offset,
            );
        }
        FeatureGrid {
            values,
            dimension,
            groups,
            predictable,
            appearance: CellAppearance::default(),
        }
    }

    /// The features of one cell whose min corner is `cell_min` (same frame as the
    /// points) and side `cell_size_m`.
    fn cell_features(
        &self,
        points: &[[f32; 3]],
        range_m: &[f32],
        cell_min: [f64; 2],
        cell_size_m: f64,
        ground_normal: [f64; 3],
        scratch: &mut Scratch,
    ) -> [f32; FEATURE_COUNT] {
        let k = points.len();
        let per_side = self.config.subcells_per_side(cell_size_m);
        scratch.subcells.fill(Moments::default());

        let mut zeta = (f64::INFINITY, f64::NEG_INFINITY);
        let mut bbox = [
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        // The range extremes are taken here, not in the d_m loop below: as an f32
        // min/max reduction beside an f64 one there, rustc 1.95 (LLVM 22) at
        // opt-level 3 crashes in x86 instruction selection.
        let (mut range_min, mut range_max) = (f32::INFINITY, f32::NEG_INFINITY);
        for (p, &r) in points.iter().zip(range_m) {
            range_min = lesser(range_min, r);
            range_max = greater(range_max, r);
            let q = [
                p[0] as f64 - cell_min[0],
                p[1] as f64 - cell_min[1],
                p[2] as f64,
            ];
            let along = q[0] * ground_normal[0] + q[1] * ground_normal[1] + q[2] * ground_normal[2];
            zeta = (lesser(zeta.0, along), greater(zeta.1, along));
            bbox = [
                lesser(bbox[0], q[0]),
                greater(bbox[1], q[0]),
                lesser(bbox[2], q[1]),
                greater(bbox[3], q[1]),
            ];
            // `(v / subcell_m) as usize` capped at the last sub-cell (negatives
            // saturate to 0): how many sub-cell edges v reaches.
            let sub = |v: f64| scratch.subcell_edges.iter().filter(|&&e| v >= e).count();
            scratch.subcells[sub(q[1]) * per_side + sub(q[0])].add(q);
        }
        // The cell's moments are the sum of its sub-cells'. Coordinates relative to
        // the cell corner keep the f64 sums well conditioned.
        let mut moments = Moments::default();
        for sub in &scratch.subcells {
            moments.merge(sub);
        }
        let centroid = moments.mean();
        let covariance = moments.covariance();
        let eigen = covariance.smallest_eigen();
        let [l1, l2, l3] = eigen.values.map(|l| l.max(0.0));
        let sum = l1 + l2 + l3;
        let normal = eigen.normal;
        let ratio = |num: f64, den: f64| if den > 0.0 { num / den } else { 0.0 };

        let eigenentropy = if sum > 0.0 {
            -[l1, l2, l3]
                .iter()
                .map(|l| l / sum)
                .filter(|e| *e > 0.0)
                .map(|e| e * e.ln())
                .sum::<f64>()
        } else {
            0.0
        };

        // Unevenness: resultant of the sub-cells' unit normals (Decision of METHOD.md).
        let mut resultant = [0.0f64; 3];
        let mut occupied_subcells = 0usize;
        for sub in &scratch.subcells {
            if sub.count > 0 {
                occupied_subcells += 1;
            }
            if sub.count as usize >= self.config.unevenness_min_points {
                let n = sub.covariance().smallest_eigen().normal;
                for (r, v) in resultant.iter_mut().zip(n) {
                    *r += v;
                }
            }
        }
        let unevenness =
            (resultant[0].powi(2) + resultant[1].powi(2) + resultant[2].powi(2)).sqrt() / k as f64;

        let horizontal_sq = |p: &[f32; 3]| {
            let dx = p[0] as f64 - cell_min[0] - centroid[0];
            let dy = p[1] as f64 - cell_min[1] - centroid[1];
            dx * dx + dy * dy
        };
        // Four running maxima: with one, each point's max waited for the last one's.
        // A maximum is exact in any order.
        let mut maxima = [0.0f64; 4];
        let mut quads = points.chunks_exact(4);
        for quad in &mut quads {
            for (m, p) in maxima.iter_mut().zip(quad) {
                *m = greater(*m, horizontal_sq(p));
            }
        }
        for p in quads.remainder() {
            maxima[0] = greater(maxima[0], horizontal_sq(p));
        }
        let max_horizontal_sq = maxima.into_iter().fold(0.0f64, f64::max);
        let surface_density = ratio(k as f64, max_horizontal_sq);

        // Curvity: share of empty bins of the range histogram over [min, max].
        let bins = scratch.occupied_bins.len();
        scratch.occupied_bins.fill(false);
        let span = (range_max - range_min) as f64;
        for &r in range_m {
            let bin = if span > 0.0 {
                (((r - range_min) as f64 / span * bins as f64) as usize).min(bins - 1)
            } else {
                0
            };
            scratch.occupied_bins[bin] = true;
        }
        let empty_bins = scratch.occupied_bins.iter().filter(|o| !**o).count();

        let zeta_difference = zeta.1 - zeta.0;
        let bbox_area = (bbox[1] - bbox[0]) * (bbox[3] - bbox[2]);
        let values: [f64; FEATURE_COUNT] = [
            ratio(l1 - l2, l1),
            ratio(l2 - l3, l1),
            ratio(l3, l1),
            ratio(l1 - l3, l1),
            (l1 * l2 * l3).cbrt(),
            eigenentropy,
            sum,
            ratio(l3, sum),
            normal[2].clamp(-1.0, 1.0).acos(),
            normal[0],
            normal[1],
            normal[2],
            (k as f64 * l3).sqrt(),
            covariance.zz.max(0.0),
            unevenness,
            surface_density,
            zeta_difference,
            occupied_subcells as f64 / scratch.subcells.len() as f64,
            empty_bins as f64 / bins as f64,
            bbox_area * zeta_difference,
        ];
        values.map(|v| v as f32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use travmap_core::config::Config;
    use travmap_core::random::SplitMix64;

    fn index(name: &str) -> usize {
        FEATURE_NAMES.iter().position(|n| *n == name).unwrap()
    }

    fn extractor() -> FeatureExtractor {
        let config = Config::default();
        FeatureExtractor {
            config: config.features,
            min_points: config.grid.min_points,
        }
    }

    /// Features of `points` as one 0.4 m cell with corner at the origin, ranges from
    /// a sensor at `origin`, ground normal +z.
    fn features_of(points: &[[f32; 3]], origin: [f32; 3]) -> [f32; FEATURE_COUNT] {
        let ranges: Vec<f32> = points
            .iter()
            .map(|p| {
                ((p[0] - origin[0]).powi(2)
                    + (p[1] - origin[1]).powi(2)
                    + (p[2] - origin[2]).powi(2))
                .sqrt()
            })
            .collect();
        features_with_ranges(points, &ranges)
    }

    fn features_with_ranges(points: &[[f32; 3]], ranges: &[f32]) -> [f32; FEATURE_COUNT] {
        let e = extractor();
        let mut scratch = Scratch::new(&e.config, 0.4);
        e.cell_features(
            points,
            ranges,
            [0.0, 0.0],
            0.4,
            [0.0, 0.0, 1.0],
            &mut scratch,
        )
    }

    fn assert_near(f: &[f32; FEATURE_COUNT], name: &str, expected: f64, tolerance: f64) {
        let v = f[index(name)] as f64;
        assert!(
            (v - expected).abs() <= tolerance,
            "{name} = {v}, expected {expected}"
        );
    }

    /// A 6 x 6 lattice filling the cell, at height z = a*y.
    fn lattice(slope: f32) -> Vec<[f32; 3]> {
        let mut points = Vec::new();
        for i in 0..6 {
            for j in 0..6 {
                let (x, y) = (0.03 + 0.065 * i as f32, 0.03 + 0.065 * j as f32);
                points.push([x, y, slope * y]);
            }
        }
        points
    }

    #[test]
    fn horizontal_plane() {
        let f = features_of(&lattice(0.0), [0.0, 0.0, 1.7]);
        assert_near(&f, "linearity", 0.0, 1e-5);
        assert_near(&f, "planarity", 1.0, 1e-5);
        assert_near(&f, "sphericity", 0.0, 1e-6);
        assert_near(&f, "anisotropy", 1.0, 1e-6);
        assert_near(&f, "omnivariance", 0.0, 1e-6);
        assert_near(&f, "eigenentropy", 2f64.ln(), 1e-5);
        assert_near(&f, "change_of_curvature", 0.0, 1e-6);
        assert_near(&f, "angle_rad", 0.0, 1e-6);
        assert_near(&f, "normal_z", 1.0, 1e-6);
        assert_near(&f, "goodness_of_fit", 0.0, 1e-5);
        assert_near(&f, "roughness", 0.0, 1e-9);
        assert_near(&f, "zeta_difference", 0.0, 1e-6);
        assert_near(&f, "volume", 0.0, 1e-6);
        assert_near(&f, "internal_density", 1.0, 0.0);
        // Four sub-cells of 9 points, each normal +z: |r_q| = 4 over k = 36.
        assert_near(&f, "unevenness", 4.0 / 36.0, 1e-6);
        // Variance of x (and y) of 6 equally spaced values 0.065 apart.
        let var = 0.065f64.powi(2) * (36.0 - 1.0) / 12.0;
        assert_near(&f, "eigenvalue_sum", 2.0 * var, 1e-6);
        // d_m is the corner's distance from the centroid.
        let d_m = (2.0f64).sqrt() * 2.5 * 0.065;
        assert_near(&f, "surface_density", 36.0 / (d_m * d_m), 1e-2);
    }

    #[test]
    fn tilted_plane_angle_and_normal() {
        let slope = 30f32.to_radians().tan();
        let f = features_of(&lattice(slope), [0.0, 0.0, 1.7]);
        assert_near(&f, "angle_rad", 30f64.to_radians(), 1e-5);
        assert_near(&f, "normal_x", 0.0, 1e-5);
        assert_near(&f, "normal_y", -0.5, 1e-5);
        assert_near(&f, "planarity", 0.75, 1e-4); // l2 / l1 = cos^2 30
        assert_near(&f, "goodness_of_fit", 0.0, 1e-4);
        let rise = slope as f64 * 5.0 * 0.065;
        assert_near(&f, "zeta_difference", rise, 1e-5);
        assert_near(&f, "volume", (5.0 * 0.065f64).powi(2) * rise, 1e-5);
    }

    #[test]
    fn line() {
        let points: Vec<[f32; 3]> = (0..10)
            .map(|i| [0.02 + 0.04 * i as f32, 0.1, 0.5])
            .collect();
        let f = features_of(&points, [0.0, 0.0, 0.0]);
        assert_near(&f, "linearity", 1.0, 1e-6);
        assert_near(&f, "planarity", 0.0, 1e-6);
        assert_near(&f, "sphericity", 0.0, 1e-6);
        assert_near(&f, "eigenentropy", 0.0, 1e-6);
        assert_near(&f, "surface_density", 10.0 / 0.18f64.powi(2), 1e-1);
        // Two of four sub-cells hold points (y = 0.1 lies in the lower row).
        assert_near(&f, "internal_density", 0.5, 0.0);
        for v in f {
            assert!(v.is_finite());
        }
    }

    #[test]
    fn isotropic_octahedron_and_sphere() {
        let a = 0.1f32;
        let c = [0.2f32, 0.2, 1.0];
        let octahedron: Vec<[f32; 3]> = [
            [a, 0.0, 0.0],
            [-a, 0.0, 0.0],
            [0.0, a, 0.0],
            [0.0, -a, 0.0],
            [0.0, 0.0, a],
            [0.0, 0.0, -a],
        ]
        .iter()
        .map(|d| [c[0] + d[0], c[1] + d[1], c[2] + d[2]])
        .collect();
        let f = features_of(&octahedron, [0.0; 3]);
        assert_near(&f, "sphericity", 1.0, 1e-5);
        assert_near(&f, "linearity", 0.0, 1e-5);
        assert_near(&f, "planarity", 0.0, 1e-5);
        assert_near(&f, "anisotropy", 0.0, 1e-5);
        assert_near(&f, "eigenentropy", 3f64.ln(), 1e-5);
        assert_near(&f, "change_of_curvature", 1.0 / 3.0, 1e-5);
        let l = (a as f64).powi(2) / 3.0;
        assert_near(&f, "omnivariance", l, 1e-7);
        assert_near(&f, "goodness_of_fit", (6.0 * l).sqrt(), 1e-5);
        assert_near(&f, "roughness", l, 1e-7);
        assert_near(&f, "zeta_difference", 2.0 * a as f64, 1e-6);

        // A Fibonacci sphere of radius 0.15: covariance r^2/3 I, sphericity near 1.
        let n = 400;
        let sphere: Vec<[f32; 3]> = (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let t = i as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
                let r = (1.0 - z * z).sqrt();
                [
                    (0.2 + 0.15 * r * t.cos()) as f32,
                    (0.2 + 0.15 * r * t.sin()) as f32,
                    (1.0 + 0.15 * z) as f32,
                ]
            })
            .collect();
        let f = features_of(&sphere, [0.0; 3]);
        assert_near(&f, "sphericity", 1.0, 0.02);
        assert_near(&f, "eigenvalue_sum", 0.15f64.powi(2), 1e-4);
    }

    #[test]
    fn random_blob_gives_finite_features() {
        let mut rng = SplitMix64(3);
        let blob: Vec<[f32; 3]> = (0..50)
            .map(|_| {
                [
                    rng.uniform(0.0, 0.4) as f32,
                    rng.uniform(0.0, 0.4) as f32,
                    rng.uniform(0.0, 2.0) as f32,
                ]
            })
            .collect();
        let f = features_of(&blob, [0.0; 3]);
        assert!(f.iter().all(|v| v.is_finite()), "{f:?}");
        // Two identical points: l1 = 0, every ratio guarded.
        let f = features_of(&[[0.1, 0.1, 0.1], [0.1, 0.1, 0.1]], [0.0; 3]);
        assert!(f.iter().all(|v| v.is_finite()), "{f:?}");
        assert_near(&f, "surface_density", 0.0, 0.0);
    }

    #[test]
    fn curvity_counts_empty_bins_of_a_known_histogram() {
        let points = vec![[0.1f32, 0.1, 0.0]; 4];
        // 160 bins over [10, 26]: 10, 10.05, 18 and 26 fill bins 0, 0, 80 and 159.
        let f = features_with_ranges(&points, &[10.0, 10.05, 18.0, 26.0]);
        assert_near(&f, "curvity", 157.0 / 160.0, 1e-7);
        // Ranges spread over every bin leave none empty.
        let points = vec![[0.1f32, 0.1, 0.0]; 160];
        let ranges: Vec<f32> = (0..160).map(|i| 5.0 + 0.1 * i as f32 + 0.05).collect();
        let f = features_with_ranges(&points, &ranges);
        assert_near(&f, "curvity", 0.0, 1e-7);
        // Equal ranges: one occupied bin.
        let f = features_with_ranges(&points[..3], &[7.0; 3]);
        assert_near(&f, "curvity", 159.0 / 160.0, 1e-7);
    }
}
