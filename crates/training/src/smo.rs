//! The C-SVC dual solver: sequential minimal optimisation with libsvm's
//! second-order working-set selection (Fan, Chen and Lin, JMLR 2005) and an LRU
//! cache of kernel rows, so memory stays bounded at any sample count.
//!
//! Why our own: the pure-Rust SVM crates measured for this project either train far
//! too slowly or hold the n x n kernel matrix (linfa-svm: 26 s and 0.8 GB at 10k
//! samples). This is the algorithm libsvm runs, without shrinking, over a flat f32
//! sample matrix.

use std::sync::Arc;

use rayon::prelude::*;

use super::columns::SampleColumns;
use super::working_set::{Duals, Scratch, most_violating, partner, positive_curvature};

/// A row is split across cores in pieces of at least this many entries (they are
/// independent, so the row is the same); a shorter one stays on one thread.
const PARALLEL_ROW_LENGTH: usize = 4096;

/// Entries of a row computed together (their sums side by side in vector lanes).
const ROW_BLOCK: usize = 1024;

/// Samples (row-major, standardised) with labels +1 / -1.
pub struct Problem<'a> {
    pub samples: &'a [f32],
    pub dimension: usize,
    pub labels: &'a [f32],
    /// Per-sample weights on C (empty: all 1).
    pub weights: &'a [f32],
}

#[derive(Clone, Copy, Debug)]
pub struct Parameters {
    pub c: f64,
    /// C of a sample is `c` times its class's weight (libsvm's `-w`).
    pub positive_weight: f64,
    pub negative_weight: f64,
    pub gamma: f64,
    /// Stop when the maximal KKT violation is below this.
    pub tolerance: f64,
    pub cache_bytes: usize,
}

#[derive(Clone, Debug)]
pub struct Solution {
    /// Dual variables, one per sample, in [0, C].
    pub alpha: Vec<f64>,
    /// Offset: the decision value is sum(alpha_i y_i K(x_i, x)) - rho.
    pub rho: f64,
    pub iterations: usize,
    /// False when the iteration limit stopped the solver first.
    pub converged: bool,
}

/// Rows of `Q_ij = y_i y_j K(x_i, x_j)`, computed on demand, least recently used
/// evicted first.
struct KernelRows<'a> {
    problem: &'a Problem<'a>,
    gamma: f32,
    squared_norms: Vec<f32>,
    columns: SampleColumns,
    rows: Vec<Option<Arc<[f32]>>>,
    last_used: Vec<u64>,
    cached: Vec<usize>,
    capacity: usize,
    clock: u64,
}

impl<'a> KernelRows<'a> {
    fn new(problem: &'a Problem<'a>, gamma: f64, cache_bytes: usize) -> Self {
        let n = problem.labels.len();
        let squared_norms = problem
            .samples
            .chunks_exact(problem.dimension)
            .map(|x| x.iter().map(|v| v * v).sum())
            .collect();
        Self {
            problem,
            gamma: gamma as f32,
            squared_norms,
            columns: SampleColumns::new(problem.samples, problem.dimension),
            rows: vec![None; n],
            last_used: vec![0; n],
            cached: Vec::new(),
            capacity: (cache_bytes / (4 * n.max(1))).max(2),
            clock: 0,
        }
    }

    fn row(&mut self, i: usize) -> Arc<[f32]> {
        self.clock += 1;
        self.last_used[i] = self.clock;
        if let Some(row) = &self.rows[i] {
            return row.clone();
        }
        if self.cached.len() >= self.capacity
            && let Some(position) =
                (0..self.cached.len()).min_by_key(|&k| self.last_used[self.cached[k]])
        {
            let evicted = self.cached.swap_remove(position);
            self.rows[evicted] = None;
        }
        let p = self.problem;
        let d = p.dimension;
        let xi = &p.samples[i * d..(i + 1) * d];
        let (yi, ni) = (p.labels[i], self.squared_norms[i]);
        let gamma = self.gamma;
        let mut row = vec![0f32; p.labels.len()];
        row.par_chunks_mut(ROW_BLOCK)
            .with_min_len(PARALLEL_ROW_LENGTH / ROW_BLOCK)
            .enumerate()
            .for_each(|(block, out)| {
                let first = block * ROW_BLOCK;
                self.columns.sums(xi, first, out, |a, b| a * b);
                for ((value, &yt), &nt) in out
                    .iter_mut()
                    .zip(&p.labels[first..])
                    .zip(&self.squared_norms[first..])
                {
                    let dot = *value;
                    *value = yi * yt * (-gamma * (ni + nt - 2.0 * dot).max(0.0)).exp();
                }
            });
        let row: Arc<[f32]> = row.into();
        self.rows[i] = Some(row.clone());
        self.cached.push(i);
        row
    }
}

/// Solves `min 1/2 a'Qa - e'a` subject to `0 <= a_i <= C_i`, `y'a = 0`, with `C_i`
/// C times sample i's class weight and its own weight. On x86-64 CPUs with AVX2 the
/// solver is compiled a second time for them: its passes over every sample get
/// twice the lanes (still no fused multiply-add, so the same bits).
pub fn solve(problem: &Problem, parameters: &Parameters) -> Solution {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has just been checked to support AVX2.
        return unsafe { solve_avx2(problem, parameters) };
    }
    solve_portable(problem, parameters)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn solve_avx2(problem: &Problem, parameters: &Parameters) -> Solution {
    solve_portable(problem, parameters)
}

#[inline(always)]
fn solve_portable(problem: &Problem, parameters: &Parameters) -> Solution {
    let n = problem.labels.len();
    let y: Vec<f64> = problem.labels.iter().map(|&v| v as f64).collect();
    // The upper bound of each variable: C times its class's weight.
    let (c_positive, c_negative) = (
        parameters.c * parameters.positive_weight,
        parameters.c * parameters.negative_weight,
    );
    let weight = |i: usize| problem.weights.get(i).map_or(1.0, |&w| w as f64);
    let c: Vec<f64> = y
        .iter()
        .enumerate()
        .map(|(i, &y)| weight(i) * if y > 0.0 { c_positive } else { c_negative })
        .collect();
    let mut kernel = KernelRows::new(problem, parameters.gamma, parameters.cache_bytes);
    let mut alpha = vec![0.0f64; n];
    let mut gradient = vec![-1.0f64; n];
    let max_iterations = (100 * n).max(10_000_000);
    let mut iterations = 0;
    let mut converged = false;
    let mut scratch = Scratch::default();

    while iterations < max_iterations {
        let duals = Duals {
            y: &y,
            alpha: &alpha,
            gradient: &gradient,
            c: &c,
        };
        // The maximal violating pair by second-order selection; none at optimality.
        let Some((i, g_max)) = most_violating(&duals, &mut scratch) else {
            converged = true;
            break;
        };
        let q_i = kernel.row(i);
        let (g_max2, j) = partner(&duals, y[i], g_max, &q_i, &mut scratch);
        let Some(j) = j.filter(|_| g_max + g_max2 >= parameters.tolerance) else {
            converged = true;
            break;
        };
        iterations += 1;
        let q_j = kernel.row(j);
        let (old_i, old_j) = (alpha[i], alpha[j]);
        let (mut a_i, mut a_j) = (old_i, old_j);
        let q_ij = q_i[j] as f64;
        // Q_ii = Q_jj = 1 for the RBF kernel.
        if y[i] != y[j] {
            let delta = (-gradient[i] - gradient[j]) / positive_curvature(2.0 + 2.0 * q_ij);
            let diff = a_i - a_j;
            a_i += delta;
            a_j += delta;
            // a_i - a_j = diff stays: clip at 0, then at each one's C (libsvm).
            let (c_i, c_j) = (c[i], c[j]);
            if diff > 0.0 {
                if a_j < 0.0 {
                    a_j = 0.0;
                    a_i = diff;
                }
            } else if a_i < 0.0 {
                a_i = 0.0;
                a_j = -diff;
            }
            if diff > c_i - c_j {
                if a_i > c_i {
                    a_i = c_i;
                    a_j = c_i - diff;
                }
            } else if a_j > c_j {
                a_j = c_j;
                a_i = c_j + diff;
            }
        } else {
            let delta = (gradient[i] - gradient[j]) / positive_curvature(2.0 - 2.0 * q_ij);
            let sum = a_i + a_j;
            a_i -= delta;
            a_j += delta;
            // a_i + a_j = sum stays: clip each against the box in turn.
            clip_with_sum(&mut a_i, &mut a_j, sum, c[i]);
            clip_with_sum(&mut a_j, &mut a_i, sum, c[j]);
        }
        alpha[i] = a_i;
        alpha[j] = a_j;
        let (d_i, d_j) = (a_i - old_i, a_j - old_j);
        for ((g, &qi), &qj) in gradient.iter_mut().zip(q_i.iter()).zip(q_j.iter()) {
            *g += qi as f64 * d_i + qj as f64 * d_j;
        }
    }
    let rho = offset(&y, &alpha, &gradient, &c);
    Solution {
        alpha,
        rho,
        iterations,
        converged,
    }
}

/// libsvm's clipping of a pair with a fixed sum: `first` down to its bound `c` when
/// the sum exceeds it, else `second` up to 0, the other taking up the rest.
fn clip_with_sum(first: &mut f64, second: &mut f64, sum: f64, c: f64) {
    if sum > c {
        if *first > c {
            *first = c;
            *second = sum - c;
        }
    } else if *second < 0.0 {
        *second = 0.0;
        *first = sum;
    }
}

/// rho: the mean of y_i G_i over free variables, else the middle of the feasible range.
fn offset(y: &[f64], alpha: &[f64], gradient: &[f64], c: &[f64]) -> f64 {
    let (mut upper, mut lower) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut free, mut free_sum) = (0usize, 0.0f64);
    for t in 0..y.len() {
        let yg = y[t] * gradient[t];
        let at_upper = alpha[t] >= c[t];
        let at_lower = alpha[t] <= 0.0;
        if at_upper {
            if y[t] < 0.0 {
                upper = upper.min(yg)
            } else {
                lower = lower.max(yg)
            }
        } else if at_lower {
            if y[t] > 0.0 {
                upper = upper.min(yg)
            } else {
                lower = lower.max(yg)
            }
        } else {
            free += 1;
            free_sum += yg;
        }
    }
    if free > 0 {
        free_sum / free as f64
    } else {
        (upper + lower) / 2.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use travmap_core::random::SplitMix64;

    fn decision(problem: &Problem, s: &Solution, gamma: f64, x: &[f32]) -> f64 {
        let d = problem.dimension;
        let mut f = -s.rho;
        for (t, xt) in problem.samples.chunks_exact(d).enumerate() {
            let dist: f32 = xt.iter().zip(x).map(|(a, b)| (a - b) * (a - b)).sum();
            f += s.alpha[t] * problem.labels[t] as f64 * (-gamma * dist as f64).exp();
        }
        f
    }

    fn parameters(c: f64, gamma: f64, tolerance: f64, cache_bytes: usize) -> Parameters {
        Parameters {
            c,
            positive_weight: 1.0,
            negative_weight: 1.0,
            gamma,
            tolerance,
            cache_bytes,
        }
    }

    #[test]
    fn separates_two_blobs_and_satisfies_the_constraints() {
        let mut rng = SplitMix64(11);
        let (mut samples, mut labels) = (Vec::new(), Vec::new());
        for i in 0..200 {
            let class = if i % 2 == 0 { 1.0f32 } else { -1.0 };
            samples.push(class * 1.5 + rng.uniform(-1.0, 1.0) as f32);
            samples.push(rng.uniform(-1.0, 1.0) as f32);
            labels.push(class);
        }
        let problem = Problem {
            samples: &samples,
            dimension: 2,
            labels: &labels,
            weights: &[],
        };
        let s = solve(&problem, &parameters(1.0, 0.5, 1e-3, 1 << 20));
        assert!(s.converged);
        let balance: f64 = s
            .alpha
            .iter()
            .zip(&labels)
            .map(|(a, &y)| a * y as f64)
            .sum();
        assert!(balance.abs() < 1e-9, "y'a = {balance}");
        assert!(s.alpha.iter().all(|&a| (0.0..=1.0).contains(&a)));
        assert!(decision(&problem, &s, 0.5, &[2.0, 0.0]) > 0.0);
        assert!(decision(&problem, &s, 0.5, &[-2.0, 0.0]) < 0.0);
        let correct = samples
            .chunks_exact(2)
            .zip(&labels)
            .filter(|(x, y)| decision(&problem, &s, 0.5, x).signum() as f32 == **y)
            .count();
        assert!(correct >= 195, "{correct} of 200 training samples right");
    }

    #[test]
    fn learns_xor_which_no_linear_model_can() {
        let points = [[1.0f32, 1.0], [-1.0, -1.0], [1.0, -1.0], [-1.0, 1.0]];
        let labels = [1.0f32, 1.0, -1.0, -1.0];
        let samples: Vec<f32> = points.iter().flatten().copied().collect();
        let problem = Problem {
            samples: &samples,
            dimension: 2,
            labels: &labels,
            weights: &[],
        };
        let s = solve(&problem, &parameters(10.0, 1.0, 1e-6, 16));
        for (x, y) in points.iter().zip(labels) {
            assert_eq!(decision(&problem, &s, 1.0, x).signum() as f32, y);
        }
        // By symmetry every sample is a support vector with the same weight and rho = 0.
        assert!(s.rho.abs() < 1e-6, "rho {}", s.rho);
        assert!(
            s.alpha
                .iter()
                .all(|&a| (a - s.alpha[0]).abs() < 1e-6 && a > 0.0)
        );
    }

    #[test]
    fn a_tiny_cache_gives_the_same_solution() {
        let mut rng = SplitMix64(5);
        let samples: Vec<f32> = (0..300).map(|_| rng.uniform(-2.0, 2.0) as f32).collect();
        let labels: Vec<f32> = samples
            .chunks_exact(3)
            .map(|x| {
                if x[0] * x[1] + 0.3 * x[2] > 0.0 {
                    1.0
                } else {
                    -1.0
                }
            })
            .collect();
        let problem = Problem {
            samples: &samples,
            dimension: 3,
            labels: &labels,
            weights: &[],
        };
        let big = parameters(5.0, 0.3, 1e-3, 1 << 20);
        let tiny = parameters(5.0, 0.3, 1e-3, 0);
        let (a, b) = (solve(&problem, &big), solve(&problem, &tiny));
        assert_eq!(a.alpha, b.alpha);
        assert_eq!(a.rho, b.rho);
    }
}
