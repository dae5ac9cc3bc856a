//! A margin as a probability: P(traversable) = 1 / (1 + exp(a * margin + b)), Platt's
//! sigmoid, fitted when the model is trained to the margins its cross-validation
//! gave cells held out of each fold (`crates/training`). A planner that weighs costs
//! reads a probability, not a vote.

use serde::{Deserialize, Serialize};

/// Platt's sigmoid of a model's margin (`a` < 0: a larger margin, more likely
/// traversable).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    pub a: f64,
    pub b: f64,
    /// Held-out cells it was fitted on.
    pub cells: usize,
}

/// The sigmoid of a model without a calibration (one adapted, or taught from a few
/// answers, with no held-out margins of its own): a margin of 1 is 0.88, the
/// classifier's own notion of sure.
pub const UNCALIBRATED: Calibration = Calibration {
    a: -2.0,
    b: 0.0,
    cells: 0,
};

impl Calibration {
    /// P(traversable) of a margin; NaN for a NaN margin (an unpredictable cell).
    pub fn probability(&self, margin: f32) -> f32 {
        if margin.is_nan() {
            return f32::NAN;
        }
        let z = self.a * margin as f64 + self.b;
        // exp of a large z overflows to inf, and 1 / inf is 0: the right limit.
        (1.0 / (1.0 + z.exp())) as f32
    }

    /// Whether it can be a calibration: finite, and rising with the margin.
    pub fn is_plausible(&self) -> bool {
        self.a.is_finite() && self.b.is_finite() && self.a < 0.0
    }

    /// Platt's sigmoid fitted to (margin, traversable) pairs by Newton's method with
    /// a line search and Platt's smoothed targets (Lin, Lin and Weng, 2007); None
    /// without both classes.
    pub fn fit(values: &[(f32, bool)]) -> Option<Calibration> {
        let positives = values.iter().filter(|v| v.1).count() as f64;
        let negatives = values.len() as f64 - positives;
        if positives == 0.0 || negatives == 0.0 {
            return None;
        }
        let (high, low) = (
            (positives + 1.0) / (positives + 2.0),
            1.0 / (negatives + 2.0),
        );
        // Targets for P(traversable) = 1 / (1 + exp(a f + b)).
        let data: Vec<(f64, f64)> = (values.iter())
            .map(|&(f, t)| (f as f64, if t { high } else { low }))
            .collect();
        let loss = |a: f64, b: f64| -> f64 {
            data.iter()
                .map(|&(f, t)| {
                    let z = a * f + b;
                    // -log-likelihood of target t under p = 1 / (1 + exp(z)), stably.
                    if z >= 0.0 {
                        t * z + (1.0 + (-z).exp()).ln()
                    } else {
                        (t - 1.0) * z + (1.0 + z.exp()).ln()
                    }
                })
                .sum()
        };
        let (mut a, mut b) = (0.0, ((negatives + 1.0) / (positives + 1.0)).ln());
        let mut current = loss(a, b);
        for _ in 0..100 {
            // Gradient and Hessian (with a small ridge) of the loss in (a, b).
            let (mut h11, mut h22, mut h21, mut g1, mut g2) = (1e-12, 1e-12, 0.0, 0.0, 0.0);
            for &(f, t) in &data {
                let z = a * f + b;
                let (p, q) = if z >= 0.0 {
                    let e = (-z).exp();
                    (e / (1.0 + e), 1.0 / (1.0 + e))
                } else {
                    let e = z.exp();
                    (1.0 / (1.0 + e), e / (1.0 + e))
                };
                let d2 = p * q;
                h11 += f * f * d2;
                h22 += d2;
                h21 += f * d2;
                let d1 = t - p;
                g1 += f * d1;
                g2 += d1;
            }
            if g1.abs() < 1e-6 && g2.abs() < 1e-6 {
                break;
            }
            let det = h11 * h22 - h21 * h21;
            let (da, db) = (-(h22 * g1 - h21 * g2) / det, -(-h21 * g1 + h11 * g2) / det);
            let gd = g1 * da + g2 * db;
            let mut step = 1.0;
            while step >= 1e-10 {
                let (na, nb) = (a + step * da, b + step * db);
                let next = loss(na, nb);
                if next < current + 1e-4 * step * gd {
                    (a, b, current) = (na, nb, next);
                    break;
                }
                step /= 2.0;
            }
            if step < 1e-10 {
                break;
            }
        }
        let calibration = Calibration {
            a,
            b,
            cells: values.len(),
        };
        calibration.is_plausible().then_some(calibration)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use travmap_core::random::SplitMix64;

    #[test]
    fn a_known_sigmoid_is_recovered_from_its_samples() {
        // Margins spread over [-3, 3], labels drawn with P = 1 / (1 + exp(-2 f + 0.5)).
        let mut random = SplitMix64(3);
        let values: Vec<(f32, bool)> = (0..20_000)
            .map(|_| {
                let f = (random.next_u64() % 6000) as f64 / 1000.0 - 3.0;
                let p = 1.0 / (1.0 + (-2.0 * f + 0.5).exp());
                let u = (random.next_u64() % 1_000_000) as f64 / 1e6;
                (f as f32, u < p)
            })
            .collect();
        let fitted = Calibration::fit(&values).unwrap();
        assert!(
            (fitted.a + 2.0).abs() < 0.1 && (fitted.b - 0.5).abs() < 0.1,
            "{fitted:?}"
        );
        assert!((fitted.probability(0.25) - 0.5).abs() < 0.03);
    }

    #[test]
    fn one_class_or_a_nan_margin_gives_no_probability() {
        assert_eq!(Calibration::fit(&[(1.0, true), (2.0, true)]), None);
        assert!(UNCALIBRATED.probability(f32::NAN).is_nan());
        assert!((UNCALIBRATED.probability(1.0) - 0.881).abs() < 1e-3);
        assert_eq!(UNCALIBRATED.probability(1e30), 1.0);
        assert_eq!(UNCALIBRATED.probability(-1e30), 0.0);
    }
}
