//! Stage 3b, appearance features (METHOD.md section 5): HSV histograms of the image
//! pixels each cell covers, accumulated per world cell across frames.
//!
//! Input: the in-grid points ([`CellPoints`]), the current pose and the frame's camera
//! image. Output: [`FrameVotes`], this frame's pixel counts per world cell; the
//! pipeline adds them into its [`ColourMemory`], whose normalised histograms are the
//! 88 appearance values of a cell. Each cell's prism (xy bounding box of its points, z
//! from min to max) is projected with `P2 * Tr`; vertices behind the camera are
//! dropped; every pixel whose centre lies inside the convex hull of the rest, clipped
//! to the image, votes once. Integer arithmetic over the flat RGB buffer, no per-pixel
//! allocation; each pixel's buckets are found once a frame (`appearance/pixels.rs`).

mod pixels;

use std::collections::HashMap;

use nalgebra::{Isometry3, Point3};

use crate::grid::{CellPoints, GridLayout};
use travmap_core::config::AppearanceConfig;
use travmap_core::frame::CameraImage;

use pixels::{BucketRows, HsvBuckets, PixelCounts};

/// Convex hull (counter-clockwise, no repeated end) of up to a few points.
pub fn convex_hull(points: &mut [[f64; 2]]) -> Vec<[f64; 2]> {
    points.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(points.len() * 2);
    for pass in 0..2 {
        let start = hull.len();
        let ordered: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(points.iter())
        } else {
            Box::new(points.iter().rev())
        };
        for &p in ordered {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    hull
}

/// Calls `on_row(y, x_start, x_end)` for every image row whose pixel centres inside the
/// convex polygon `hull` form the run `x_start..x_end`, clipped to the image.
pub fn rasterise(
    hull: &[[f64; 2]],
    width: u32,
    height: u32,
    mut on_row: impl FnMut(u32, u32, u32),
) {
    if hull.len() < 3 {
        return;
    }
    let min_y = hull.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min);
    let max_y = hull.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max);
    let first = (min_y - 0.5).ceil().max(0.0) as u32;
    let last = ((max_y - 0.5).floor().min(height as f64 - 1.0)).max(-1.0);
    if last < 0.0 {
        return;
    }
    for y in first..=last as u32 {
        let centre = y as f64 + 0.5;
        let (mut left, mut right) = (f64::INFINITY, f64::NEG_INFINITY);
        for (k, a) in hull.iter().enumerate() {
            let b = hull[(k + 1) % hull.len()];
            if (a[1] <= centre && centre <= b[1]) || (b[1] <= centre && centre <= a[1]) {
                let x = if a[1] == b[1] {
                    a[0].min(b[0])
                } else {
                    a[0] + (centre - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
                };
                let x_other = if a[1] == b[1] { a[0].max(b[0]) } else { x };
                left = left.min(x);
                right = right.max(x_other);
            }
        }
        let start = (left - 0.5).ceil().max(0.0);
        let end = ((right - 0.5).floor() + 1.0).min(width as f64);
        if end > start {
            on_row(y, start as u32, end as u32);
        }
    }
}

/// One frame's pixel votes: per voted world cell, `values_per_cell` counts (hue,
/// saturation, value buckets) and the number of voting pixels last.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameVotes {
    pub keys: Vec<[i64; 2]>,
    pub counts: Vec<u32>,
}

/// Projects each predictable cell's prism and counts its pixels' HSV buckets.
#[derive(Clone, Debug)]
pub struct AppearanceVoter {
    pub config: AppearanceConfig,
    pub min_points: usize,
}

impl AppearanceVoter {
    /// Values per cell: the three histograms concatenated.
    pub fn histogram_len(&self) -> usize {
        (self.config.hue_bins + self.config.saturation_bins + self.config.value_bins) as usize
    }

    pub fn vote(
        &self,
        cells: &CellPoints,
        drive_from_velodyne: &Isometry3<f64>,
        camera: &CameraImage,
    ) -> FrameVotes {
        let layout: &GridLayout = &cells.layout;
        let [min_x, min_y] = layout.min_corner_in_drive();
        let velodyne_from_drive = drive_from_velodyne.inverse();
        let image = &camera.image;
        let bins = [
            self.config.hue_bins,
            self.config.saturation_bins,
            self.config.value_bins,
        ];
        let buckets = HsvBuckets::new(bins);
        let mut bucket_rows = BucketRows::new(image, &buckets);
        let mut votes = FrameVotes::default();
        let mut counts = PixelCounts::default();
        for cell in 0..layout.cell_count() {
            let range = cells.cell_range(cell);
            if range.len() < self.min_points {
                continue;
            }
            let mut bounds = [
                f32::INFINITY,
                f32::NEG_INFINITY,
                f32::INFINITY,
                f32::NEG_INFINITY,
                f32::INFINITY,
                f32::NEG_INFINITY,
            ];
            for p in &cells.points_in_grid[range] {
                for (axis, &v) in p.iter().enumerate() {
                    bounds[2 * axis] = bounds[2 * axis].min(v);
                    bounds[2 * axis + 1] = bounds[2 * axis + 1].max(v);
                }
            }
            let mut projected = [[0.0f64; 2]; 8];
            let mut in_front = 0;
            let mut inside_image = false;
            for corner in 0..8 {
                let pick = |axis: usize| bounds[2 * axis + ((corner >> axis) & 1)] as f64;
                let world = Point3::new(pick(0) + min_x, pick(1) + min_y, pick(2));
                let v = velodyne_from_drive * world;
                if let Some(px) = camera.project([v.x, v.y, v.z]) {
                    inside_image |= px[0] >= 0.0
                        && px[1] >= 0.0
                        && px[0] < image.width as f64
                        && px[1] < image.height as f64;
                    projected[in_front] = px;
                    in_front += 1;
                }
            }
            if !inside_image {
                continue;
            }
            let hull = convex_hull(&mut projected[..in_front]);
            counts.clear(bins);
            rasterise(&hull, image.width, image.height, |y, x0, x1| {
                counts.add(bucket_rows.span(y, x0, x1));
            });
            if counts.pixels > 0 {
                votes.keys.push(layout.cell_key(cell));
                counts.append_to(bins, &mut votes.counts);
            }
        }
        votes
    }
}

/// Histogram counts per world cell, kept while the cell may come back into the grid:
/// colour propagation (METHOD.md section 5).
#[derive(Clone, Debug, Default)]
pub struct ColourMemory {
    counts: HashMap<[i64; 2], Vec<u32>>,
}

impl ColourMemory {
    pub fn add(&mut self, votes: &FrameVotes) {
        let per_cell = if votes.keys.is_empty() {
            0
        } else {
            votes.counts.len() / votes.keys.len()
        };
        for (key, counts) in votes
            .keys
            .iter()
            .zip(votes.counts.chunks_exact(per_cell.max(1)))
        {
            let entry = self.counts.entry(*key).or_insert_with(|| vec![0; per_cell]);
            for (a, b) in entry.iter_mut().zip(counts) {
                *a += b;
            }
        }
    }

    pub fn is_empty(&self) -> bool {
        self.counts.is_empty()
    }

    /// Forgets cells farther than `margin_cells` outside the grid, bounding memory on
    /// long drives.
    pub fn forget_outside(&mut self, layout: &GridLayout, margin_cells: i64) {
        let [x0, y0] = layout.first_cell_key;
        let l = layout.cells_per_side as i64;
        self.counts.retain(|k, _| {
            k[0] >= x0 - margin_cells
                && k[0] < x0 + l + margin_cells
                && k[1] >= y0 - margin_cells
                && k[1] < y0 + l + margin_cells
        });
    }

    /// The normalised histograms (`n` bins) of the grid's cells that have any.
    pub fn features(&self, layout: &GridLayout, n: usize) -> CellAppearance {
        let mut row_of_cell = vec![CellAppearance::UNSEEN; layout.cell_count()];
        let mut seen = Vec::new();
        for (cell, row) in row_of_cell.iter_mut().enumerate() {
            if let Some(counts) = self.counts.get(&layout.cell_key(cell))
                && let Some(&pixels) = counts.get(n)
                && pixels > 0
            {
                *row = seen.len() as u32;
                seen.push((&counts[..n], pixels));
            }
        }
        // Sized once: grown by doubling, a training grid's values (2.9 MB) were
        // copied again and fresh pages touched at every growth.
        let mut values = Vec::with_capacity(seen.len() * n);
        for (counts, pixels) in seen {
            values.extend(counts.iter().map(|&c| c as f32 / pixels as f32));
        }
        CellAppearance {
            values,
            len: n,
            row_of_cell,
        }
    }
}

/// The appearance values of the cells an image has covered, `len` each in cell
/// order. Stored for those cells alone: a grid's worth of them (2.9 MB on the
/// training grid, most of it zeros) was held for every frame in flight.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CellAppearance {
    pub values: Vec<f32>,
    pub len: usize,
    /// Each cell's row of `values`, or [`Self::UNSEEN`]; empty when no image was
    /// ever seen.
    pub row_of_cell: Vec<u32>,
}

impl CellAppearance {
    pub const UNSEEN: u32 = u32::MAX;

    /// The values of `cell`, when an image has covered it.
    pub fn of(&self, cell: usize) -> Option<&[f32]> {
        let row = *self.row_of_cell.get(cell)?;
        (row != Self::UNSEEN).then(|| {
            let start = row as usize * self.len;
            &self.values[start..start + self.len]
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use travmap_core::posing::DriveFrame;
    use travmap_core::random::SplitMix64;

    #[test]
    fn rasteriser_matches_brute_force_point_in_polygon() {
        let mut rng = SplitMix64(17);
        for _ in 0..300 {
            let mut points: Vec<[f64; 2]> = (0..8)
                .map(|_| [rng.uniform(-20.0, 60.0), rng.uniform(-20.0, 50.0)])
                .collect();
            let hull = convex_hull(&mut points);
            let (w, h) = (40u32, 30u32);
            let mut fast = vec![false; (w * h) as usize];
            rasterise(&hull, w, h, |y, x0, x1| {
                for x in x0..x1 {
                    assert!(!fast[(y * w + x) as usize], "pixel voted twice");
                    fast[(y * w + x) as usize] = true;
                }
            });
            for y in 0..h {
                for x in 0..w {
                    let c = [x as f64 + 0.5, y as f64 + 0.5];
                    // Inside a counter-clockwise convex polygon: left of (or on) every edge.
                    let inside = hull.len() >= 3
                        && (0..hull.len()).all(|k| {
                            let (a, b) = (hull[k], hull[(k + 1) % hull.len()]);
                            (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]) >= -1e-9
                        });
                    assert_eq!(
                        fast[(y * w + x) as usize],
                        inside,
                        "pixel ({x}, {y}) of hull {hull:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn colour_memory_keeps_a_cell_while_the_grid_moves() {
        let drive = DriveFrame::default();
        let layout_then = GridLayout::centred_on([0.0, 0.0], drive, 0.4, 30);
        let layout_now = GridLayout::centred_on([2.0, 0.0], drive, 0.4, 30); // 5 cells later
        let key = layout_then.cell_key(100);
        let mut memory = ColourMemory::default();
        let mut counts = vec![0u32; 5];
        counts[1] = 3;
        counts[4] = 3;
        memory.add(&FrameVotes {
            keys: vec![key],
            counts,
        });
        memory.forget_outside(&layout_now, 2);
        let appearance = memory.features(&layout_now, 4);
        let cell = (0..layout_now.cell_count())
            .find(|&c| layout_now.cell_key(c) == key)
            .unwrap();
        assert_eq!(appearance.of(cell), Some(&[0.0, 1.0, 0.0, 0.0][..]));
        let seen = (0..layout_now.cell_count()).filter(|&c| appearance.of(c).is_some());
        assert_eq!(seen.count(), 1);
        assert_eq!(
            appearance.values.len(),
            4,
            "only the seen cell's values are kept"
        );
        assert_ne!(
            cell, 100,
            "the same world cell has another index in the moved grid"
        );
    }
}
