//! The reduced set (a Decision of this project, docs/speed.md): k-means centres of
//! the support vectors with weights fitted by least squares to the exact decision
//! function, so prediction costs the centres' count instead of the support vectors'.

use std::ops::Range;

use rayon::prelude::*;

use super::columns::SampleColumns;
use travmap_method::training_set::TrainingSet;

/// Rows of the reduced set's design matrix computed at a time.
const DESIGN_BLOCK_ROWS: usize = 1024;
use travmap_core::config::{Config, ForeignRemissionPolicy};
use travmap_core::random::SplitMix64;
use travmap_method::classifier::{PredictionScratch, ReducedSet, SvmModel};

/// Lloyd's k-means on row-major `points`, started from a seeded random subset;
/// an emptied cluster keeps its previous centre.
fn k_means(
    points: &[f32],
    d: usize,
    k: usize,
    iterations: usize,
    rng: &mut SplitMix64,
) -> Vec<f32> {
    let n = points.len() / d;
    let mut start: Vec<usize> = (0..n).collect();
    rng.shuffle(&mut start);
    let mut centres: Vec<f32> = start[..k]
        .iter()
        .flat_map(|&i| points[i * d..(i + 1) * d].iter().copied())
        .collect();
    for _ in 0..iterations {
        // The nearest centres on all cores; the sums in the points' order, so the
        // centres are the same whatever the thread count.
        let by_column = SampleColumns::new(&centres, d);
        let nearest: Vec<usize> = points
            .par_chunks_exact(d)
            .map_init(
                || vec![0f32; k],
                |distances, p| {
                    by_column.sums(p, 0, distances, |q, c| (c - q) * (c - q));
                    distances
                        .iter()
                        .enumerate()
                        .fold((0, f32::INFINITY), |best, (j, &dist)| {
                            if dist < best.1 { (j, dist) } else { best }
                        })
                        .0
                },
            )
            .collect();
        let mut sums = vec![0f64; k * d];
        let mut counts = vec![0usize; k];
        for (p, &nearest) in points.chunks_exact(d).zip(&nearest) {
            counts[nearest] += 1;
            for (s, &v) in sums[nearest * d..(nearest + 1) * d].iter_mut().zip(p) {
                *s += v as f64;
            }
        }
        for j in (0..k).filter(|&j| counts[j] > 0) {
            for (c, s) in centres[j * d..(j + 1) * d]
                .iter_mut()
                .zip(&sums[j * d..(j + 1) * d])
            {
                *c = (s / counts[j] as f64) as f32;
            }
        }
    }
    centres
}

/// Fits `training.reduced_set_size` kernel centres (k-means centres of the support
/// vectors) and their weights and bias by ridge least squares to the exact
/// decision values on at most `training.reduced_set_samples` training cells. None
/// when the model has no more support vectors than that.
pub(super) fn fit_reduced_set(
    model: &SvmModel,
    set: &TrainingSet,
    config: &Config,
) -> Option<ReducedSet> {
    fit_expansion(
        model,
        &model.support_vectors,
        &set.features,
        config,
        |row, [scratch, _]| model.exact_decision_value(row, scratch),
    )
}

/// A reduced set of the adapted model `model` that stands for its sum with its
/// prior (`margin + prior_weight x prior margin`, docs/method.md "Adaptation"), so that
/// classifying costs one expansion, not two: centres from both models' support
/// vectors (the prior's brought into `model`'s standardisation), fitted on `rows`
/// (raw features: the drive's cells) and the prior's support vectors.
pub(super) fn fit_folded_reduced_set(
    model: &SvmModel,
    prior: &SvmModel,
    weight: f32,
    rows: &[f32],
    config: &Config,
) -> Option<ReducedSet> {
    let d = model.dimension();
    // A prior with a prior of its own is not one expansion: it stays as it is.
    if prior.dimension() != d || prior.prior.is_some() {
        return None;
    }
    // Rows whose remission is foreign to the prior, where it classifies them by
    // its fallback: this expansion would not follow.
    let remission = travmap_method::features::FEATURE_COUNT;
    let uses_remission = config.classifier.foreign_remission == ForeignRemissionPolicy::Fallback
        && prior.fallback.is_some()
        && d > remission;
    if uses_remission
        && prior
            .foreign_remission_of(rows.chunks_exact(d).map(|r| r[remission]).collect())
            .is_some()
    {
        return None;
    }
    let prior_raw: Vec<f32> = prior.support_vectors_raw();
    let mut candidates = model.support_vectors.clone();
    let mut scratch = PredictionScratch::default();
    for row in prior_raw.chunks_exact(d) {
        candidates.extend_from_slice(model.standardise(row, &mut scratch));
    }
    let all_rows = [rows, &prior_raw].concat();
    fit_expansion(
        model,
        &candidates,
        &all_rows,
        config,
        |row, [own, other]| {
            model.exact_decision_value(row, own)
                + weight * (prior.exact_decision_value(row, other) - prior.threshold)
        },
    )
}

/// `training.reduced_set_size` k-means centres of `candidates` (standardised as
/// `model` does) with weights and bias by weighted ridge least squares to `target`
/// on at most `training.reduced_set_samples` of `rows` (raw features, row-major),
/// in `model`'s kernel (`target_of` is given two scratch spaces for the models it
/// runs); then `training.reduced_set_refinements` steps that move the centres
/// ([`Expansion::refine`]). None when there are no more candidates than centres.
fn fit_expansion(
    model: &SvmModel,
    candidates: &[f32],
    rows: &[f32],
    config: &Config,
    target_of: impl Fn(&[f32], [&mut PredictionScratch; 2]) -> f32 + Sync,
) -> Option<ReducedSet> {
    let t = &config.training;
    let d = model.dimension();
    if t.reduced_set_size == 0 || candidates.len() / d <= t.reduced_set_size {
        return None;
    }
    let mut rng = SplitMix64(t.seed ^ 0x5EED);
    let centres = k_means(candidates, d, t.reduced_set_size, 10, &mut rng);
    let mut chosen: Vec<usize> = (0..rows.len() / d).collect();
    rng.shuffle(&mut chosen);
    chosen.truncate(t.reduced_set_samples.max(1));
    // The samples standardised, and the exact decision value at each.
    let samples: Vec<(f64, Vec<f32>)> = chosen
        .par_iter()
        .map_init(
            <[PredictionScratch; 3]>::default,
            |[own, other, scratch], &i| {
                let features = &rows[i * d..(i + 1) * d];
                let target = target_of(features, [own, other]) as f64;
                (target, model.standardise(features, scratch).to_vec())
            },
        )
        .collect();
    let expansion = Expansion {
        target: nalgebra::DVector::from_iterator(samples.len(), samples.iter().map(|s| s.0)),
        samples: samples.into_iter().flat_map(|s| s.1).collect(),
        gamma: model.gamma,
        d,
    };
    let mut fitted = expansion.solve(centres)?;
    for _ in 0..t.reduced_set_refinements {
        fitted = expansion.refine(fitted);
    }
    let m = t.reduced_set_size;
    let agreeing = (fitted.values.iter().zip(expansion.target.iter()))
        .filter(|(f, e)| (**f > 0.0) == (**e > 0.0))
        .count();
    Some(ReducedSet::new(
        fitted.centres,
        fitted.solution.iter().take(m).map(|&w| w as f32).collect(),
        fitted.solution[m] as f32,
        agreeing as f64 / expansion.target.len() as f64,
    ))
}

/// What a reduced set is fitted to: standardised samples (row-major, `d` values
/// each), the exact decision value at each, and the kernel's gamma.
struct Expansion {
    samples: Vec<f32>,
    target: nalgebra::DVector<f64>,
    gamma: f64,
    d: usize,
}

/// Kernel centres with their fitted weights and bias (`solution`, the bias last),
/// the expansion's value at each sample, and its weighted squared error there.
struct Fitted {
    centres: Vec<f32>,
    solution: nalgebra::DVector<f64>,
    kernel: nalgebra::DMatrix<f64>,
    values: nalgebra::DVector<f64>,
    error: f64,
}

impl Expansion {
    /// A sample's weight in the fit: samples near the decision boundary decide
    /// signs, so they count more, `1 / (1 + f^2)`.
    fn weight(&self, sample: usize) -> f64 {
        1.0 / (1.0 + self.target[sample] * self.target[sample])
    }

    /// The weights and bias of `centres` by weighted ridge least squares.
    fn solve(&self, centres: Vec<f32>) -> Option<Fitted> {
        let (d, n) = (self.d, self.target.len());
        let m = centres.len() / d;
        // Design matrix: the kernel to every centre plus a column of ones for the
        // bias. Rows are computed on all cores a block at a time (the matrix is
        // column-major, so a block is copied in; whole, the copy would double the
        // matrix's memory).
        let by_column = SampleColumns::new(&centres, d);
        let mut design = nalgebra::DMatrix::<f64>::zeros(n, m + 1);
        for (block, rows) in self.samples.chunks(DESIGN_BLOCK_ROWS * d).enumerate() {
            let block_rows: Vec<Vec<f64>> = rows
                .par_chunks_exact(d)
                .map(|z| {
                    let mut kernel = vec![0f64; m];
                    by_column.sums(z, 0, &mut kernel, |q, c| ((c - q) as f64).powi(2));
                    kernel
                        .iter_mut()
                        .for_each(|k| *k = (-self.gamma * *k).exp());
                    kernel
                })
                .collect();
            for (offset, kernel) in block_rows.into_iter().enumerate() {
                let r = block * DESIGN_BLOCK_ROWS + offset;
                for (j, k) in kernel.into_iter().enumerate() {
                    design[(r, j)] = k;
                }
                design[(r, m)] = 1.0;
            }
        }
        let mut weighted = design.clone();
        let mut weighted_target = self.target.clone();
        for r in 0..n {
            let w = self.weight(r).sqrt();
            weighted.row_mut(r).scale_mut(w);
            weighted_target[r] *= w;
        }
        let mut normal = gram(&weighted);
        let right = transposed_times(&weighted, &weighted_target);
        // A small ridge keeps the system positive definite when centres nearly coincide.
        let ridge = 1e-6 * (0..=m).map(|j| normal[(j, j)]).fold(0.0, f64::max);
        for j in 0..=m {
            normal[(j, j)] += ridge;
        }
        let solution = normal.cholesky()?.solve(&right);
        let values = &design * &solution;
        let error = (0..n)
            .map(|r| self.weight(r) * (self.target[r] - values[r]).powi(2))
            .sum();
        Some(Fitted {
            centres,
            solution,
            kernel: design,
            values,
            error,
        })
    }

    /// One step of the centres down the gradient of the weighted squared error, its
    /// length found by halving from a step that moves the farthest centre 0.1 (in
    /// standard deviations), with the weights re-solved at each try; `fitted` as it
    /// was when no step lowers the error.
    fn refine(&self, fitted: Fitted) -> Fitted {
        let (d, n) = (self.d, self.target.len());
        let m = fitted.centres.len() / d;
        // dE/dc_j = -4 gamma beta_j sum_i w_i r_i K_ij (z_i - c_j)
        let residual: Vec<f64> = (0..n)
            .map(|r| self.weight(r) * (self.target[r] - fitted.values[r]))
            .collect();
        let descent: Vec<f64> = (0..m)
            .into_par_iter()
            .flat_map_iter(|j| {
                let (mut along, mut total) = (vec![0f64; d], 0f64);
                for (r, z) in self.samples.chunks_exact(d).enumerate() {
                    let k = residual[r] * fitted.kernel[(r, j)];
                    total += k;
                    for (a, &v) in along.iter_mut().zip(z) {
                        *a += k * v as f64;
                    }
                }
                let scale = 4.0 * self.gamma * fitted.solution[j];
                let centre = &fitted.centres[j * d..(j + 1) * d];
                (0..d).map(move |k| scale * (along[k] - total * centre[k] as f64))
            })
            .collect();
        let longest = descent
            .chunks_exact(d)
            .map(|g| g.iter().map(|v| v * v).sum::<f64>().sqrt())
            .fold(0.0, f64::max);
        if longest == 0.0 {
            return fitted;
        }
        let mut step = 0.1 / longest;
        for _ in 0..4 {
            let moved: Vec<f32> = (fitted.centres.iter().zip(&descent))
                .map(|(&c, &g)| (c as f64 + step * g) as f32)
                .collect();
            match self.solve(moved) {
                Some(better) if better.error < fitted.error => return better,
                _ => step *= 0.5,
            }
        }
        fitted
    }
}

/// Columns of the Gram matrix's panels multiplied at a time, at most.
const GRAM_PANEL_COLUMNS: usize = 64;

/// `w^T w` on all cores. The product is symmetric, so only the panels on and above
/// the diagonal are multiplied (0.57 of the work for the reduced set's 385 columns),
/// each by the gemm of the whole product over the same rows, so every sum is taken
/// in the same order and the matrix is the same to the bit.
fn gram(w: &nalgebra::DMatrix<f64>) -> nalgebra::DMatrix<f64> {
    let (rows, n) = w.shape();
    let count = n.div_ceil(GRAM_PANEL_COLUMNS);
    // nalgebra hands only products over 5 in every dimension to matrixmultiply; the
    // panels are kept above that.
    if count < 2 || rows <= 5 {
        return w.transpose() * w;
    }
    let panels: Vec<Range<usize>> = (0..count)
        .map(|k| k * n / count..(k + 1) * n / count)
        .collect();
    let pairs: Vec<(usize, usize)> = (0..count)
        .flat_map(|i| (i..count).map(move |j| (i, j)))
        .collect();
    let products: Vec<nalgebra::DMatrix<f64>> = pairs
        .par_iter()
        .map(|&(i, j)| {
            let (left, right) = (&panels[i], &panels[j]);
            let mut product = nalgebra::DMatrix::zeros(left.len(), right.len());
            let left_rows = nalgebra::DMatrixView::from_slice_with_strides(
                &w.as_slice()[left.start * rows..left.end * rows],
                left.len(),
                rows,
                rows,
                1,
            );
            product.gemm(1.0, &left_rows, &w.columns(right.start, right.len()), 0.0);
            product
        })
        .collect();
    let mut gram = nalgebra::DMatrix::zeros(n, n);
    for (&(i, j), product) in pairs.iter().zip(&products) {
        let (left, right) = (panels[i].start, panels[j].start);
        gram.view_mut((left, right), product.shape())
            .copy_from(product);
        gram.view_mut((right, left), (product.ncols(), product.nrows()))
            .tr_copy_from(product);
    }
    gram
}

/// Columns of `w` summed side by side in [`transposed_times`].
const COLUMNS_AT_ONCE: usize = 8;

/// `w^T v`, each column's sum taken down its rows in order as the product of `w`'s
/// transposed copy with `v` takes it (to the bit), without the copy; columns side
/// by side keep several of the dependent adds in flight.
fn transposed_times(
    w: &nalgebra::DMatrix<f64>,
    v: &nalgebra::DVector<f64>,
) -> nalgebra::DVector<f64> {
    let rows = w.nrows();
    let mut product = nalgebra::DVector::zeros(w.ncols());
    let groups = w.as_slice().chunks(rows.max(1) * COLUMNS_AT_ONCE);
    for (sums, group) in product
        .as_mut_slice()
        .chunks_mut(COLUMNS_AT_ONCE)
        .zip(groups)
    {
        for (r, &value) in v.iter().enumerate() {
            for (k, sum) in sums.iter_mut().enumerate() {
                *sum += group[k * rows + r] * value;
            }
        }
    }
    product
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train;

    #[test]
    fn reduced_set_follows_the_exact_decision_function() {
        // A curved boundary that needs many support vectors: x^2 + y^2 < 1.
        let mut set = TrainingSet {
            dimension: 2,
            ..Default::default()
        };
        let mut rng = SplitMix64(21);
        for i in 0..1500 {
            let (x, y) = (rng.uniform(-2.0, 2.0), rng.uniform(-2.0, 2.0));
            set.push(
                &[x as f32, y as f32],
                None,
                x * x + y * y < 1.0,
                [(i % 40) as f64, (i / 40) as f64],
            );
        }
        let mut config = crate::tests::paper_config();
        config.training.c_values = vec![10.0];
        config.training.gamma_values = vec![1.0];
        config.training.reduced_set_size = 24;
        let model = train(&set, &config, &|_, _| {}).unwrap();
        assert!(
            model.support_vector_count() > 24,
            "{} support vectors",
            model.support_vector_count()
        );
        let reduced = model.reduced_set.as_ref().expect("a reduced set");
        assert_eq!(reduced.len(), 24);
        assert!(
            reduced.training_agreement > 0.98,
            "{}",
            reduced.training_agreement
        );
        let mut scratch = model.scratch();
        let agreeing = set
            .features
            .chunks_exact(2)
            .filter(|row| {
                (model.decision_value(row, &mut scratch) > 0.0)
                    == (model.exact_decision_value(row, &mut scratch) > 0.0)
            })
            .count();
        assert!(
            agreeing as f64 / set.len() as f64 > 0.98,
            "{agreeing} of {}",
            set.len()
        );
        // The file keeps it.
        let mut exact = model.clone();
        exact.reduced_set = None;
        assert_ne!(exact.to_json(), model.to_json());
    }

    #[test]
    fn gram_and_transposed_times_are_the_transposed_products_to_the_bit() {
        let mut rng = SplitMix64(5);
        for (rows, columns) in [(10, 1), (33, 64), (700, 150), (300, 385), (4, 200), (0, 3)] {
            let w = nalgebra::DMatrix::from_fn(rows, columns, |_, _| rng.uniform(-2.0, 2.0));
            let v = nalgebra::DVector::from_fn(rows, |_, _| rng.uniform(-1.0, 1.0));
            let transposed = w.transpose();
            // assert! rather than assert_eq!: a failure prints no matrix of 150,000 values.
            assert!(gram(&w) == &transposed * &w, "{rows} x {columns}");
            assert!(
                transposed_times(&w, &v) == &transposed * &v,
                "{rows} x {columns}"
            );
        }
    }

    #[test]
    fn k_means_finds_separated_clusters() {
        let points: Vec<f32> = (0..60)
            .flat_map(|i| {
                if i % 2 == 0 {
                    [0.0 + 0.01 * i as f32, 0.0]
                } else {
                    [10.0, 10.0 + 0.01 * i as f32]
                }
            })
            .collect();
        let centres = k_means(&points, 2, 2, 5, &mut SplitMix64(1));
        let mut xs: Vec<f32> = centres.chunks_exact(2).map(|c| c[0]).collect();
        xs.sort_by(f32::total_cmp);
        assert!(
            (xs[0] - 0.29).abs() < 0.01 && (xs[1] - 10.0).abs() < 1e-4,
            "{centres:?}"
        );
    }
}
