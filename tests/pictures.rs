//! Pictures that say what they show (issue "pictures that explain themselves"): each
//! panel titled and the scale bar labelled, read back by OCR (tesseract); the colours
//! safe for every common colour vision by default (their distances are the palette's
//! unit test), red and green on request.

use std::process::Command;

use crate::common::{arg, run_client, sample, success, travmap, write_output};
use travmap_outputs::palette::Palette;

/// How many pixels of `image` are `colour`.
fn count(image: &travmap_core::frame::RgbImage, colour: [u8; 3]) -> usize {
    image.rgb.chunks_exact(3).filter(|p| *p == colour).count()
}

#[test]
fn the_default_colours_are_blue_and_orange_and_classic_keeps_red_and_green() {
    let Some(seq) = sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (safe, classic) = (dir.path().join("safe.png"), dir.path().join("classic.png"));
    write_output("render", &seq, &safe, &["--frame", "2"]);
    write_output(
        "render",
        &seq,
        &classic,
        &["--frame", "2", "--palette", "classic"],
    );
    let (safe, classic) = (
        crate::common::read_png(&safe),
        crate::common::read_png(&classic),
    );
    for (image, palette, other) in [
        (&safe, Palette::SAFE, Palette::CLASSIC),
        (&classic, Palette::CLASSIC, Palette::SAFE),
    ] {
        assert!(count(image, palette.traversable) > 10_000);
        assert!(count(image, palette.not_traversable) > 1_000);
        assert_eq!(count(image, other.traversable), 0);
    }
    // A person reads a 12 m frame without zooming: each panel 480 pixels or more.
    assert!(safe.width >= 3 * 480);
    let help = success(travmap(&["render", "--help"]));
    assert!(
        help.contains("--palette") && help.contains("classic"),
        "{help}"
    );
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn ocr_reads_each_panels_title_and_the_scales_unit() {
    let Some(seq) = sample() else {
        return;
    };
    let Some(tesseract) =
        crate::common::env_var("TRAVMAP_TESSERACT", "tesseract (apt install tesseract-ocr)")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let frame = dir.path().join("frame.png");
    let map = dir.path().join("map.png");
    write_output("render", &seq, &frame, &["--frame", "2"]);
    write_output("map", &seq, &map, &[]);
    let read = |png: &std::path::Path| {
        let out = run_client(Command::new(&tesseract).args([arg(png), "stdout"]));
        String::from_utf8_lossy(&out.stdout).to_lowercase()
    };
    let text = read(&frame);
    let squeezed: String = text.chars().filter(|c| !c.is_whitespace()).collect();
    for title in [
        "groundtruth",
        "prediction",
        "errors",
        "traversable",
        "nottraversable",
    ] {
        assert!(squeezed.contains(title), "{title:?} not read in {text:?}");
    }
    // The scale bar's length and unit: "2 m".
    assert!(
        squeezed.contains("2m"),
        "the scale's unit not read in {text:?}"
    );
    let layers = dir.path().join("layers.png");
    write_output("render", &seq, &layers, &["--frame", "2", "--layers"]);
    let text = read(&layers);
    let squeezed: String = text.chars().filter(|c| !c.is_whitespace()).collect();
    for title in ["p(traversable)", "elevation", "elevationrange", "unsure"] {
        assert!(squeezed.contains(title), "{title:?} not read in {text:?}");
    }
    let text = read(&map);
    let squeezed: String = text.chars().filter(|c| !c.is_whitespace()).collect();
    for title in ["fusedmap", "fusedgroundtruth", "errors", "trajectory", "5m"] {
        assert!(squeezed.contains(title), "{title:?} not read in {text:?}");
    }
}
