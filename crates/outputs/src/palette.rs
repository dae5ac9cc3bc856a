//! The colours of travmap's pictures. The default tells traversable (blue) from not
//! (orange), and a false call each way, apart for people with any common colour
//! vision deficiency: every pair of its colours stays at least [`MIN_DISTANCE`]
//! apart in CIELAB with normal vision and under simulated protanopia, deuteranopia
//! and tritanopia (the test below). `classic` is the red / green of earlier
//! versions, for those who want it.

use travmap_method::grid::CellClass;

/// The smallest CIELAB distance (Delta E 1976) between two colours of the default
/// palette under every simulated vision: about five times a just noticeable
/// difference, enough to tell two cells apart at a glance.
pub const MIN_DISTANCE: f64 = 20.0;

/// The colours a picture uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Palette {
    pub traversable: [u8; 3],
    pub not_traversable: [u8; 3],
    /// A cell without enough points (or without ground truth).
    pub unknown: [u8; 3],
    /// Errors panel: a right call, a cell called traversable that is not, and one
    /// called not traversable that is.
    pub right: [u8; 3],
    pub false_traversable: [u8; 3],
    pub false_not_traversable: [u8; 3],
    /// The sensor and the trajectory, drawn with an edge of `marker_edge`.
    pub marker: [u8; 3],
    pub marker_edge: [u8; 3],
}

impl Palette {
    /// Blue and orange (Okabe and Ito's), dark grey unknown; errors in dark red and
    /// sky blue on grey.
    pub const SAFE: Palette = Palette {
        traversable: [0, 114, 178],
        not_traversable: [230, 159, 0],
        unknown: [40, 40, 40],
        right: [150, 150, 150],
        false_traversable: [153, 0, 0],
        false_not_traversable: [102, 204, 238],
        marker: [255, 255, 255],
        marker_edge: [0, 0, 0],
    };

    /// Green traversable, red not; errors orange and blue.
    pub const CLASSIC: Palette = Palette {
        traversable: [60, 170, 75],
        not_traversable: [200, 60, 50],
        unknown: [40, 40, 40],
        right: [200, 200, 200],
        false_traversable: [255, 140, 0],
        false_not_traversable: [40, 120, 255],
        marker: [255, 255, 255],
        marker_edge: [0, 0, 0],
    };

    pub fn class(&self, class: CellClass) -> [u8; 3] {
        match class {
            CellClass::Unknown => self.unknown,
            CellClass::Traversable => self.traversable,
            CellClass::NonTraversable => self.not_traversable,
        }
    }

    /// The errors panel's colour of a cell called `predicted` that is `truth`.
    pub fn error(&self, predicted: CellClass, truth: CellClass) -> [u8; 3] {
        use CellClass::{NonTraversable as N, Traversable as T, Unknown as U};
        match (predicted, truth) {
            (U, _) | (_, U) => self.unknown,
            (T, N) => self.false_traversable,
            (N, T) => self.false_not_traversable,
            _ => self.right,
        }
    }

    /// The colours every picture's legend names, with their words.
    pub fn legend(&self) -> Vec<([u8; 3], &'static str)> {
        vec![
            (self.traversable, "traversable"),
            (self.not_traversable, "not traversable"),
            (self.unknown, "unknown (too few points)"),
            (self.right, "right"),
            (self.false_traversable, "called traversable, is not"),
            (self.false_not_traversable, "called not traversable, is"),
        ]
    }
}

/// A colour for continuous values (P, heights) along a dark-blue to yellow ramp (viridis' ends and middle), `t` in 0..1:
/// ordered in lightness, so that it reads in grey and to every common colour vision.
pub fn ramp(t: f32) -> [u8; 3] {
    const STOPS: [[f32; 3]; 5] = [
        [68.0, 1.0, 84.0],
        [59.0, 82.0, 139.0],
        [33.0, 145.0, 140.0],
        [94.0, 201.0, 98.0],
        [253.0, 231.0, 37.0],
    ];
    let t = t.clamp(0.0, 1.0) * (STOPS.len() - 1) as f32;
    let i = (t.floor() as usize).min(STOPS.len() - 2);
    let f = t - i as f32;
    std::array::from_fn(|k| (STOPS[i][k] + f * (STOPS[i + 1][k] - STOPS[i][k])) as u8)
}

/// The 2nd and 98th percentiles of `values` (a sorted copy): a scale that one stray
/// point does not stretch.
pub fn robust_range(mut values: Vec<f32>) -> (f32, f32) {
    if values.is_empty() {
        return (0.0, 1.0);
    }
    values.sort_unstable_by(f32::total_cmp);
    let at = |q: f64| values[((values.len() - 1) as f64 * q) as usize];
    let (low, high) = (at(0.02), at(0.98));
    (low, if high > low { high } else { low + 1.0 })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ramp_grows_lighter_from_end_to_end() {
        let lightness =
            |c: [u8; 3]| 0.299 * c[0] as f32 + 0.587 * c[1] as f32 + 0.114 * c[2] as f32;
        let steps: Vec<f32> = (0..=10).map(|i| lightness(ramp(i as f32 / 10.0))).collect();
        assert!(steps.windows(2).all(|w| w[1] > w[0]), "{steps:?}");
        assert_eq!(ramp(-1.0), ramp(0.0));
        assert_eq!(ramp(2.0), ramp(1.0));
    }

    #[test]
    fn a_stray_value_does_not_stretch_the_scale() {
        let mut values: Vec<f32> = (0..100).map(|i| i as f32 / 100.0).collect();
        values.push(1e6);
        let (low, high) = robust_range(values);
        assert!(low < 0.05 && high < 1.0, "{low} {high}");
    }

    /// Machado, Oliveira and Fernandes (2009), severity 1: linear-RGB matrices that
    /// simulate each dichromacy.
    const SIMULATIONS: [(&str, [[f64; 3]; 3]); 4] = [
        (
            "normal vision",
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        ),
        (
            "protanopia",
            [
                [0.152286, 1.052583, -0.204868],
                [0.114503, 0.786281, 0.099216],
                [-0.003882, -0.048116, 1.051998],
            ],
        ),
        (
            "deuteranopia",
            [
                [0.367322, 0.860646, -0.227968],
                [0.280085, 0.672501, 0.047413],
                [-0.011820, 0.042940, 0.968881],
            ],
        ),
        (
            "tritanopia",
            [
                [1.255528, -0.076749, -0.178779],
                [-0.078411, 0.930809, 0.147602],
                [0.004733, 0.691367, 0.303900],
            ],
        ),
    ];

    fn linear(c: u8) -> f64 {
        let c = c as f64 / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    }

    /// CIELAB (D65) of a linear RGB colour.
    fn lab([r, g, b]: [f64; 3]) -> [f64; 3] {
        let x = (0.4124 * r + 0.3576 * g + 0.1805 * b) / 0.95047;
        let y = 0.2126 * r + 0.7152 * g + 0.0722 * b;
        let z = (0.0193 * r + 0.1192 * g + 0.9505 * b) / 1.08883;
        let f = |t: f64| {
            if t > 0.008856 {
                t.cbrt()
            } else {
                7.787 * t + 16.0 / 116.0
            }
        };
        [
            116.0 * f(y) - 16.0,
            500.0 * (f(x) - f(y)),
            200.0 * (f(y) - f(z)),
        ]
    }

    fn seen(colour: [u8; 3], matrix: &[[f64; 3]; 3]) -> [f64; 3] {
        let rgb = colour.map(linear);
        lab(matrix.map(|row| (row[0] * rgb[0] + row[1] * rgb[1] + row[2] * rgb[2]).clamp(0.0, 1.0)))
    }

    /// The closest pair of `palette`'s legend colours and the marker, under every
    /// simulated vision: (distance, vision, the two names).
    fn closest(palette: &Palette) -> (f64, &'static str, &'static str, &'static str) {
        let mut colours = palette.legend();
        colours.push((palette.marker, "sensor and trajectory"));
        let mut worst = (f64::INFINITY, "", "", "");
        for (vision, matrix) in &SIMULATIONS {
            for (i, (a, a_name)) in colours.iter().enumerate() {
                for (b, b_name) in &colours[i + 1..] {
                    let (la, lb) = (seen(*a, matrix), seen(*b, matrix));
                    let distance = (0..3).map(|k| (la[k] - lb[k]).powi(2)).sum::<f64>().sqrt();
                    if distance < worst.0 {
                        worst = (distance, vision, a_name, b_name);
                    }
                }
            }
        }
        worst
    }

    #[test]
    fn every_pair_of_the_default_colours_stays_apart_for_every_common_vision() {
        let (distance, vision, a, b) = closest(&Palette::SAFE);
        assert!(
            distance >= MIN_DISTANCE,
            "{a} and {b} under {vision}: Delta E {distance:.1}"
        );
    }

    #[test]
    fn the_classic_red_and_green_do_not_and_that_is_why_it_is_not_the_default() {
        let (distance, vision, _, _) = closest(&Palette::CLASSIC);
        assert!(distance < MIN_DISTANCE, "{vision}: {distance:.1}");
    }

    #[test]
    fn the_simulation_of_a_known_colour_is_the_published_one() {
        // Pure red seen by a protanope is a dark olive (Machado's matrix, row by row).
        let red = SIMULATIONS[1].1.map(|row| row[0]);
        assert!((red[0] - 0.152286).abs() < 1e-9 && red[2] < 0.0);
        // White stays white for every vision (rows sum to 1).
        for (_, matrix) in &SIMULATIONS {
            let white = seen([255, 255, 255], matrix);
            assert!((white[0] - 100.0).abs() < 0.5, "{white:?}");
        }
    }
}
