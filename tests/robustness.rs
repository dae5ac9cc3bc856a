//! The fuzz targets on stable Rust, without libFuzzer: every file of the seed
//! corpus (`fuzz/seeds/`) and every input a fuzzer once crashed on
//! (`fuzz/regressions/`) is replayed through its target in `travmap_fuzzing`, and
//! seeded random corruptions of the seeds (bit flips, byte overwrites, truncations,
//! insertions, huge length fields) follow. Each must return, never panic or abort.
//! `TRAVMAP_FUZZ_ITERATIONS` sets the mutations per seed (default 300).

use std::path::{Path, PathBuf};

use travmap_core::random::SplitMix64;
use travmap_fuzzing::TARGETS;

fn iterations() -> usize {
    std::env::var("TRAVMAP_FUZZ_ITERATIONS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(300)
}

/// One random corruption of `input`.
fn mutate(input: &[u8], rng: &mut SplitMix64) -> Vec<u8> {
    let mut out = input.to_vec();
    let pick = |rng: &mut SplitMix64, n: usize| (rng.next_u64() % n.max(1) as u64) as usize;
    for _ in 0..1 + pick(rng, 4) {
        match pick(rng, 5) {
            0 if !out.is_empty() => {
                let at = pick(rng, out.len());
                out[at] ^= 1 << pick(rng, 8);
            }
            1 if !out.is_empty() => {
                let at = pick(rng, out.len());
                out[at] = [0x00, 0xff, 0x7f, 0x80, b'-', b'e', b' ', b'\n'][pick(rng, 8)];
            }
            2 => out.truncate(pick(rng, out.len() + 1)),
            3 => {
                let at = pick(rng, out.len() + 1);
                let bytes: Vec<u8> = (0..1 + pick(rng, 8))
                    .map(|_| rng.next_u64() as u8)
                    .collect();
                out.splice(at..at, bytes);
            }
            _ if out.len() >= 8 => {
                // A length-like field set huge: allocation must follow the bytes present.
                let at = pick(rng, out.len() - 4);
                out[at..at + 4].copy_from_slice(&0xfff0_0000u32.to_le_bytes());
            }
            _ => {}
        }
    }
    out
}

/// The files in `fuzz/<kind>/<target>/`, sorted; none when the folder is absent.
fn corpus(kind: &str, target: &str) -> Vec<(PathBuf, Vec<u8>)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz")
        .join(kind)
        .join(target);
    let mut files: Vec<PathBuf> = match std::fs::read_dir(&dir) {
        Ok(entries) => entries.map(|e| e.unwrap().path()).collect(),
        Err(_) => Vec::new(),
    };
    files.sort();
    files
        .into_iter()
        .map(|path| {
            let bytes = std::fs::read(&path).unwrap();
            (path, bytes)
        })
        .collect()
}

#[test]
fn seeds_and_past_crashes_replay_cleanly() {
    let mut regressions = 0;
    for (target, run) in TARGETS {
        let seeds = corpus("seeds", target);
        assert!(!seeds.is_empty(), "no seeds for fuzz target {target}");
        let crashes = corpus("regressions", target);
        regressions += crashes.len();
        for (path, bytes) in seeds.iter().chain(&crashes) {
            eprintln!("{target}: {}", path.display());
            run(bytes);
        }
    }
    assert!(regressions >= 3, "the regression inputs are missing");
}

#[test]
fn mutated_seeds_never_panic() {
    for (salt, (target, run)) in TARGETS.iter().enumerate() {
        for (_, seed) in corpus("seeds", target) {
            let mut rng = SplitMix64(salt as u64);
            for _ in 0..iterations() {
                run(&mutate(&seed, &mut rng));
            }
        }
    }
}
