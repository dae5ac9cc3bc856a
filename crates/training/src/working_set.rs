//! The solver's choice of a working set at each iteration: libsvm's second-order
//! selection (Fan, Chen and Lin, JMLR 2005), two passes over every sample.
//!
//! As loops with a branch per sample and a running best, these passes were three
//! quarters of training's time. Here each pass first writes every sample's value
//! (an ineligible one's can never win) in a loop without branches, which runs in
//! vector lanes; then takes the best value, and the last sample that has it,
//! which is exactly the sample the sequential loop picked, so every solution is
//! the same to the bit.

/// Values compared side by side when taking the best of many.
const LANES: usize = 4;

/// libsvm's floor on the curvature of a non-positive-definite pair.
const TAU: f64 = 1e-12;

#[inline(always)]
pub(super) fn positive_curvature(a: f64) -> f64 {
    if a > 0.0 { a } else { TAU }
}

/// The solver's state the selection reads: labels (+1 / -1), dual variables,
/// gradient and upper bounds, one per sample.
pub(super) struct Duals<'a> {
    pub y: &'a [f64],
    pub alpha: &'a [f64],
    pub gradient: &'a [f64],
    pub c: &'a [f64],
}

/// Per-sample values of the two passes, kept from one iteration to the next.
#[derive(Default)]
pub(super) struct Scratch {
    values: Vec<f64>,
    others: Vec<f64>,
}

/// The first of the pair: the sample of I_up (a positive sample below its bound, a
/// negative one above 0) with the largest `-y_t G_t`, the last of equal ones, and
/// that value; None when I_up is empty.
#[inline(always)]
pub(super) fn most_violating(d: &Duals, scratch: &mut Scratch) -> Option<(usize, f64)> {
    let values = &mut scratch.values;
    values.resize(d.y.len(), 0.0);
    for ((((value, &y), &alpha), &gradient), &c) in values
        .iter_mut()
        .zip(d.y)
        .zip(d.alpha)
        .zip(d.gradient)
        .zip(d.c)
    {
        let up = if y > 0.0 { alpha < c } else { alpha > 0.0 };
        // -y_t G_t: -G_t for a positive sample, G_t for a negative one, exactly.
        *value = if up { -y * gradient } else { f64::NEG_INFINITY };
    }
    let best = extreme(values, |a, b| a > b, f64::NEG_INFINITY);
    let i = last_equal(values, best).filter(|_| best != f64::NEG_INFINITY)?;
    Some((i, -d.y[i] * d.gradient[i]))
}

/// The second of the pair for `i` (label `y_i`, violation `g_max`, kernel row
/// `q_i`): the sample of I_low (a positive sample above 0, a negative one below its
/// bound) that decreases the objective most to second order, the last of equal
/// ones; and the largest `y_t G_t` over I_low, which ends the solver when
/// `g_max + that` falls below the tolerance.
#[inline(always)]
pub(super) fn partner(
    d: &Duals,
    y_i: f64,
    g_max: f64,
    q_i: &[f32],
    scratch: &mut Scratch,
) -> (f64, Option<usize>) {
    let Scratch { values, others } = scratch;
    values.resize(d.y.len(), 0.0);
    others.resize(d.y.len(), 0.0);
    let twice_y_i = 2.0 * y_i;
    for ((((((value, other), &y), &alpha), &gradient), &c), &q) in values
        .iter_mut()
        .zip(others.iter_mut())
        .zip(d.y)
        .zip(d.alpha)
        .zip(d.gradient)
        .zip(d.c)
        .zip(q_i)
    {
        let down = if y > 0.0 { alpha > 0.0 } else { alpha < c };
        // y_t G_t, and g_max + y_t G_t: for a negative sample g_max - G_t, exactly.
        let y_g = y * gradient;
        let grad_diff = g_max + y_g;
        // 2 - 2 y_i Q_it for a positive sample, 2 + 2 y_i Q_it for a negative one.
        let curvature = 2.0 - y * (twice_y_i * q as f64);
        let objective = -grad_diff * grad_diff / positive_curvature(curvature);
        *value = if down && grad_diff > 0.0 {
            objective
        } else {
            f64::INFINITY
        };
        *other = if down { y_g } else { f64::NEG_INFINITY };
    }
    let g_max2 = extreme(others, |a, b| a > b, f64::NEG_INFINITY);
    let best = extreme(values, |a, b| a < b, f64::INFINITY);
    let j = last_equal(values, best).filter(|_| best != f64::INFINITY);
    (g_max2, j)
}

/// The last position of `value` in `values`: blocks from the end, each compared
/// whole (in vector lanes) before it is searched.
#[inline(always)]
fn last_equal(values: &[f64], value: f64) -> Option<usize> {
    const BLOCK: usize = 2 * LANES;
    let whole = values.len() - values.len() % BLOCK;
    if let Some(t) = values[whole..].iter().rposition(|&v| v == value) {
        return Some(whole + t);
    }
    let (block, chunk) = values[..whole]
        .chunks_exact(BLOCK)
        .enumerate()
        .rev()
        .find(|(_, chunk)| chunk.iter().fold(false, |hit, &v| hit | (v == value)))?;
    chunk
        .iter()
        .rposition(|&v| v == value)
        .map(|t| block * BLOCK + t)
}

/// The value of `values` that is `beyond` every other (`none` when it is empty),
/// taken in [`LANES`] running extremes side by side: a max or min is exact in any
/// order.
#[inline(always)]
fn extreme(values: &[f64], beyond: impl Fn(f64, f64) -> bool, none: f64) -> f64 {
    let mut lanes = [none; LANES];
    let mut chunks = values.chunks_exact(LANES);
    for chunk in &mut chunks {
        for (lane, &v) in lanes.iter_mut().zip(chunk) {
            *lane = if beyond(v, *lane) { v } else { *lane };
        }
    }
    for &v in chunks.remainder() {
        lanes[0] = if beyond(v, lanes[0]) { v } else { lanes[0] };
    }
    lanes
        .into_iter()
        .fold(none, |e, v| if beyond(v, e) { v } else { e })
}

#[cfg(test)]
mod tests {
    use super::*;
    use travmap_core::random::SplitMix64;

    /// The sequential selection as the solver had it, a branch per sample.
    fn sequential(
        d: &Duals,
        q_i: impl Fn(usize) -> f64,
    ) -> Option<(usize, f64, f64, Option<usize>)> {
        let (mut g_max, mut i) = (f64::NEG_INFINITY, None);
        for t in 0..d.y.len() {
            let violation = if d.y[t] > 0.0 {
                (d.alpha[t] < d.c[t]).then_some(-d.gradient[t])
            } else {
                (d.alpha[t] > 0.0).then_some(d.gradient[t])
            };
            if let Some(v) = violation
                && v >= g_max
            {
                g_max = v;
                i = Some(t);
            }
        }
        let i = i?;
        let (mut g_max2, mut best, mut best_objective) = (f64::NEG_INFINITY, None, f64::INFINITY);
        for t in 0..d.y.len() {
            let (grad_diff, curvature) = if d.y[t] > 0.0 {
                if d.alpha[t] <= 0.0 {
                    continue;
                }
                g_max2 = g_max2.max(d.gradient[t]);
                (g_max + d.gradient[t], 2.0 - 2.0 * d.y[i] * q_i(t))
            } else {
                if d.alpha[t] >= d.c[t] {
                    continue;
                }
                g_max2 = g_max2.max(-d.gradient[t]);
                (g_max - d.gradient[t], 2.0 + 2.0 * d.y[i] * q_i(t))
            };
            if grad_diff > 0.0 {
                let objective = -grad_diff * grad_diff / positive_curvature(curvature);
                if objective <= best_objective {
                    best_objective = objective;
                    best = Some(t);
                }
            }
        }
        Some((i, g_max, g_max2, best))
    }

    #[test]
    fn lanes_pick_what_the_sequential_loop_picks() {
        let mut rng = SplitMix64(7);
        for case in 0..400 {
            let n = 1 + case % 37;
            // Few distinct values, so that ties (and signed zeros) are common.
            let pick = |rng: &mut SplitMix64, values: &[f64]| {
                values[(rng.uniform(0.0, values.len() as f64) as usize).min(values.len() - 1)]
            };
            let y: Vec<f64> = (0..n).map(|_| pick(&mut rng, &[1.0, -1.0])).collect();
            let c: Vec<f64> = (0..n).map(|_| pick(&mut rng, &[1.0, 2.5])).collect();
            let alpha: Vec<f64> = (0..n).map(|t| pick(&mut rng, &[0.0, 0.5, c[t]])).collect();
            let gradient: Vec<f64> = (0..n)
                .map(|_| pick(&mut rng, &[-1.0, -0.5, -0.0, 0.0, 0.25, 1.0]))
                .collect();
            let q: Vec<f32> = (0..n)
                .map(|_| pick(&mut rng, &[-1.0, -0.3, 0.0, 0.7, 1.0]) as f32)
                .collect();
            let d = Duals {
                y: &y,
                alpha: &alpha,
                gradient: &gradient,
                c: &c,
            };
            let expected = sequential(&d, |t| q[t] as f64);
            let mut scratch = Scratch::default();
            let got = most_violating(&d, &mut scratch).map(|(i, g_max)| {
                let (g_max2, j) = partner(&d, y[i], g_max, &q, &mut scratch);
                (i, g_max, g_max2, j)
            });
            match (expected, got) {
                (None, None) => {}
                (Some(e), Some(g)) => {
                    assert_eq!((e.0, e.3), (g.0, g.3), "case {case}");
                    assert_eq!(e.1.to_bits(), g.1.to_bits(), "case {case}");
                    assert_eq!(e.2, g.2, "case {case}");
                }
                _ => panic!("case {case}: {expected:?} against {got:?}"),
            }
        }
    }
}
