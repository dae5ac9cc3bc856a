//! Training (METHOD.md section 6): z-score standardisation, a grid search over C
//! and gamma with cross-validation, and a final fit on every training cell.
//!
//! Folds are spatial (Decision of this project): the world plane is cut into square
//! blocks and whole blocks go to one fold, so no cell, nor its copies seen in other
//! frames, is in a training fold and its test fold at once. Random folds would let
//! the search reward memorising cells (consecutive frames share most cells).

pub mod adaptation;
mod columns;
pub mod crossval;
mod reduced_set;
pub mod smo;
pub mod teaching;
mod working_set;

use rayon::prelude::*;

use reduced_set::fit_reduced_set;
use smo::{Parameters, Problem};
use travmap_core::config::{
    ClassWeights, Config, Criterion, FeatureGroup, TrainingConfig, WeighInputs,
};
use travmap_core::error::{Error, Result};
use travmap_core::random::SplitMix64;
use travmap_method::classifier::calibration::Calibration;
use travmap_method::classifier::{
    ReducedSet, SearchResult, SvmModel, TrainingSummary, appearance_feature_names,
    model_feature_names,
};
use travmap_method::feature_groups::REMISSION_NAMES;
use travmap_method::features::{FEATURE_COUNT, feature_count};
use travmap_method::grid::CellClass;
pub use travmap_method::training_set::{TrainingSet, spatial_folds};
use travmap_run::scoring::metrics::Confusion;

/// Mean and 1/deviation of each feature; constant features get 1, those `config`
/// leaves out 0 (every standardised value 0: no part in the kernel's distances).
fn standardisation(set: &TrainingSet, config: &Config) -> (Vec<f32>, Vec<f32>) {
    let d = set.dimension;
    let n = set.len().max(1) as f64;
    let mut mean = vec![0f64; d];
    for row in set.features.chunks_exact(d) {
        for (m, &v) in mean.iter_mut().zip(row) {
            *m += v as f64;
        }
    }
    mean.iter_mut().for_each(|m| *m /= n);
    let mut variance = vec![0f64; d];
    for row in set.features.chunks_exact(d) {
        for ((s, &v), m) in variance.iter_mut().zip(row).zip(&mean) {
            *s += (v as f64 - m).powi(2);
        }
    }
    let left_out = &config.training.left_out_features;
    let inverse_std = variance
        .iter()
        .zip(model_feature_names(config, d))
        .map(|(s, name)| {
            let std = (s / n).sqrt();
            match left_out.contains(&name) {
                true => 0.0,
                false if std > 1e-12 => (1.0 / std) as f32,
                false => 1.0,
            }
        })
        .collect();
    (mean.iter().map(|&m| m as f32).collect(), inverse_std)
}

/// Fits one SVM on `set` with the given C and gamma.
fn fit(set: &TrainingSet, c: f64, gamma: f64, config: &Config) -> SvmModel {
    let d = set.dimension;
    let (mean, inverse_std) = standardisation(set, config);
    let standardised: Vec<f32> = set
        .features
        .chunks_exact(d)
        .flat_map(|row| {
            row.iter()
                .zip(&mean)
                .zip(&inverse_std)
                .map(|((&x, &m), &s)| (x - m) * s)
                .collect::<Vec<f32>>()
        })
        .collect();
    let labels: Vec<f32> = set
        .traversable
        .iter()
        .map(|&t| if t { 1.0 } else { -1.0 })
        .collect();
    let problem = Problem {
        samples: &standardised,
        dimension: d,
        labels: &labels,
        weights: &set.weight,
    };
    let (positive_weight, negative_weight) = class_weights(set, config.training.class_weights);
    let parameters = Parameters {
        c,
        positive_weight,
        negative_weight,
        gamma,
        tolerance: config.training.tolerance,
        cache_bytes: config.training.cache_mib << 20,
    };
    let solution = smo::solve(&problem, &parameters);
    let (mut coefficients, mut support_vectors) = (Vec::new(), Vec::new());
    for (i, &a) in solution.alpha.iter().enumerate() {
        if a > 0.0 {
            coefficients.push((a * labels[i] as f64) as f32);
            support_vectors.extend_from_slice(&standardised[i * d..(i + 1) * d]);
        }
    }
    let summary = TrainingSummary {
        sources: set.sources.clone(),
        samples: set.len(),
        traversable_samples: set.traversable.iter().filter(|t| **t).count(),
        search: Vec::new(),
        solver_iterations: solution.iterations,
        solver_converged: solution.converged,
        seconds: 0.0,
        frame_sha256: set.frame_sha256.clone(),
        adaptation: None,
    };
    SvmModel::new(
        mean,
        inverse_std,
        c,
        gamma,
        solution.rho as f32,
        coefficients,
        support_vectors,
        config.clone(),
        summary,
    )
}

/// The cells of several inputs, each input weighing as much in all: an input with
/// more than its share of `max_cells` gives a seeded random share, and each cell's
/// weight on C is scaled so that every input's weights sum alike.
fn weigh_inputs_equally(set: &TrainingSet, max_cells: usize, seed: u64) -> TrainingSet {
    let inputs: Vec<&std::ops::Range<usize>> =
        set.input_rows.iter().filter(|r| !r.is_empty()).collect();
    let share = (max_cells / inputs.len().max(1)).max(1);
    let mut rng = SplitMix64(seed);
    let mut indices = Vec::new();
    let mut scale = Vec::new();
    for rows in &inputs {
        let mut taken: Vec<usize> = (*rows).clone().collect();
        if taken.len() > share {
            rng.shuffle(&mut taken);
            taken.truncate(share);
            taken.sort_unstable();
        }
        let weight_sum: f64 = taken.iter().map(|&i| set.weight[i] as f64).sum();
        scale.extend(std::iter::repeat_n(1.0 / weight_sum, taken.len()));
        indices.extend(taken);
    }
    let mut weighed = set.subset(&indices);
    // Mean weight 1, as unweighted cells have.
    let mean: f64 = scale
        .iter()
        .zip(&weighed.weight)
        .map(|(s, w)| s * *w as f64)
        .sum::<f64>()
        / weighed.len() as f64;
    for (w, s) in weighed.weight.iter_mut().zip(&scale) {
        *w = (*w as f64 * s / mean) as f32;
    }
    weighed
}

/// The weights on C of the traversable and the non-traversable class.
fn class_weights(set: &TrainingSet, weights: ClassWeights) -> (f64, f64) {
    match weights {
        ClassWeights::None => (1.0, 1.0),
        ClassWeights::Balanced => {
            let n = set.len() as f64;
            let traversable = set.traversable.iter().filter(|t| **t).count() as f64;
            let weight = |cells: f64| if cells > 0.0 { n / (2.0 * cells) } else { 1.0 };
            (weight(traversable), weight(n - traversable))
        }
    }
}

/// The decision value of every cell of `set` under `model`, with its truth.
fn decision_values(model: &SvmModel, set: &TrainingSet) -> Vec<(f32, bool)> {
    let d = set.dimension;
    let mut scratch = model.scratch();
    set.features
        .chunks_exact(d)
        .zip(&set.traversable)
        .map(|(row, &truth)| (model.decision_value(row, &mut scratch), truth))
        .collect()
}

/// The confusion of cells called traversable when their value exceeds `threshold`.
fn confusion(values: &[(f32, bool)], threshold: f32) -> Confusion {
    let class = |traversable: bool| {
        if traversable {
            CellClass::Traversable
        } else {
            CellClass::NonTraversable
        }
    };
    let mut confusion = Confusion::default();
    for &(value, truth) in values {
        confusion.add(class(value > threshold), class(truth));
    }
    confusion
}

/// The threshold in [-1, 1] (the margin) that scores best by `criterion` on held-out
/// decision values; ties go to the one nearest 0. Candidates are the midpoints
/// between consecutive values, swept once over the sorted values.
fn best_threshold(values: &[(f32, bool)], criterion: Criterion) -> f32 {
    let mut sorted = values.to_vec();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    let traversable = sorted.iter().filter(|v| v.1).count() as u64;
    // Below the first value everything is traversable.
    let mut confusion = Confusion {
        tp: traversable,
        fp: sorted.len() as u64 - traversable,
        ..Confusion::default()
    };
    let score = |c: &Confusion| {
        let s = c.scores();
        match criterion {
            Criterion::Accuracy => s.accuracy,
            Criterion::Miou => s.miou,
        }
    };
    let (mut best, mut best_score) = (0.0f32, score(&self::confusion(values, 0.0)));
    for (k, &(value, truth)) in sorted.iter().enumerate() {
        // Raising the threshold past `value` turns this cell non-traversable.
        if truth {
            confusion.tp -= 1;
            confusion.r#fn += 1;
        } else {
            confusion.fp -= 1;
            confusion.tn += 1;
        }
        let next = sorted.get(k + 1).map_or(value + 1.0, |n| n.0);
        if next == value {
            continue;
        }
        let threshold = (value + next) / 2.0;
        if !(-1.0..=1.0).contains(&threshold) {
            continue;
        }
        let s = score(&confusion);
        if s > best_score || (s == best_score && threshold.abs() < best.abs()) {
            (best, best_score) = (threshold, s);
        }
    }
    best
}

/// How a model's C and gamma are chosen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Search {
    /// By the grid search over `training.c_values` and `gamma_values` with
    /// spatially-blocked cross-validation.
    Grid,
    /// As given (self-labelled cells have no labels to choose them by).
    Fixed { c: f64, gamma: f64 },
}

/// Trains the geometric model on every cell and, when cameras saw some, the hybrid
/// model on those (METHOD.md section 5's Decision). A hybrid set that cannot be
/// trained (one class, too few blocks) leaves the model geometric-only.
pub fn train(
    set: &TrainingSet,
    config: &Config,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<SvmModel> {
    train_by(set, config, Search::Grid, None, true, progress)
}

/// A reduced set fitted in place of a model's own, given the model and the cells it
/// was fitted on (adaptation's, which folds in the prior).
pub type Reduce<'a> = dyn Fn(&SvmModel, &TrainingSet) -> Option<ReducedSet> + Sync + 'a;

/// [`train`] with C and gamma chosen as `search` says, and the model's reduced set
/// by `reduce` when given (its hybrid and fallback always get their own); the
/// fallback without remission only when `fallback` asks (the caller supplies one
/// otherwise: a model with remission features carries one).
pub fn train_by(
    set: &TrainingSet,
    config: &Config,
    search: Search,
    reduce: Option<&Reduce>,
    fallback: bool,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<SvmModel> {
    check_left_out_features(set, config)?;
    // The model, its hybrid and the fallback are independent fits: run side by side,
    // the solvers' serial steps overlap.
    // Progress is the sum over the three: each reports its own (done, total).
    let parts = std::sync::Mutex::new([(0, 0); 3]);
    let part = |k: usize| {
        let parts = &parts;
        move |done: usize, total: usize| {
            let mut parts = parts.lock().unwrap_or_else(|e| e.into_inner());
            parts[k] = (done, total);
            let (done, total) = parts.iter().fold((0, 0), |s, p| (s.0 + p.0, s.1 + p.1));
            progress(done, total);
        }
    };
    let (model, (hybrid, fallback)) = rayon::join(
        || train_one(set, config, search, reduce, &part(0)),
        || {
            rayon::join(
                || {
                    let hybrid = set.hybrid()?;
                    Some(train_one(&hybrid, config, search, None, &part(1)))
                },
                || match fallback {
                    true => fallback_without_remission(set, config, search, &part(2)),
                    false => Ok(None),
                },
            )
        },
    );
    let mut model = model?;
    match hybrid {
        Some(Ok(hybrid)) => model.hybrid = Some(Box::new(hybrid)),
        Some(Err(Error::Training(_))) | None => {}
        Some(Err(e)) => return Err(e),
    }
    model.fallback = fallback?.map(Box::new);
    Ok(model)
}

/// Errors when `training.left_out_features` names a feature the cells do not have,
/// listing those they have.
fn check_left_out_features(set: &TrainingSet, config: &Config) -> Result<()> {
    let mut names = model_feature_names(config, set.dimension);
    names.extend(appearance_feature_names(&config.appearance));
    match config
        .training
        .left_out_features
        .iter()
        .find(|name| !names.contains(name))
    {
        Some(name) => Err(Error::Config(format!(
            "training.left_out_features: {name:?} is not a feature of these cells ({})",
            names.join(", ")
        ))),
        None => Ok(()),
    }
}

/// Where a cell's remission features are, when it has them.
pub const REMISSION_COLUMNS: std::ops::Range<usize> =
    FEATURE_COUNT..FEATURE_COUNT + REMISSION_NAMES.len();

/// `config` with its remission features taken out (and out of those left out).
pub fn config_without_remission(config: &Config) -> Config {
    let mut without = config.clone();
    without.features = config.features.without_remission();
    without
        .training
        .left_out_features
        .retain(|name| !REMISSION_NAMES.contains(&name.as_str()));
    without
}

/// Clouds without usable intensity get the same model without remission: the same
/// cells with the remission columns left out, so no second pass is needed. None
/// when the model has no remission features.
fn fallback_without_remission(
    set: &TrainingSet,
    config: &Config,
    search: Search,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Option<SvmModel>> {
    if !config.features.groups.contains(&FeatureGroup::Remission) {
        return Ok(None);
    }
    let without = config_without_remission(config);
    let columns = REMISSION_COLUMNS;
    if set.dimension < columns.end {
        return Err(Error::Training(format!(
            "{} values per cell: too few for remission features ({} expected)",
            set.dimension,
            feature_count(&config.features.groups)
        )));
    }
    train_by(
        &set.without_columns(columns),
        &without,
        search,
        None,
        false,
        progress,
    )
    .map(Some)
}

/// Grid search with spatially-blocked cross-validation, then a fit on all of `set`.
/// `progress(done, total)` is called after each fit.
fn train_one(
    set: &TrainingSet,
    config: &Config,
    search: Search,
    reduce: Option<&Reduce>,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<SvmModel> {
    let started = std::time::Instant::now();
    let t: &TrainingConfig = &config.training;
    let traversable = set.traversable.iter().filter(|t| **t).count();
    if traversable == 0 || traversable == set.len() {
        return Err(Error::Training(format!(
            "{} cells, {traversable} traversable: both classes are needed",
            set.len()
        )));
    }

    let weighed;
    let set = match t.weigh_inputs {
        WeighInputs::Equally if set.input_rows.len() > 1 => {
            weighed = weigh_inputs_equally(set, t.max_fit_samples, t.seed);
            &weighed
        }
        _ => set,
    };
    // The search and the final fit run on seeded random subsets when the set is
    // large; the fit's subset holds the search's.
    let mut order: Vec<usize> = (0..set.len()).collect();
    SplitMix64(t.seed).shuffle(&mut order);
    let subset = |n: usize| {
        let mut indices = order[..n.min(order.len())].to_vec();
        indices.sort_unstable();
        set.subset(&indices)
    };
    let fit_set = subset(t.max_fit_samples);
    let reduced_set = |model: &SvmModel| match reduce {
        Some(reduce) => reduce(model, &fit_set),
        None => fit_reduced_set(model, &fit_set, config),
    };
    if let Search::Fixed { c, gamma } = search {
        let mut model = fit(&fit_set, c, gamma, config);
        model.reduced_set = reduced_set(&model);
        progress(1, 1);
        model.training.seconds = started.elapsed().as_secs_f64();
        return Ok(model);
    }
    let search_set = subset(t.max_search_samples.max(t.folds));
    let folds = spatial_folds(&search_set.centre_in_world, t.block_size_m, t.folds, t.seed);
    let used_folds: Vec<usize> = (0..t.folds).filter(|f| folds.contains(f)).collect();
    if used_folds.len() < 2 {
        return Err(Error::Training(format!(
            "the cells span fewer than 2 blocks of {} m: lower training.block_size_m",
            t.block_size_m
        )));
    }
    let candidates: Vec<(f64, f64)> = t
        .c_values
        .iter()
        .flat_map(|&c| t.gamma_values.iter().map(move |&g| (c, g)))
        .collect();
    let jobs: Vec<(usize, usize)> = (0..candidates.len())
        .flat_map(|k| used_folds.iter().map(move |&f| (k, f)))
        .collect();
    let total = jobs.len() + 1;
    let done = std::sync::atomic::AtomicUsize::new(0);
    let held_out: Vec<(usize, Vec<(f32, bool)>)> = jobs
        .par_iter()
        .map(|&(k, fold)| {
            let (train_idx, test_idx): (Vec<usize>, Vec<usize>) =
                (0..search_set.len()).partition(|&i| folds[i] != fold);
            let (c, gamma) = candidates[k];
            let model = fit(&search_set.subset(&train_idx), c, gamma, config);
            let test = search_set.subset(&test_idx);
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            progress(n, total);
            (k, decision_values(&model, &test))
        })
        .collect();
    let search: Vec<SearchResult> = candidates
        .iter()
        .enumerate()
        .map(|(k, &(c, gamma))| {
            let mut pooled = Confusion::default();
            for (_, values) in held_out.iter().filter(|s| s.0 == k) {
                pooled.merge(&confusion(values, 0.0));
            }
            let scores = pooled.scores();
            SearchResult {
                c,
                gamma,
                accuracy: scores.accuracy,
                miou: scores.miou,
            }
        })
        .collect();
    // The first best in (C, gamma) order: ties go to the smaller, smoother model.
    let score = |r: &SearchResult| match t.criterion {
        Criterion::Accuracy => r.accuracy,
        Criterion::Miou => r.miou,
    };
    let best = search.iter().fold(
        search[0],
        |best, r| {
            if score(r) > score(&best) { *r } else { best }
        },
    );
    let mut model = fit(&fit_set, best.c, best.gamma, config);
    model.reduced_set = reduced_set(&model);
    let best_k = candidates
        .iter()
        .position(|&(c, g)| c == best.c && g == best.gamma)
        .unwrap_or(0);
    if t.tune_threshold {
        let values: Vec<(f32, bool)> = held_out
            .iter()
            .filter(|s| s.0 == best_k)
            .flat_map(|s| s.1.iter().copied())
            .collect();
        model.threshold = best_threshold(&values, t.criterion);
    }
    // The margins of the chosen (C, gamma) on cells held out of each fold, as
    // P(traversable).
    let margins: Vec<(f32, bool)> = (held_out.iter())
        .filter(|s| s.0 == best_k)
        .flat_map(|s| s.1.iter().map(|&(v, t)| (v - model.threshold, t)))
        .collect();
    model.calibration = Calibration::fit(&margins);
    progress(total, total);
    model.training.search = search;
    model.training.seconds = started.elapsed().as_secs_f64();
    Ok(model)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Training parameters for synthetic sets (of any dimension): no feature groups,
    /// so no fallback model is trained from remission columns they do not have.
    pub(super) fn paper_config() -> Config {
        let mut config = Config::default();
        config.features.groups.clear();
        config.training.left_out_features.clear();
        config
    }

    /// 600 cells on a 30 x 20 m patch, a third non-traversable, separable by the
    /// first feature; the second is noise on a large scale, so standardisation matters.
    fn separable_set() -> TrainingSet {
        let mut set = TrainingSet {
            dimension: 2,
            ..Default::default()
        };
        let mut rng = SplitMix64(9);
        for i in 0..600 {
            let traversable = i % 3 != 0;
            let x = if traversable { 0.1 } else { 0.6 } + rng.uniform(-0.15, 0.15) as f32;
            set.push(
                &[x, 1000.0 * rng.uniform(-1.0, 1.0) as f32],
                None,
                traversable,
                [(i % 30) as f64, (i / 30) as f64],
            );
        }
        set
    }

    #[test]
    fn training_learns_a_separable_feature_and_stores_the_search() {
        let set = separable_set();
        let mut config = paper_config();
        config.training.c_values = vec![1.0, 10.0];
        config.training.gamma_values = vec![0.1, 1.0];
        let model = train(&set, &config, &|_, _| {}).unwrap();
        assert_eq!(model.training.search.len(), 4);
        assert!(
            model.training.search.iter().all(|r| r.accuracy > 0.95),
            "{:?}",
            model.training.search
        );
        assert!(
            confusion(&decision_values(&model, &set), 0.0)
                .scores()
                .accuracy
                > 0.98
        );
        let mut scratch = model.scratch();
        assert!(model.decision_value(&[0.1, 0.0], &mut scratch) > 0.0);
        assert!(model.decision_value(&[0.6, 0.0], &mut scratch) < 0.0);
    }

    #[test]
    fn a_left_out_feature_has_no_part_in_the_decision() {
        let set = separable_set();
        let mut config = paper_config();
        config.training.c_values = vec![10.0];
        config.training.gamma_values = vec![1.0];
        // The synthetic cells' two columns carry the paper's first two names.
        config.training.left_out_features = vec!["planarity".into()];
        let model = train(&set, &config, &|_, _| {}).unwrap();
        assert_eq!(model.left_out_features(), ["planarity"]);
        let mut scratch = model.scratch();
        for x in [0.1, 0.35, 0.6] {
            let low = model.decision_value(&[x, -1000.0], &mut scratch);
            let high = model.decision_value(&[x, 1000.0], &mut scratch);
            assert_eq!(low, high);
        }
        // Without the separating column nothing is learnt but the majority.
        config.training.left_out_features = vec!["linearity".into()];
        let blind = train(&set, &config, &|_, _| {}).unwrap();
        let mut scratch = blind.scratch();
        let near = blind.decision_value(&[0.1, 0.0], &mut scratch);
        let far = blind.decision_value(&[0.6, 0.0], &mut scratch);
        assert_eq!(near, far);
    }

    #[test]
    fn leaving_out_a_feature_the_cells_lack_is_a_configuration_error() {
        let mut config = paper_config();
        config.training.left_out_features = vec!["wheel_count".into()];
        match train(&separable_set(), &config, &|_, _| {}) {
            Err(Error::Config(message)) => assert!(
                message.contains("training.left_out_features")
                    && message.contains("\"wheel_count\"")
                    && message.contains("linearity"),
                "{message}"
            ),
            other => panic!("expected a configuration error, got {other:?}"),
        }
    }

    #[test]
    fn a_large_set_is_fitted_on_a_seeded_subset_that_still_separates_it() {
        let set = separable_set();
        let mut config = paper_config();
        config.training.c_values = vec![10.0];
        config.training.gamma_values = vec![0.1];
        config.training.max_search_samples = 100;
        config.training.max_fit_samples = 200;
        let model = train(&set, &config, &|_, _| {}).unwrap();
        assert_eq!(model.training.samples, 200);
        // A third of the cells is non-traversable; a random subset keeps about that.
        let traversable = model.training.traversable_samples;
        assert!((115..=150).contains(&traversable), "{traversable} of 200");
        assert!(model.support_vector_count() <= 200);
        assert!(
            confusion(&decision_values(&model, &set), 0.0)
                .scores()
                .accuracy
                > 0.98
        );
        // Seeded: the same subset, so the same model.
        let again = train(&set, &config, &|_, _| {}).unwrap();
        let (mut a, mut b) = (model.scratch(), again.scratch());
        for row in set.features.chunks_exact(2).take(20) {
            assert_eq!(
                model.exact_decision_value(row, &mut a),
                again.exact_decision_value(row, &mut b)
            );
        }
        config.training.max_fit_samples = 600;
        assert_eq!(
            train(&set, &config, &|_, _| {}).unwrap().training.samples,
            600
        );
    }

    #[test]
    fn the_threshold_moves_to_where_the_held_out_classes_part() {
        // Non-traversable cells at 0.1-0.3, traversable at 0.5-0.7: at 0 every cell
        // is called traversable; between 0.3 and 0.5 all are right.
        let values: Vec<(f32, bool)> = [0.1, 0.2, 0.3]
            .map(|v| (v, false))
            .into_iter()
            .chain([0.5, 0.6, 0.7].map(|v| (v, true)))
            .collect();
        let t = best_threshold(&values, Criterion::Miou);
        assert!((t - 0.4).abs() < 1e-6, "{t}");
        assert_eq!(confusion(&values, t).scores().miou, 1.0);
        // Separated at 0 already: the threshold stays at 0.
        let centred: Vec<(f32, bool)> = values.iter().map(|&(v, y)| (v - 0.4, y)).collect();
        assert_eq!(best_threshold(&centred, Criterion::Accuracy), 0.0);
    }

    #[test]
    fn one_class_is_an_error() {
        let mut set = TrainingSet {
            dimension: 1,
            ..Default::default()
        };
        set.push(&[1.0], None, true, [0.0, 0.0]);
        set.push(&[2.0], None, true, [9.0, 0.0]);
        assert!(train(&set, &paper_config(), &|_, _| {}).is_err());
    }
}
