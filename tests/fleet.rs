//! The Ray fleet script's own tests (`fleet/test_travmap_fleet.py`), run with the
//! client Python so that `cargo test` covers them: a local Ray with 2 CPUs over a
//! handful of converted MCAP files.

use std::path::Path;

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn the_ray_fleet_script_passes_its_tests() {
    if crate::common::sample().is_none() {
        return;
    }
    let Some(python) =
        crate::common::env_var("TRAVMAP_CLIENT_PYTHON", "a Python with ray and pytest")
    else {
        return;
    };
    let fleet = Path::new(env!("CARGO_MANIFEST_DIR")).join("fleet");
    let out = std::process::Command::new(python)
        .args([
            "-m",
            "pytest",
            "-q",
            "-p",
            "no:cacheprovider",
            "test_travmap_fleet.py",
        ])
        .current_dir(&fleet)
        .env("TRAVMAP_BIN", env!("CARGO_BIN_EXE_travmap"))
        .output()
        .unwrap();
    let report = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{report}");
    assert!(report.contains("5 passed"), "{report}");
}
