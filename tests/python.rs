//! The Python package as a user installs it: the wheel (`scripts/build_wheel.sh`)
//! in a fresh virtual environment (`.ci/wheel.sh` makes both), where pytest runs
//! `python/tests/`: the module against the command (frames, grids, errors, eval,
//! dataset) and `python -m travmap.fleet` on a local Ray.

use std::path::Path;

#[test]
#[ignore = "needs the wheel installed: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn the_wheel_passes_its_tests() {
    if crate::common::sample().is_none() {
        return;
    }
    let Some(python) = crate::common::env_var(
        "TRAVMAP_WHEEL_PYTHON",
        "a virtual environment with the travmap wheel installed",
    ) else {
        return;
    };
    let tests = Path::new(env!("CARGO_MANIFEST_DIR")).join("python/tests");
    // The wheel's own command first on PATH, as `pip install` leaves it.
    let bin = Path::new(&python).parent().unwrap();
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let out = std::process::Command::new(&python)
        .args(["-m", "pytest", "-q", "-p", "no:cacheprovider", "."])
        .current_dir(&tests)
        .env("PATH", path)
        .env_remove("TRAVMAP_BIN")
        .output()
        .unwrap();
    let report = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{report}");
    assert!(report.contains("22 passed"), "{report}");
}
