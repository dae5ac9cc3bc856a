//! The pixels' side of appearance voting: HSV buckets of RGB pixels, found once per
//! pixel a frame, and counted per cell.

use travmap_core::frame::RgbImage;

/// The hue, saturation and value buckets of RGB pixels: `floor(p * n / range)`
/// (METHOD.md's Decision), hue over [0, 360) degrees wrapping red, saturation over
/// [0, 1] and value over [0, 256). Grey pixels have hue 0 and saturation 0.
///
/// The two divisions per pixel are multiplications by precomputed reciprocals
/// `ceil(2^32 / d)`, exact here because numerator times divisor stays below 2^32
/// (checked against plain division on every RGB value in the tests).
#[derive(Clone, Debug)]
pub struct HsvBuckets {
    bins: [u32; 3],
    /// Reciprocal of `6 delta` per delta = max - min.
    hue_reciprocal: [u64; 256],
    /// Reciprocal of `max` per max.
    saturation_reciprocal: [u64; 256],
}

impl HsvBuckets {
    /// `bins` (hue, saturation, value) must each be in 1..=256.
    pub fn new(bins: [u32; 3]) -> Self {
        let reciprocal = |d: u64| if d == 0 { 0 } else { (1u64 << 32).div_ceil(d) };
        Self {
            bins,
            hue_reciprocal: std::array::from_fn(|delta| reciprocal(6 * delta as u64)),
            saturation_reciprocal: std::array::from_fn(|max| reciprocal(max as u64)),
        }
    }

    #[inline]
    pub fn of(&self, r: u8, g: u8, b: u8) -> [u32; 3] {
        let (r, g, b) = (r as u32, g as u32, b as u32);
        let max = r.max(g).max(b);
        let min = r.min(g).min(b);
        let delta = max - min;
        // Hue in units of delta: [0, 6 delta), 60 degrees per unit; red wraps. All
        // three sectors' values are computed (wrapping where unused) and one is
        // selected: a branch per pixel on the sector was mispredicted on real images.
        let from_red = (g + 6 * delta).wrapping_sub(b);
        let from_red = if from_red >= 6 * delta {
            from_red.wrapping_sub(6 * delta)
        } else {
            from_red
        };
        let from_green = (b + 2 * delta).wrapping_sub(r);
        let from_blue = (r + 4 * delta).wrapping_sub(g);
        let hue = if max == r {
            from_red
        } else if max == g {
            from_green
        } else {
            from_blue
        };
        let divide = |n: u32, reciprocal: u64| ((n as u64 * reciprocal) >> 32) as u32;
        let [hue_bins, saturation_bins, value_bins] = self.bins;
        // A zero reciprocal (grey, black) gives bucket 0.
        let h = divide(hue * hue_bins, self.hue_reciprocal[delta as usize]).min(hue_bins - 1);
        let s = divide(
            delta * saturation_bins,
            self.saturation_reciprocal[max as usize],
        )
        .min(saturation_bins - 1);
        let v = max * value_bins / 256;
        [h, s, v]
    }
}

/// An image's pixels as their (hue, saturation, value) buckets, each block of a row
/// found when a cell first covers it. The cells' prisms overlap in the image: on the
/// 36 m training grid they cover ~1.1 M pixels a frame, 2.3 times the image, and each
/// pixel's buckets were found again for every cell; on the 12 m grid they cover a
/// quarter of it, so whole rows would be found in vain. A bucket is below 256
/// ([`HsvBuckets::new`]), so a byte.
pub(super) struct BucketRows<'a> {
    image: &'a RgbImage,
    buckets: &'a HsvBuckets,
    pixels: Vec<[u8; 3]>,
    /// Per row, per block of [`Self::BLOCK`] pixels: found yet.
    found: Vec<bool>,
    blocks_per_row: usize,
}

impl<'a> BucketRows<'a> {
    const BLOCK: usize = 32;

    pub(super) fn new(image: &'a RgbImage, buckets: &'a HsvBuckets) -> Self {
        let blocks_per_row = (image.width as usize).div_ceil(Self::BLOCK);
        Self {
            image,
            buckets,
            // Zeroed memory the system maps as it is touched: what no cell covers
            // costs nothing.
            pixels: vec![[0; 3]; image.width as usize * image.height as usize],
            found: vec![false; blocks_per_row * image.height as usize],
            blocks_per_row,
        }
    }

    /// The buckets of row `y`'s pixels `x0..x1` (`x0 < x1`).
    pub(super) fn span(&mut self, y: u32, x0: u32, x1: u32) -> &[[u8; 3]] {
        let (y, x0, x1) = (y as usize, x0 as usize, x1 as usize);
        let row_start = y * self.image.width as usize;
        for block in x0 / Self::BLOCK..=(x1 - 1) / Self::BLOCK {
            let found = &mut self.found[y * self.blocks_per_row + block];
            if *found {
                continue;
            }
            *found = true;
            let start = row_start + block * Self::BLOCK;
            let end = (start + Self::BLOCK).min(row_start + self.image.width as usize);
            let rgb = &self.image.rgb[3 * start..3 * end];
            for (out, px) in self.pixels[start..end].iter_mut().zip(rgb.chunks_exact(3)) {
                let [h, s, v] = self.buckets.of(px[0], px[1], px[2]);
                *out = [h as u8, s as u8, v as u8];
            }
        }
        &self.pixels[row_start + x0..row_start + x1]
    }
}

/// One cell's pixels counted per hue, saturation and value bucket. Pixels alternate
/// between two sets of counts: a pixel's bucket is most often the one before it, and
/// one set would make each count wait for the last one to be stored.
pub(super) struct PixelCounts {
    /// [hue, saturation, value] buckets of even pixels, then of odd ones.
    buckets: [[[u32; 256]; 3]; 2],
    pub(super) pixels: u32,
}

impl Default for PixelCounts {
    fn default() -> Self {
        Self {
            buckets: [[[0; 256]; 3]; 2],
            pixels: 0,
        }
    }
}

impl PixelCounts {
    pub(super) fn clear(&mut self, bins: [u32; 3]) {
        for set in &mut self.buckets {
            for (counts, &bins) in set.iter_mut().zip(&bins) {
                counts[..bins as usize].fill(0);
            }
        }
        self.pixels = 0;
    }

    /// Counts a run of pixels' (hue, saturation, value) buckets.
    pub(super) fn add(&mut self, pixels: &[[u8; 3]]) {
        let [even, odd] = &mut self.buckets;
        let count = |set: &mut [[u32; 256]; 3], [h, s, v]: [u8; 3]| {
            set[0][h as usize] += 1;
            set[1][s as usize] += 1;
            set[2][v as usize] += 1;
        };
        let mut pairs = pixels.chunks_exact(2);
        for pair in &mut pairs {
            count(even, pair[0]);
            count(odd, pair[1]);
        }
        if let [last] = *pairs.remainder() {
            count(even, last);
        }
        self.pixels += pixels.len() as u32;
    }

    /// Appends the hue, saturation and value counts, then the number of pixels.
    pub(super) fn append_to(&self, bins: [u32; 3], out: &mut Vec<u32>) {
        let [even, odd] = &self.buckets;
        for (k, &bins) in bins.iter().enumerate() {
            let (even, odd) = (&even[k][..bins as usize], &odd[k][..bins as usize]);
            out.extend(even.iter().zip(odd).map(|(a, b)| a + b));
        }
        out.push(self.pixels);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use travmap_core::random::SplitMix64;

    const BINS: [u32; 3] = [32, 8, 48];

    /// The buckets by plain division, as METHOD.md writes them.
    fn reference(r: u8, g: u8, b: u8, bins: [u32; 3]) -> [u32; 3] {
        let (r, g, b) = (r as f64, g as f64, b as f64);
        let max = r.max(g).max(b);
        let delta = max - r.min(g).min(b);
        let hue_degrees = if delta == 0.0 {
            0.0
        } else if max == r {
            (60.0 * (g - b) / delta).rem_euclid(360.0)
        } else if max == g {
            60.0 * (b - r) / delta + 120.0
        } else {
            60.0 * (r - g) / delta + 240.0
        };
        let saturation = if max == 0.0 { 0.0 } else { delta / max };
        let bucket =
            |p: f64, n: u32, range: f64| ((p * n as f64 / range + 1e-9).floor() as u32).min(n - 1);
        [
            bucket(hue_degrees, bins[0], 360.0),
            bucket(saturation, bins[1], 1.0),
            bucket(max, bins[2], 256.0),
        ]
    }

    fn hsv_buckets(r: u8, g: u8, b: u8, bins: [u32; 3]) -> [u32; 3] {
        HsvBuckets::new(bins).of(r, g, b)
    }

    #[test]
    fn fast_buckets_equal_plain_division_on_every_colour() {
        for bins in [BINS, [256, 256, 256], [7, 3, 5], [1, 1, 1]] {
            let fast = HsvBuckets::new(bins);
            for r in 0..=255u8 {
                for g in 0..=255u8 {
                    for b in (0..=255u8).step_by(if bins == BINS { 1 } else { 17 }) {
                        assert_eq!(
                            fast.of(r, g, b),
                            reference(r, g, b, bins),
                            "rgb ({r}, {g}, {b}), bins {bins:?}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn pixel_counts_of_runs_are_each_pixels_buckets_counted_once() {
        let mut rng = SplitMix64(5);
        let buckets = HsvBuckets::new(BINS);
        let mut counts = PixelCounts::default();
        for _ in 0..50 {
            counts.clear(BINS);
            let mut expected = vec![0u32; (BINS[0] + BINS[1] + BINS[2] + 1) as usize];
            for run_pixels in 0..8 {
                let rgb: Vec<u8> = (0..3 * run_pixels)
                    .map(|_| rng.uniform(0.0, 256.0) as u8)
                    .collect();
                let pixels: Vec<[u8; 3]> = rgb
                    .chunks_exact(3)
                    .map(|px| buckets.of(px[0], px[1], px[2]).map(|b| b as u8))
                    .collect();
                counts.add(&pixels);
                for px in rgb.chunks_exact(3) {
                    let [h, s, v] = reference(px[0], px[1], px[2], BINS);
                    expected[h as usize] += 1;
                    expected[(BINS[0] + s) as usize] += 1;
                    expected[(BINS[0] + BINS[1] + v) as usize] += 1;
                }
            }
            *expected.last_mut().unwrap() = 28;
            let mut out = Vec::new();
            counts.append_to(BINS, &mut out);
            assert_eq!(out, expected);
        }
    }

    #[test]
    fn hsv_bucket_edges() {
        // Pure red is hue 0; a red a hair towards magenta wraps to the last hue bucket.
        assert_eq!(hsv_buckets(255, 0, 0, BINS), [0, 7, 47]);
        assert_eq!(hsv_buckets(255, 0, 1, BINS)[0], 31);
        // Green 120 degrees: bucket 120 * 32 / 360 = 10.67 -> 10; blue 240 -> 21.
        assert_eq!(hsv_buckets(0, 255, 0, BINS)[0], 10);
        assert_eq!(hsv_buckets(0, 0, 255, BINS)[0], 21);
        // Greys: hue 0, saturation 0, value by brightness; black is all zero.
        assert_eq!(hsv_buckets(128, 128, 128, BINS), [0, 0, 24]);
        assert_eq!(hsv_buckets(0, 0, 0, BINS), [0, 0, 0]);
        assert_eq!(hsv_buckets(255, 255, 255, BINS), [0, 0, 47]);
        // Half saturation: delta / max = 0.5 -> bucket 4.
        assert_eq!(hsv_buckets(200, 100, 100, BINS)[1], 4);
    }

    #[test]
    fn bucket_rows_give_each_pixels_buckets_whichever_spans_come_first() {
        let (width, height) = (70u32, 5u32);
        let mut rng = SplitMix64(9);
        let image = RgbImage {
            width,
            height,
            rgb: (0..3 * width * height)
                .map(|_| rng.uniform(0.0, 256.0) as u8)
                .collect(),
        };
        let buckets = HsvBuckets::new(BINS);
        let mut rows = BucketRows::new(&image, &buckets);
        for _ in 0..200 {
            let y = rng.uniform(0.0, height as f64) as u32;
            let x0 = rng.uniform(0.0, width as f64) as u32;
            let x1 = (x0 + 1 + rng.uniform(0.0, 40.0) as u32).min(width);
            let span = rows.span(y, x0, x1).to_vec();
            for (x, found) in (x0..x1).zip(span) {
                let at = 3 * (y * width + x) as usize;
                let px = &image.rgb[at..at + 3];
                let [h, s, v] = reference(px[0], px[1], px[2], BINS);
                assert_eq!(found, [h as u8, s as u8, v as u8], "pixel ({x}, {y})");
            }
        }
    }
}
