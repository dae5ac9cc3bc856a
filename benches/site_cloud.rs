//! `cargo bench --bench site_cloud`: a site map from one large saved cloud, timed and
//! measured as in the README's "Large clouds" table. The shipped scan 000000 of
//! sequence 00 is repeated on a 160 m lattice (n x n copies, n the smallest that
//! reaches `TRAVMAP_SITE_POINTS`, default 10 M: 9 x 9; the README's 97.7 M is 28 x
//! 28) into a binary PCD, and the release binary maps it with `--cell-pixels 1
//! --nav2`: seconds and the child's peak RSS. Asserts nothing about time. Skips,
//! saying why, when `../shared/data` is absent.

use std::io::Write;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

/// Lattice spacing, metres: wider than a scan's reach, so the copies do not overlap.
const SPACING_M: f32 = 160.0;

fn main() {
    let scan_path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/semantickitti-00/sequences/00/velodyne/000000.bin");
    let Ok(scan) = std::fs::read(&scan_path) else {
        println!("skipped: {} is not here", scan_path.display());
        return;
    };
    let wanted: usize = std::env::var("TRAVMAP_SITE_POINTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(10_000_000);
    let scan: Vec<[f32; 4]> = scan
        .chunks_exact(16)
        .map(|p| {
            std::array::from_fn(|i| f32::from_le_bytes(p[4 * i..4 * i + 4].try_into().unwrap()))
        })
        .collect();
    let copies = (wanted as f64 / scan.len() as f64).sqrt().ceil() as usize;
    let points = copies * copies * scan.len();
    let dir = tempfile::tempdir().unwrap();
    let cloud = dir.path().join("site.pcd");
    let mut out = std::io::BufWriter::new(std::fs::File::create(&cloud).unwrap());
    write!(
        out,
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH {points}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {points}\nDATA binary\n"
    )
    .unwrap();
    for i in 0..copies {
        for j in 0..copies {
            let (dx, dy) = (SPACING_M * i as f32, SPACING_M * j as f32);
            for p in &scan {
                for v in [p[0] + dx, p[1] + dy, p[2], p[3]] {
                    out.write_all(&v.to_le_bytes()).unwrap();
                }
            }
        }
    }
    out.flush().unwrap();
    drop(out);
    let file_mb = std::fs::metadata(&cloud).unwrap().len() as f64 / 1e6;
    let start = Instant::now();
    let status = Command::new(env!("CARGO_BIN_EXE_travmap"))
        .arg("map")
        .arg(&cloud)
        .arg("-o")
        .arg(dir.path().join("site.png"))
        .args(["--cell-pixels", "1", "--nav2"])
        .arg(dir.path().join("site.yaml"))
        .arg("-q")
        .status()
        .unwrap();
    let seconds = start.elapsed().as_secs_f64();
    assert!(status.success(), "travmap map failed: {status}");
    // The largest resident set of the children waited for: the one run above.
    // SAFETY: rusage is plain data (all zeroes is a value of it) and getrusage only
    // writes into the struct it is given.
    let peak_kib = unsafe {
        let mut usage: libc::rusage = std::mem::zeroed();
        libc::getrusage(libc::RUSAGE_CHILDREN, &mut usage);
        usage.ru_maxrss
    };
    println!(
        "{:>12} {:>10} {:>9} {:>12}",
        "points", "file MB", "seconds", "peak RSS MB"
    );
    println!(
        "{points:>12} {file_mb:>10.0} {seconds:>9.1} {:>12.0}",
        peak_kib as f64 / 1024.0
    );
}
