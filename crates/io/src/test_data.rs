//! Where the readers' tests find real files: the repository's `fixtures/` and
//! `../shared/data` beside it (tests that need the latter skip, saying so, except
//! on CI).

use std::path::{Path, PathBuf};

/// A file of the repository (`fixtures/...`, `fuzz/seeds/...`).
pub fn repository_file(relative: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(relative)
}

/// A file of tier4/nebula's decoder tests staged in `fixtures/nebula/`.
pub fn nebula_fixture(relative: &str) -> PathBuf {
    repository_file("fixtures/nebula").join(relative)
}

/// nebula's ground-truth scan `relative` (a PCD named for the stamp of the message
/// during which nebula completed it): that stamp, and its points.
pub fn nebula_ground_truth(relative: &str) -> (u64, Vec<[f32; 3]>) {
    let path = nebula_fixture(relative);
    let stamp = path.file_stem().unwrap().to_str().unwrap().parse().unwrap();
    let cloud =
        crate::cloud_files::pcd::parse_pcd(&std::fs::read(&path).unwrap(), "lidar").unwrap();
    let points = crate::payloads::cloud::cloud_points(&cloud).unwrap().points;
    (stamp, points.iter().map(|p| [p[0], p[1], p[2]]).collect())
}

/// The same points in the same order as nebula's, each within `tolerance_m`.
pub fn point_for_point(name: &str, truth: &[[f32; 3]], decoded: &[[f32; 3]], tolerance_m: f32) {
    assert_eq!(decoded.len(), truth.len(), "{name}: point count");
    let worst = truth
        .iter()
        .zip(decoded)
        .map(|(t, d)| (0..3).map(|i| (t[i] - d[i]).abs()).fold(0.0, f32::max))
        .fold(0.0, f32::max);
    println!(
        "{name}: {} points, in nebula's order, the farthest {worst:e} m from nebula's",
        truth.len()
    );
    assert!(worst <= tolerance_m, "{name}: a point {worst} m off");
}

/// `relative` under `../shared/data`, or None (with the reason printed) when the
/// data is not beside the repository.
pub fn shared_data(relative: &str) -> Option<PathBuf> {
    let path = repository_file("../shared/data").join(relative);
    if path.exists() {
        return Some(path);
    }
    let reason = format!(
        "{} not found (../shared/data is not beside the repository)",
        path.display()
    );
    assert!(
        std::env::var_os("CI").is_none(),
        "CI must run this test, but {reason}"
    );
    eprintln!("skipping: {reason}");
    None
}
