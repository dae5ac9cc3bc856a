//! The RBF decision sum `sum_i c_i exp(-gamma |x - sv_i|^2)` over all support
//! vectors, the cost of classification.
//!
//! Support vectors are stored in blocks of [`LANES`]: per block, for each dimension,
//! the values of its LANES vectors side by side, so the inner loops are elementwise
//! over fixed-size arrays and the compiler vectorises them; the exponential is a
//! branch-free polynomial that vectorises too (libm's `expf` does not). On x86-64 CPUs
//! with AVX2 and FMA the same code is compiled a second time for them and chosen at
//! run time, so one binary runs everywhere and fast where it can.

/// Support vectors per block: one AVX register of f32.
pub const LANES: usize = 8;

/// Support vectors laid out for [`SupportVectorBlocks::rbf_sum`], padded with zero-weight vectors.
#[derive(Clone, Debug, PartialEq)]
pub struct SupportVectorBlocks {
    /// The dimensions where some vector is not 0, ascending. The others add nothing
    /// to a dot product (a feature the model leaves out is 0 in every vector), so
    /// they are not stored and not multiplied.
    used: Vec<usize>,
    /// Per block, `used.len()` rows of LANES values.
    values: Vec<[f32; LANES]>,
    squared_norms: Vec<[f32; LANES]>,
    coefficients: Vec<[f32; LANES]>,
}

impl SupportVectorBlocks {
    /// From row-major support vectors and their coefficients.
    pub fn new(support_vectors: &[f32], coefficients: &[f32], dimension: usize) -> Self {
        let blocks = coefficients.len().div_ceil(LANES);
        let vectors = || {
            support_vectors
                .chunks_exact(dimension)
                .take(coefficients.len())
        };
        let used: Vec<usize> = (0..dimension)
            .filter(|&k| vectors().any(|sv| sv[k] != 0.0))
            .collect();
        let mut out = Self {
            values: vec![[0.0; LANES]; blocks * used.len()],
            squared_norms: vec![[0.0; LANES]; blocks],
            coefficients: vec![[0.0; LANES]; blocks],
            used,
        };
        for (i, (sv, &c)) in vectors().zip(coefficients).enumerate() {
            let (block, lane) = (i / LANES, i % LANES);
            for (row, &k) in out.used.iter().enumerate() {
                out.values[block * out.used.len() + row][lane] = sv[k];
            }
            out.squared_norms[block][lane] = sv.iter().map(|v| v * v).sum();
            out.coefficients[block][lane] = c;
        }
        out
    }

    /// `sum_i c_i exp(-gamma |z - sv_i|^2)` for a standardised row `z`.
    pub fn rbf_sum(&self, z: &[f32], gamma: f32) -> f32 {
        self.with_used(z, |blocks, used, z_norm| {
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                // SAFETY: the CPU has just been checked to support AVX2 and FMA.
                return unsafe { rbf_sum_avx2_fma(blocks, used, z_norm, gamma) };
            }
            rbf_sum::<false>(blocks, used, z_norm, gamma)
        })
    }

    /// The portable path, whatever the CPU (for tests against the fast one).
    #[cfg(test)]
    fn rbf_sum_portable(&self, z: &[f32], gamma: f32) -> f32 {
        self.with_used(z, |blocks, used, z_norm| {
            rbf_sum::<false>(blocks, used, z_norm, gamma)
        })
    }

    /// Calls `f` with `z`'s values in the used dimensions (gathered on the stack) and
    /// the squared norm of all of `z`.
    fn with_used(&self, z: &[f32], f: impl FnOnce(&Self, &[f32], f32) -> f32) -> f32 {
        let z_norm: f32 = z.iter().map(|v| v * v).sum();
        let gather = |out: &mut [f32]| {
            for (o, &k) in out.iter_mut().zip(&self.used) {
                *o = z.get(k).copied().unwrap_or(0.0);
            }
        };
        let mut on_stack = [0f32; 128];
        if let Some(used) = on_stack.get_mut(..self.used.len()) {
            gather(used);
            f(self, used, z_norm)
        } else {
            let mut used = vec![0f32; self.used.len()];
            gather(&mut used);
            f(self, &used, z_norm)
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn rbf_sum_avx2_fma(blocks: &SupportVectorBlocks, z: &[f32], z_norm: f32, gamma: f32) -> f32 {
    rbf_sum::<true>(blocks, z, z_norm, gamma)
}

/// `a * b + c`, fused where the target has FMA (without it `mul_add` is a libm call).
#[inline(always)]
fn multiply_add<const FUSED: bool>(a: f32, b: f32, c: f32) -> f32 {
    if FUSED { a.mul_add(b, c) } else { a * b + c }
}

/// Blocks whose dot products are summed side by side. Each lane's dot product is one
/// chain of `dimension` dependent multiply-adds: a block alone waits out the latency
/// of each (classification took the chains' latency, not the units' throughput);
/// four chains in flight keep the units busy. Each lane still adds its terms in the
/// same order, so the sums are the same to the bit.
const BLOCKS_AT_ONCE: usize = 4;

/// [`SupportVectorBlocks::rbf_sum`] of `z` in the used dimensions, `z_norm` its
/// squared norm in all.
#[inline(always)]
fn rbf_sum<const FUSED: bool>(
    blocks: &SupportVectorBlocks,
    z: &[f32],
    z_norm: f32,
    gamma: f32,
) -> f32 {
    let mut total = [0f32; LANES];
    let mut add = |dot: &[f32; LANES], block: usize| {
        let (norms, coefficients) = (&blocks.squared_norms[block], &blocks.coefficients[block]);
        for l in 0..LANES {
            let distance = (z_norm + norms[l] - 2.0 * dot[l]).max(0.0);
            total[l] = multiply_add::<FUSED>(
                coefficients[l],
                exp_non_positive::<FUSED>(-gamma * distance),
                total[l],
            );
        }
    };
    let count = blocks.coefficients.len();
    let grouped = count - count % BLOCKS_AT_ONCE;
    for first in (0..grouped).step_by(BLOCKS_AT_ONCE) {
        let dots = dot_products::<BLOCKS_AT_ONCE, FUSED>(blocks, first, z);
        for (g, dot) in dots.iter().enumerate() {
            add(dot, first + g);
        }
    }
    for block in grouped..count {
        add(&dot_products::<1, FUSED>(blocks, block, z)[0], block);
    }
    total.iter().sum()
}

/// The dot products of `z` with the LANES vectors of each of blocks `first..first + G`.
#[inline(always)]
fn dot_products<const G: usize, const FUSED: bool>(
    blocks: &SupportVectorBlocks,
    first: usize,
    z: &[f32],
) -> [[f32; LANES]; G] {
    let d = blocks.used.len();
    // Each block's rows sliced to the length of `z` once, so that indexing them by
    // position in `z` needs no bounds check per block and term in the hot loop.
    let z = &z[..d.min(z.len())];
    let rows: [&[[f32; LANES]]; G] =
        std::array::from_fn(|g| &blocks.values[(first + g) * d..][..z.len()]);
    let mut dots = [[0f32; LANES]; G];
    for (k, &zk) in z.iter().enumerate() {
        for (dot, rows) in dots.iter_mut().zip(&rows) {
            let row = &rows[k];
            for l in 0..LANES {
                dot[l] = multiply_add::<FUSED>(zk, row[l], dot[l]);
            }
        }
    }
    dots
}

/// `e^x` for `x <= 0` (0 below -87), relative error under 2e-7: `x = n ln 2 + r`,
/// `e^r` by Cephes' degree-6 polynomial, `2^n` put straight into the exponent bits.
#[inline(always)]
fn exp_non_positive<const FUSED: bool>(x: f32) -> f32 {
    const ROUND: f32 = 12_582_912.0; // 1.5 * 2^23: adding it rounds to an integer
    let x = x.max(-87.0);
    let shifted = x * std::f32::consts::LOG2_E + ROUND;
    let n = shifted - ROUND;
    // ln 2 = 355/512 - 2.121944e-4 (Cephes): the first part is exact in f32, so r is too.
    let r = multiply_add::<FUSED>(
        n,
        2.121_944_4e-4,
        multiply_add::<FUSED>(n, -355.0 / 512.0, x),
    );
    let mut p = 1.987_569_1e-4;
    for c in [
        1.398_199_9e-3,
        8.333_452e-3,
        4.166_579_6e-2,
        0.166_666_65,
        0.5,
    ] {
        p = multiply_add::<FUSED>(p, r, c);
    }
    let e = multiply_add::<FUSED>(p, r * r, r + 1.0);
    // The integer n sits in the low mantissa bits of `shifted`.
    let n_int = shifted.to_bits().wrapping_sub(ROUND.to_bits()) as i32;
    e * f32::from_bits(((n_int + 127) as u32) << 23)
}

#[cfg(test)]
mod tests {
    use super::*;
    use travmap_core::random::SplitMix64;

    #[test]
    fn exponential_is_accurate_over_its_range() {
        let mut worst = 0.0f64;
        for i in 0..=870_000 {
            let x = -(i as f32) * 1e-4;
            let reference = (x as f64).exp();
            for fast in [exp_non_positive::<false>(x), exp_non_positive::<true>(x)] {
                worst = worst.max((fast as f64 - reference).abs() / reference);
            }
        }
        assert!(worst < 3e-7, "worst relative error {worst}");
        assert_eq!(exp_non_positive::<false>(0.0), 1.0);
        assert!(exp_non_positive::<false>(-1e6) < 1e-37);
    }

    #[test]
    fn blocked_sum_matches_a_plain_f64_sum_and_skips_unused_dimensions() {
        let mut rng = SplitMix64(4);
        let (d, n) = (20, 37); // 37 is not a multiple of LANES: padding is exercised
        let mut svs: Vec<f32> = (0..n * d).map(|_| rng.uniform(-2.0, 2.0) as f32).collect();
        // Two dimensions no vector uses (features left out): not stored, yet the
        // row's values there still count in its distance to every vector.
        for sv in svs.chunks_exact_mut(d) {
            (sv[3], sv[11]) = (0.0, 0.0);
        }
        let coefficients: Vec<f32> = (0..n).map(|_| rng.uniform(-10.0, 10.0) as f32).collect();
        let blocks = SupportVectorBlocks::new(&svs, &coefficients, d);
        assert_eq!(blocks.used.len(), d - 2);
        for _ in 0..50 {
            let z: Vec<f32> = (0..d).map(|_| rng.uniform(-2.0, 2.0) as f32).collect();
            let gamma = 0.05;
            let mut reference = 0.0f64;
            let mut scale = 0.0f64;
            for (sv, &c) in svs.chunks_exact(d).zip(&coefficients) {
                let dist: f64 = sv
                    .iter()
                    .zip(&z)
                    .map(|(a, b)| (*a as f64 - *b as f64).powi(2))
                    .sum();
                reference += c as f64 * (-gamma * dist).exp();
                scale += (c as f64).abs();
            }
            for fast in [
                blocks.rbf_sum(&z, gamma as f32),
                blocks.rbf_sum_portable(&z, gamma as f32),
            ] {
                assert!(
                    (fast as f64 - reference).abs() < 1e-5 * scale,
                    "{fast} vs {reference}"
                );
            }
        }
    }
}
