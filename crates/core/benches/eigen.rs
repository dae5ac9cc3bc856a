//! `cargo bench --bench eigen`: the closed-form 3x3 symmetric eigen-decomposition that
//! the feature stage uses against nalgebra's general iterative solver, on the same
//! seeded covariances. Prints medians of repeated runs; asserts nothing about time.

use std::hint::black_box;
use std::time::Instant;

use travmap_core::geometry::{Moments, SymmetricMatrix3};
use travmap_core::random::SplitMix64;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let mut rng = SplitMix64(1);
    let matrices: Vec<SymmetricMatrix3> = (0..100_000)
        .map(|_| {
            let mut m = Moments::default();
            for _ in 0..12 {
                m.add([
                    rng.uniform(-1.0, 1.0),
                    rng.uniform(-1.0, 1.0),
                    0.1 * rng.uniform(-1.0, 1.0),
                ]);
            }
            m.covariance()
        })
        .collect();
    let time = |f: &dyn Fn(&SymmetricMatrix3) -> f64| {
        median(
            (0..15)
                .map(|_| {
                    let started = Instant::now();
                    let mut sum = 0.0;
                    for m in &matrices {
                        sum += f(black_box(m));
                    }
                    black_box(sum);
                    started.elapsed().as_secs_f64() * 1e9 / matrices.len() as f64
                })
                .collect(),
        )
    };
    let closed = time(&|m| m.smallest_eigen().normal[2]);
    let general = time(&|m| {
        let a = nalgebra::Matrix3::new(m.xx, m.xy, m.xz, m.xy, m.yy, m.yz, m.xz, m.yz, m.zz);
        let e = a.symmetric_eigen();
        let i = e.eigenvalues.imin();
        e.eigenvectors.column(i)[2].abs()
    });
    println!("3x3 symmetric eigen-decomposition, median ns per matrix over 15 runs of 100,000:");
    println!("  closed form (travmap): {closed:.1} ns");
    println!("  nalgebra symmetric_eigen: {general:.1} ns");
    println!("  ratio: {:.1}x", general / closed);
}
