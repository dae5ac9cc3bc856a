//! The annotated drive seen in a real viewer: rerun's web viewer (rerun-sdk) in
//! headless Chromium with software WebGL, screenshot taken, and the grid's colours
//! checked on screen (`tests/clients/viewer_screenshot.py`).

use std::path::Path;
use std::process::Command;

use crate::common::{arg, run_client, write_output};
use serde_json::Value;

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn rerun_web_viewer_shows_the_annotated_grids() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let Some(python) = crate::common::env_var("TRAVMAP_CLIENT_PYTHON", "the client venv's python")
    else {
        return;
    };
    let Some(rerun) = crate::common::env_var("TRAVMAP_RERUN", "rerun from rerun-sdk") else {
        return;
    };
    let Some(chromium) = crate::common::env_var(
        "TRAVMAP_CHROMIUM",
        "a Chromium binary (apt install chromium)",
    ) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let annotated = dir.path().join("annotated.mcap");
    write_output("annotate", &seq, &annotated, &[]);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/clients/viewer_screenshot.py");
    for entity in ["/travmap/prediction", "/travmap/drive_map"] {
        let shot = dir.path().join("shot.png");
        let output = run_client(Command::new(&python).args([
            arg(&script),
            &rerun,
            arg(&annotated),
            arg(&shot),
            "--chromium",
            &chromium,
            "--grid-entity",
            entity,
        ]));
        let line = String::from_utf8_lossy(&output.stdout);
        let measured: Value = serde_json::from_str(line.trim().lines().last().unwrap()).unwrap();
        eprintln!("{entity}: {measured}");
        assert_eq!(measured["ok"], true, "{entity}: {measured}");
        // Free (white) and unknown (grey-green) cells both cover a real area.
        for colour in ["free_pixels", "unknown_pixels"] {
            assert!(
                measured[colour].as_u64().unwrap() >= 1000,
                "{entity}: {measured}"
            );
        }
        assert!(std::fs::metadata(&shot).unwrap().len() > 10_000);
    }
}
