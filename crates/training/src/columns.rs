//! Samples stored column by column, for training's sums of one query against many
//! samples (the solver's kernel rows, k-means distances, the reduced set's design).
//! Stored by row, each sample's sum is a chain of dependent additions that the
//! compiler may not reorder; stored by column, a run of samples is summed side by
//! side in vector lanes, each lane still adding its terms in the row's order, so
//! every sum is the same to the bit as the sequential one.

use std::ops::Add;

pub(super) struct SampleColumns {
    /// `dimension` columns of `count` values each.
    values: Vec<f32>,
    count: usize,
}

impl SampleColumns {
    /// From row-major `rows` of `dimension` values.
    pub fn new(rows: &[f32], dimension: usize) -> Self {
        let count = rows.len() / dimension.max(1);
        let mut values = vec![0.0; count * dimension];
        for (i, row) in rows.chunks_exact(dimension).enumerate() {
            for (k, &v) in row.iter().enumerate() {
                values[k * count + i] = v;
            }
        }
        Self { values, count }
    }

    /// `out[j] = term(query[0], s[0]) + term(query[1], s[1]) + ...`, added in that
    /// order, for the samples `s` from `first` on (`out.len()` of them), as
    /// `iter().map(term).sum()` over a row gives it (whose sum starts at -0.0, which
    /// adds nothing). On x86-64 CPUs with AVX2 the loop is compiled a second time for
    /// them (twice the lanes; still no fused multiply-add, so the same bits).
    #[inline]
    pub fn sums<A, T>(&self, query: &[f32], first: usize, out: &mut [A], term: T)
    where
        A: Copy + Add<Output = A>,
        T: Fn(f32, f32) -> A,
    {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has just been checked to support AVX2.
            return unsafe { self.sums_avx2(query, first, out, term) };
        }
        self.sums_portable(query, first, out, term)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn sums_avx2<A, T>(&self, query: &[f32], first: usize, out: &mut [A], term: T)
    where
        A: Copy + Add<Output = A>,
        T: Fn(f32, f32) -> A,
    {
        self.sums_portable(query, first, out, term)
    }

    #[inline(always)]
    fn sums_portable<A, T>(&self, query: &[f32], first: usize, out: &mut [A], term: T)
    where
        A: Copy + Add<Output = A>,
        T: Fn(f32, f32) -> A,
    {
        let run = first..first + out.len();
        for (k, &q) in query.iter().enumerate() {
            let column = &self.values[k * self.count..(k + 1) * self.count][run.clone()];
            if k == 0 {
                for (o, &s) in out.iter_mut().zip(column) {
                    *o = term(q, s);
                }
            } else {
                for (o, &s) in out.iter_mut().zip(column) {
                    *o = *o + term(q, s);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use travmap_core::random::SplitMix64;

    #[test]
    fn sums_are_the_sequential_sums_to_the_bit() {
        let mut rng = SplitMix64(5);
        let d = 23;
        let rows: Vec<f32> = (0..37 * d)
            .map(|_| rng.uniform(-1e3, 1e3) as f32 * rng.uniform(0.0, 1e-3) as f32)
            .collect();
        let query: Vec<f32> = (0..d).map(|_| rng.uniform(-5.0, 5.0) as f32).collect();
        let columns = SampleColumns::new(&rows, d);
        let mut dots = vec![0f32; 30];
        columns.sums(&query, 7, &mut dots, |q, s| q * s);
        let mut distances = vec![0f64; 30];
        columns.sums(&query, 7, &mut distances, |q, s| ((s - q) as f64).powi(2));
        // The path for CPUs without AVX2 too.
        let mut portable = vec![0f32; 30];
        columns.sums_portable(&query, 7, &mut portable, |q, s| q * s);
        assert_eq!(portable, dots);
        for (j, row) in rows.chunks_exact(d).skip(7).take(30).enumerate() {
            let dot: f32 = query.iter().zip(row).map(|(a, b)| a * b).sum();
            let distance: f64 = row
                .iter()
                .zip(&query)
                .map(|(a, b)| ((a - b) as f64).powi(2))
                .sum();
            assert_eq!(dots[j].to_bits(), dot.to_bits());
            assert_eq!(distances[j].to_bits(), distance.to_bits());
        }
    }
}
