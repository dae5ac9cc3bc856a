//! KITTI's text files: `calib.txt` (into a [`KittiCalibration`]), `poses.txt` and
//! `times.txt`. Every number is checked, every matrix that should be rigid is, and
//! errors name the file and line.

use std::path::Path;

use nalgebra::{Isometry3, Matrix3, Matrix4};

use travmap_core::error::{Error, Result};
use travmap_core::frame::{CameraImage, RgbImage};
use travmap_core::geometry::rigid;

/// KITTI calibration: the camera projections and velodyne -> cam0.
#[derive(Clone, Debug)]
pub struct KittiCalibration {
    /// `P0..P3` as 4x4 with a last row 0 0 0 1; `None` where calib.txt lacks them.
    pub projections: [Option<Matrix4<f64>>; 4],
    /// `Tr`: maps velodyne coordinates to cam0 coordinates.
    pub cam0_from_velodyne: Matrix4<f64>,
}

impl KittiCalibration {
    /// A LiDAR without a camera, whose poses are its own: `Tr` the identity.
    pub fn lidar_alone() -> Self {
        Self {
            projections: [None; 4],
            cam0_from_velodyne: Matrix4::identity(),
        }
    }

    /// The rigid velodyne -> camera_0 pose (`inv(Tr)`), as `/tf_static` carries it.
    pub fn velodyne_from_camera_0(&self) -> Isometry3<f64> {
        // Tr is checked invertible when the file is read.
        rigid(
            &self
                .cam0_from_velodyne
                .try_inverse()
                .unwrap_or_else(Matrix4::identity),
        )
    }

    /// The colour camera: its intrinsics K (P2's left 3x3) and camera_0 -> camera_2,
    /// the baseline `t` of `P2 = K [I | t]`. None without P2.
    pub fn camera_2(&self) -> Option<(Matrix3<f64>, Isometry3<f64>)> {
        let p2 = self.projections[2]?;
        let k: Matrix3<f64> = p2.fixed_view::<3, 3>(0, 0).into_owned();
        // camera_2 coordinates are camera_0's plus t.
        let t = [p2[(0, 3)] / p2[(0, 0)], p2[(1, 3)] / p2[(1, 1)], p2[(2, 3)]];
        let camera_0_from_camera_2 = Isometry3::translation(-t[0], -t[1], -t[2]);
        Some((k, camera_0_from_camera_2))
    }

    /// The colour camera as the appearance stage uses it, composed from the same
    /// rigid transforms that `convert` writes to `/tf_static`.
    pub fn camera_2_image(&self, image: RgbImage) -> Option<CameraImage> {
        let (k, camera_0_from_camera_2) = self.camera_2()?;
        let velodyne_from_camera_2 = self.velodyne_from_camera_0() * camera_0_from_camera_2;
        Some(CameraImage::from_intrinsics(
            &k,
            None,
            &velodyne_from_camera_2.inverse(),
            image,
        ))
    }
}

fn read_text(path: &Path) -> Result<String> {
    // A pipe no process writes would block the open for ever.
    let kind = std::fs::metadata(path).map(|m| m.file_type());
    if let Some(what) = kind.ok().as_ref().and_then(crate::format::special_file) {
        let problem = format!("{what}, not a file: save it to a file first");
        return Err(Error::io(path, std::io::Error::other(problem)));
    }
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    // Editors on Windows start UTF-8 files with a byte-order mark; it is no number.
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    })
}

/// A token as an error quotes it: whole when short, else its start and its length
/// (a corrupt file can hold one token of megabytes).
fn quoted(token: &str) -> String {
    const SHOWN: usize = 40;
    match token.char_indices().nth(SHOWN) {
        Some((end, _)) => format!("`{}...` ({} bytes)", &token[..end], token.len()),
        None => format!("`{token}`"),
    }
}

/// The numbered lines of a text input, blank ones at the end left out; a blank line
/// before another is an error: in poses.txt and times.txt line N+1 is frame N, so it
/// would shift every later frame.
fn lines_of<'a>(text: &'a str, path: &Path, what: &str) -> Result<Vec<(usize, &'a str)>> {
    let lines: Vec<(usize, &str)> = text.lines().enumerate().map(|(i, l)| (i + 1, l)).collect();
    let end = lines
        .iter()
        .rposition(|(_, line)| !line.trim().is_empty())
        .map_or(0, |last| last + 1);
    if let Some((line_no, _)) = lines[..end].iter().find(|(_, line)| line.trim().is_empty()) {
        return Err(Error::parse(
            path,
            *line_no,
            format!(
                "a blank line; every line holds {what} (a blank one would shift every later line's meaning)"
            ),
        ));
    }
    Ok(lines[..end].to_vec())
}

/// Parses whitespace-separated numbers of one line, naming the file and line on failure.
fn parse_numbers(path: &Path, line_no: usize, text: &str) -> Result<Vec<f64>> {
    text.split_whitespace()
        .map(|token| {
            let value: f64 = token.parse().map_err(|_| {
                Error::parse(path, line_no, format!("{} is not a number", quoted(token)))
            })?;
            if value.is_finite() {
                Ok(value)
            } else {
                Err(Error::parse(
                    path,
                    line_no,
                    format!("{} is not finite", quoted(token)),
                ))
            }
        })
        .collect()
}

/// KITTI's matrices carry about seven digits; a rotation block further than this
/// from orthonormal is not a rotation written out, but a corrupt file.
const ORTHONORMALITY_TOLERANCE: f64 = 1e-3;

/// Errors unless `m` is a rotation and a translation: its 3x3 block orthonormal, and
/// not a reflection (orthonormal with determinant -1, a mirrored frame: the cloud
/// would be mirrored, and mapped as another street).
fn check_rigid(path: &Path, line_no: usize, what: &str, m: &Matrix4<f64>) -> Result<()> {
    let error = travmap_core::geometry::orthonormality_error(m);
    let determinant = m.fixed_view::<3, 3>(0, 0).determinant();
    let problem = if error > ORTHONORMALITY_TOLERANCE {
        format!(
            "its 3x3 block R is {error:.3e} from R^T R = I (tolerance {ORTHONORMALITY_TOLERANCE:e})"
        )
    } else if determinant < 0.0 {
        format!(
            "its 3x3 block is a reflection (determinant {determinant:.3}), not a rotation: a mirrored frame"
        )
    } else {
        return Ok(());
    };
    Err(Error::parse(
        path,
        line_no,
        format!("{what} is not a rigid transform: {problem}"),
    ))
}

/// A 3x4 row-major matrix of 12 numbers as a 4x4 with last row 0 0 0 1.
fn matrix_3x4(path: &Path, line_no: usize, values: &[f64]) -> Result<Matrix4<f64>> {
    top_rows(path, line_no, values, 4)
}

/// A row-major 3 x `columns` matrix (3x4 or 3x3) as the top rows of a 4x4 identity.
fn top_rows(path: &Path, line_no: usize, values: &[f64], columns: usize) -> Result<Matrix4<f64>> {
    if values.len() != 3 * columns {
        return Err(Error::parse(
            path,
            line_no,
            format!(
                "expected {} numbers (a 3x{columns} matrix), found {}",
                3 * columns,
                values.len()
            ),
        ));
    }
    let mut m = Matrix4::identity();
    for (k, v) in values.iter().enumerate() {
        m[(k / columns, k % columns)] = *v;
    }
    Ok(m)
}

/// Reads `calib.txt`: `KEY: numbers` lines. The odometry format has `Tr` (velodyne
/// -> rectified cam0); the object format has `R0_rect` (9 numbers) and
/// `Tr_velo_to_cam`, and then `Tr = R0_rect * Tr_velo_to_cam`. `P0..P3` are optional.
pub fn read_calibration(path: &Path) -> Result<KittiCalibration> {
    parse_calibration(&read_text(path)?, path)
}

/// [`read_calibration`] on the file's text; `path` names it in errors.
pub fn parse_calibration(text: &str, path: &Path) -> Result<KittiCalibration> {
    let mut projections = [None; 4];
    // Each matrix with the line it was read from.
    let (mut tr, mut rectification, mut velo_to_cam) = (None, None, None);
    for (line_no, line) in lines_of(text, path, "`KEY: numbers`")? {
        let (key, rest) = line
            .split_once(':')
            .ok_or_else(|| Error::parse(path, line_no, "expected `KEY: numbers`"))?;
        let slot = match key.trim() {
            "P0" => &mut projections[0],
            "P1" => &mut projections[1],
            "P2" => &mut projections[2],
            "P3" => &mut projections[3],
            "Tr" => &mut tr,
            "Tr_velo_to_cam" => &mut velo_to_cam,
            "R0_rect" => {
                let values = parse_numbers(path, line_no, rest)?;
                let r = top_rows(path, line_no, &values, 3)?;
                rectification = Some((line_no, r));
                continue;
            }
            // Other keys (e.g. Tr_imu_to_velo) are not used by the method.
            _ => continue,
        };
        let values = parse_numbers(path, line_no, rest)?;
        *slot = Some((line_no, matrix_3x4(path, line_no, &values)?));
    }
    let (line_no, what, cam0_from_velodyne) = match (tr, rectification, velo_to_cam) {
        (Some((line_no, tr)), _, _) => (line_no, "Tr", tr),
        (None, Some((_, r)), Some((line_no, v))) => (line_no, "R0_rect * Tr_velo_to_cam", r * v),
        _ => {
            return Err(Error::MissingCalibration {
                path: path.to_path_buf(),
                key: "Tr",
                hint: " (or, in the object format, R0_rect and Tr_velo_to_cam)",
            });
        }
    };
    check_rigid(path, line_no, what, &cam0_from_velodyne)?;
    Ok(KittiCalibration {
        projections: projections.map(|p| p.map(|(_, m)| m)),
        cam0_from_velodyne,
    })
}

/// Reads `poses.txt`: one 3x4 row-major cam0 pose per line, line N+1 for frame N.
pub fn read_poses(path: &Path) -> Result<Vec<Matrix4<f64>>> {
    parse_poses(&read_text(path)?, path)
}

/// [`read_poses`] on the file's text; `path` names it in errors.
pub fn parse_poses(text: &str, path: &Path) -> Result<Vec<Matrix4<f64>>> {
    lines_of(text, path, "a frame's pose")?
        .into_iter()
        .map(|(line_no, line)| {
            let values = parse_numbers(path, line_no, line)?;
            let pose = matrix_3x4(path, line_no, &values)?;
            check_rigid(path, line_no, "the pose", &pose)?;
            Ok(pose)
        })
        .collect()
}

/// Reads `times.txt`: seconds since the sequence start, one per line, increasing.
pub fn read_times(path: &Path) -> Result<Vec<u64>> {
    parse_times(&read_text(path)?, path)
}

/// [`read_times`] on the file's text; `path` names it in errors.
pub fn parse_times(text: &str, path: &Path) -> Result<Vec<u64>> {
    let mut stamps_ns: Vec<u64> = Vec::new();
    for (line_no, line) in lines_of(text, path, "a frame's time")? {
        let i = line_no - 1;
        let line = line.trim();
        let seconds: f64 = line
            .parse()
            .map_err(|_| Error::parse(path, i + 1, format!("{} is not a number", quoted(line))))?;
        if !(seconds.is_finite() && seconds >= 0.0) {
            return Err(Error::parse(
                path,
                i + 1,
                format!("{}: expected finite seconds >= 0", quoted(line)),
            ));
        }
        let stamp_ns = (seconds * 1e9).round() as u64;
        if stamps_ns.last().is_some_and(|&last| stamp_ns <= last) {
            return Err(Error::parse(
                path,
                i + 1,
                "times must increase strictly from line to line",
            ));
        }
        stamps_ns.push(stamp_ns);
    }
    Ok(stamps_ns)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reflection_is_no_pose_and_no_calibration() {
        let path = Path::new("poses.txt");
        let mirrored = "-1 0 0 0 0 1 0 0 0 0 1 0";
        let err = parse_poses(&format!("1 0 0 0 0 1 0 0 0 0 1 0\n{mirrored}\n"), path)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("poses.txt:2") && err.contains("a reflection (determinant -1.000)"),
            "{err}"
        );
        let calibration = format!("P0: 1 0 0 0 0 1 0 0 0 0 1 0\nTr: {mirrored}\n");
        let err = parse_calibration(&calibration, Path::new("calib.txt"))
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with(
                "calib.txt:2: Tr is not a rigid transform: its 3x3 block is a reflection"
            ),
            "{err}"
        );
    }

    #[test]
    fn a_calibration_that_is_not_rigid_is_reported_at_its_line() {
        let path = Path::new("calib.txt");
        let projection = "P0: 1 0 0 0 0 1 0 0 0 0 1 0";
        let scaled = "Tr: 2 0 0 0 0 2 0 0 0 0 2 0";
        let err = parse_calibration(&format!("{projection}\n{scaled}\n"), path).unwrap_err();
        assert!(
            err.to_string()
                .starts_with("calib.txt:2: Tr is not a rigid"),
            "{err}"
        );
        let object = "R0_rect: 1 0 0 0 1 0 0 0 1\nTr_velo_to_cam: 2 0 0 0 0 2 0 0 0 0 2 0\n";
        let err = parse_calibration(object, path).unwrap_err().to_string();
        assert!(
            err.starts_with("calib.txt:2: R0_rect * Tr_velo_to_cam"),
            "{err}"
        );
    }

    #[test]
    fn a_huge_token_is_quoted_by_its_start_and_length() {
        let token = "x".repeat(1_000_000);
        for err in [
            parse_poses(&token, Path::new("poses.txt")).unwrap_err(),
            parse_times(&token, Path::new("times.txt")).unwrap_err(),
        ] {
            let err = err.to_string();
            assert!(err.len() < 200 && err.contains("(1000000 bytes)"), "{err}");
        }
    }

    #[test]
    fn a_byte_order_mark_is_no_part_of_the_text() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("times.txt");
        std::fs::write(&path, "\u{feff}0.0\n0.1\n").unwrap();
        assert_eq!(read_times(&path).unwrap(), [0, 100_000_000]);
    }

    #[test]
    fn a_blank_line_inside_a_text_input_is_an_error_naming_it() {
        let pose = "1 0 0 0 0 1 0 0 0 0 1 0";
        let path = Path::new("poses.txt");
        let err = parse_poses(&format!("{pose}\n\n{pose}\n"), path).unwrap_err();
        assert!(
            err.to_string().starts_with("poses.txt:2: a blank line"),
            "{err}"
        );
        // Blank lines at the end are no frame's.
        let poses = parse_poses(&format!("{pose}\n{pose}\n\n\n"), path).unwrap();
        assert_eq!(poses.len(), 2);
        let err = parse_times("0.0\n\n0.1\n", Path::new("times.txt")).unwrap_err();
        assert!(
            err.to_string().starts_with("times.txt:2: a blank line"),
            "{err}"
        );
        let calib = format!("P0: {pose}\n\nTr: {pose}\n");
        let err = parse_calibration(&calib, Path::new("calib.txt")).unwrap_err();
        assert!(
            err.to_string().starts_with("calib.txt:2: a blank line"),
            "{err}"
        );
    }
}
