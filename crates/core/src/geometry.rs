//! Small geometry shared by the stages: point moments and a closed-form
//! eigen-decomposition of 3x3 symmetric matrices.
//!
//! The closed form (trigonometric eigenvalues, cross-product eigenvector) replaces a
//! general iterative solver on the per-cell hot path; it is checked against
//! nalgebra's `symmetric_eigen` on seeded random matrices below.

/// The rigid part of a 4x4 pose: its rotation re-orthonormalised (KITTI poses carry
/// six digits) and its translation. Every pose travmap uses goes through this, from
/// KITTI files and from MCAP `/tf` alike, so both give bit-identical matrices.
pub fn rigid(m: &nalgebra::Matrix4<f64>) -> nalgebra::Isometry3<f64> {
    let rotation: nalgebra::Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    nalgebra::Isometry3::from_parts(
        nalgebra::Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]),
        rotation_from_matrix(&rotation),
    )
}

/// The rotation nearest `m`. nalgebra's `from_matrix` iterates until it converges,
/// which for a matrix far from any rotation is never; a real one converges in a
/// handful of steps, so a bound changes nothing for it.
fn rotation_from_matrix(m: &nalgebra::Matrix3<f64>) -> nalgebra::UnitQuaternion<f64> {
    let rotation =
        nalgebra::Rotation3::from_matrix_eps(m, f64::EPSILON, 100, nalgebra::Rotation3::identity());
    nalgebra::UnitQuaternion::from_rotation_matrix(&rotation)
}

/// How far the 3x3 block of `m` is from a rotation: the largest entry of
/// `R^T R - I`.
pub fn orthonormality_error(m: &nalgebra::Matrix4<f64>) -> f64 {
    let r: nalgebra::Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    (r.transpose() * r - nalgebra::Matrix3::identity())
        .abs()
        .max()
}

/// The least `v` whose quotient `v / divisor` (positive divisor, rounded as f64
/// division rounds) reaches `k`. The quotient never falls as `v` rises, so
/// `v >= least_reaching(k, d)` says `v / d >= k` exactly: per-point passes compare
/// against a few of these instead of dividing (a division costs several
/// multiplications).
pub fn least_reaching(k: f64, divisor: f64) -> f64 {
    // k * divisor is within an ulp or two of the answer.
    let mut v = k * divisor;
    while v / divisor >= k {
        v = v.next_down();
    }
    while v / divisor < k {
        v = v.next_up();
    }
    v
}

/// `a.min(b)` of numbers that are never NaN (a cell's points are finite): one
/// instruction per call, where `f64::min`'s NaN handling took five in the loops over
/// a cell's points. Ties keep `a`, as `min` does there.
#[inline]
pub fn lesser<T: PartialOrd>(a: T, b: T) -> T {
    if b < a { b } else { a }
}

/// `a.max(b)` of numbers that are never NaN (see [`lesser`]).
#[inline]
pub fn greater<T: PartialOrd>(a: T, b: T) -> T {
    if b > a { b } else { a }
}

/// Zeroth, first and second moments of a point set, accumulated in f64.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Moments {
    pub count: u64,
    pub sum: [f64; 3],
    /// xx, xy, xz, yy, yz, zz of the raw (uncentred) outer products.
    pub sum_outer: [f64; 6],
}

impl Moments {
    #[inline]
    pub fn add(&mut self, p: [f64; 3]) {
        self.count += 1;
        for (s, v) in self.sum.iter_mut().zip(p) {
            *s += v;
        }
        let o = &mut self.sum_outer;
        o[0] += p[0] * p[0];
        o[1] += p[0] * p[1];
        o[2] += p[0] * p[2];
        o[3] += p[1] * p[1];
        o[4] += p[1] * p[2];
        o[5] += p[2] * p[2];
    }

    pub fn merge(&mut self, other: &Moments) {
        self.count += other.count;
        for (a, b) in self.sum.iter_mut().zip(other.sum) {
            *a += b;
        }
        for (a, b) in self.sum_outer.iter_mut().zip(other.sum_outer) {
            *a += b;
        }
    }

    pub fn mean(&self) -> [f64; 3] {
        let k = self.count.max(1) as f64;
        self.sum.map(|s| s / k)
    }

    /// Population covariance (divided by k) as a symmetric 3x3; zero for k = 0.
    pub fn covariance(&self) -> SymmetricMatrix3 {
        if self.count == 0 {
            return SymmetricMatrix3::default();
        }
        let k = self.count as f64;
        let m = self.mean();
        let o = &self.sum_outer;
        SymmetricMatrix3 {
            xx: o[0] / k - m[0] * m[0],
            xy: o[1] / k - m[0] * m[1],
            xz: o[2] / k - m[0] * m[2],
            yy: o[3] / k - m[1] * m[1],
            yz: o[4] / k - m[1] * m[2],
            zz: o[5] / k - m[2] * m[2],
        }
    }
}

/// A symmetric 3x3 matrix by its six distinct entries.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SymmetricMatrix3 {
    pub xx: f64,
    pub xy: f64,
    pub xz: f64,
    pub yy: f64,
    pub yz: f64,
    pub zz: f64,
}

/// Eigenvalues in decreasing order and the unit eigenvector of the smallest.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SmallestEigen {
    pub values: [f64; 3],
    /// Unit eigenvector of `values[2]`, oriented so that its z is >= 0.
    pub normal: [f64; 3],
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn norm_squared(a: [f64; 3]) -> f64 {
    a[0] * a[0] + a[1] * a[1] + a[2] * a[2]
}

impl SymmetricMatrix3 {
    /// Eigenvalues (decreasing) by the trigonometric closed form, and the normal
    /// (eigenvector of the smallest eigenvalue, z >= 0). The normal of a rank-deficient
    /// spectrum (a line, an isotropic blob) is any valid eigenvector; of the zero
    /// matrix, +z.
    pub fn smallest_eigen(&self) -> SmallestEigen {
        let a = self;
        let p1 = a.xy * a.xy + a.xz * a.xz + a.yz * a.yz;
        let q = (a.xx + a.yy + a.zz) / 3.0;
        let values = if p1 <= f64::EPSILON * f64::EPSILON * (q * q).max(f64::MIN_POSITIVE) {
            let mut d = [a.xx, a.yy, a.zz];
            d.sort_by(|x, y| y.total_cmp(x));
            d
        } else {
            let (dx, dy, dz) = (a.xx - q, a.yy - q, a.zz - q);
            let p2 = dx * dx + dy * dy + dz * dz + 2.0 * p1;
            let p = (p2 / 6.0).sqrt();
            // det((A - qI) / p) / 2, the cosine of three times the angle.
            let det = dx * (dy * dz - a.yz * a.yz) - a.xy * (a.xy * dz - a.yz * a.xz)
                + a.xz * (a.xy * a.yz - dy * a.xz);
            let r = (det / (2.0 * p * p * p)).clamp(-1.0, 1.0);
            let phi = r.acos() / 3.0;
            let largest = q + 2.0 * p * phi.cos();
            let smallest = q + 2.0 * p * (phi + 2.0 * std::f64::consts::FRAC_PI_3).cos();
            [largest, 3.0 * q - largest - smallest, smallest]
        };
        let normal = self.eigenvector(values[2]);
        SmallestEigen { values, normal }
    }

    /// Unit vector in the null space of `A - lambda I`, oriented z >= 0.
    fn eigenvector(&self, lambda: f64) -> [f64; 3] {
        let rows = [
            [self.xx - lambda, self.xy, self.xz],
            [self.xy, self.yy - lambda, self.yz],
            [self.xz, self.yz, self.zz - lambda],
        ];
        let candidates = [
            cross(rows[0], rows[1]),
            cross(rows[0], rows[2]),
            cross(rows[1], rows[2]),
        ];
        let (best, best_norm2) = candidates
            .iter()
            .map(|c| (*c, norm_squared(*c)))
            .fold(([0.0; 3], 0.0), |acc, c| if c.1 > acc.1 { c } else { acc });
        let (row, row_norm2) = rows
            .iter()
            .map(|r| (*r, norm_squared(*r)))
            .fold(([0.0; 3], 0.0), |acc, r| if r.1 > acc.1 { r } else { acc });
        let v = if best_norm2 > 1e-20 * row_norm2 * row_norm2 && best_norm2 > 0.0 {
            best
        } else if row_norm2 > 0.0 {
            // Rank one: the null space is the plane orthogonal to `row`; pick the
            // vector of it that is closest to the axis `row` is least aligned with.
            let axis = (0..3)
                .min_by(|&i, &j| row[i].abs().total_cmp(&row[j].abs()))
                .unwrap_or(2);
            let mut e = [0.0; 3];
            e[axis] = 1.0;
            cross(row, cross(e, row))
        } else {
            [0.0, 0.0, 1.0]
        };
        let n = norm_squared(v).sqrt();
        let sign = if v[2] < 0.0 { -1.0 } else { 1.0 };
        v.map(|c| sign * c / n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn least_reaching_is_where_the_division_reaches_k() {
        for divisor in [0.2, 0.4, 0.1, 1.0 / 3.0, 7.3] {
            for k in 0..40 {
                let k = k as f64;
                let edge = least_reaching(k, divisor);
                assert!(edge / divisor >= k, "{edge} / {divisor} < {k}");
                assert!(edge.next_down() / divisor < k, "{divisor} {k}");
            }
        }
    }

    #[test]
    fn matrices_far_from_a_rotation_still_give_a_rotation() {
        // nalgebra's unbounded iteration can run forever on such inputs (the
        // kitti_calib fuzz target found one).
        for rows in [
            [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 10.0],
            [1e300, 0.0, 0.0, 0.0, 1e-300, 0.0, 0.0, 0.0, -1.0],
            [0.0; 9],
        ] {
            let m = nalgebra::Matrix3::from_row_slice(&rows).to_homogeneous();
            let pose = rigid(&m);
            assert!((pose.rotation.norm() - 1.0).abs() < 1e-9, "{rows:?}");
        }
    }
    use crate::random::SplitMix64;

    fn to_nalgebra(a: &SymmetricMatrix3) -> nalgebra::Matrix3<f64> {
        nalgebra::Matrix3::new(a.xx, a.xy, a.xz, a.xy, a.yy, a.yz, a.xz, a.yz, a.zz)
    }

    #[test]
    fn closed_form_matches_nalgebra_on_random_covariances() {
        let mut rng = SplitMix64(7);
        for _ in 0..2000 {
            let mut m = Moments::default();
            let scale = [
                rng.uniform(0.01, 3.0),
                rng.uniform(0.01, 3.0),
                rng.uniform(0.0, 3.0),
            ];
            for _ in 0..20 {
                m.add([
                    scale[0] * rng.uniform(-1.0, 1.0),
                    scale[1] * rng.uniform(-1.0, 1.0) + 0.3 * rng.uniform(-1.0, 1.0),
                    scale[2] * rng.uniform(-1.0, 1.0),
                ]);
            }
            let cov = m.covariance();
            let ours = cov.smallest_eigen();
            let reference = to_nalgebra(&cov).symmetric_eigen();
            let mut expected: Vec<f64> = reference.eigenvalues.iter().copied().collect();
            expected.sort_by(|a, b| b.total_cmp(a));
            for (a, b) in ours.values.iter().zip(&expected) {
                assert!(
                    (a - b).abs() < 1e-9 * (1.0 + expected[0]),
                    "{ours:?} vs {expected:?}"
                );
            }
            // The eigenvector must satisfy A v = l3 v.
            let v = nalgebra::Vector3::from(ours.normal);
            let residual = to_nalgebra(&cov) * v - v * ours.values[2];
            assert!(
                residual.norm() < 1e-7 * (1.0 + expected[0]),
                "residual {residual}"
            );
            assert!((v.norm() - 1.0).abs() < 1e-12 && v.z >= 0.0);
        }
    }

    #[test]
    fn degenerate_spectra_give_defined_normals() {
        // A line along x: l2 = l3 = 0, any normal orthogonal to x is valid.
        let line = SymmetricMatrix3 {
            xx: 2.0,
            ..Default::default()
        };
        let e = line.smallest_eigen();
        assert_eq!(e.values, [2.0, 0.0, 0.0]);
        assert!(e.normal[0].abs() < 1e-12 && (norm_squared(e.normal) - 1.0).abs() < 1e-12);
        // Isotropic and zero matrices.
        let iso = SymmetricMatrix3 {
            xx: 1.0,
            yy: 1.0,
            zz: 1.0,
            ..Default::default()
        };
        assert_eq!(iso.smallest_eigen().values, [1.0, 1.0, 1.0]);
        assert_eq!(
            SymmetricMatrix3::default().smallest_eigen().normal,
            [0.0, 0.0, 1.0]
        );
        // A plane z = 0: normal +z.
        let plane = SymmetricMatrix3 {
            xx: 1.0,
            xy: 0.3,
            yy: 2.0,
            ..Default::default()
        };
        let n = plane.smallest_eigen().normal;
        assert!((n[2] - 1.0).abs() < 1e-12, "{n:?}");
    }
}
