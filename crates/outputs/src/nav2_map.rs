//! The fused map of a drive as a nav2 `map_server` map: a YAML file and the image it
//! names, which `nav2_map_server` (and ROS 1's `map_server`) loads as a static map.
//!
//! map_server (navigation2's `map_io.cpp`) reads the image's top row as the map's
//! highest row (image rows run down, map rows up), and `origin` is the world pose of
//! the lower-left pixel's lower-left corner. It turns a pixel's grey level g into
//! `p = (255 - g) / 255` (float32) and compares it with the thresholds: occupied
//! if `p >= occupied_thresh`, free if `p <= free_thresh` (ROS 1 compared strictly;
//! no level written here sits on a threshold, so both read the same). Two modes:
//! - `trinary` (as `map_saver` writes): free 254, occupied 0, unknown 205 in a binary
//!   PGM, with map_saver's thresholds 0.65 and 0.196: 205 is `p` 0.19608, just above
//!   0.196, so it loads back as unknown (a free_thresh of 0.25, map_saver's default
//!   for other modes, would load it as free).
//! - `scale`: the grey level is P(traversable), so `p` is P(not traversable) and
//!   map_server spreads it over 0..100 between the thresholds. Scale mode reads
//!   unknown only from transparency, which PGM cannot hold: the image is a
//!   grey-alpha PNG, unseen cells transparent.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::atomic::Staged;
use crate::drive_map::check_image_size;
use travmap_core::error::{Error, Result};
use travmap_io::Georeference;
use travmap_method::fusion::{FusedCell, Lattice};
use travmap_method::grid::CellClass;

/// How cells become grey levels (`mode` in the YAML).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Nav2Mode {
    Trinary,
    Scale,
}

/// Grey levels of `map_saver`'s trinary images.
pub const FREE: u8 = 254;
pub const OCCUPIED: u8 = 0;
pub const UNKNOWN: u8 = 205;
/// Thresholds written to the YAML: `occ` above this loads as occupied.
pub const OCCUPIED_THRESH: f64 = 0.65;
/// `p` at or below this loads as free (see the module comment for why not 0.25).
pub const FREE_THRESH: f64 = 0.196;

/// Where the map lies: the image's size and the world position of its lower-left
/// corner.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Nav2Map {
    #[serde(serialize_with = "lossy_path")]
    pub yaml: PathBuf,
    #[serde(serialize_with = "lossy_path")]
    pub image: PathBuf,
    pub mode: Nav2Mode,
    pub width: usize,
    pub height: usize,
    pub resolution_m: f64,
    /// x, y (metres) and yaw (radians) of the lower-left pixel in `frame`.
    pub origin: [f64; 3],
    pub frame: String,
    /// The source's georeference, written beside the map as a world file (and a
    /// `.prj` with the CRS) so GIS tools place it; None: the drive's own frame.
    pub georeference: Option<Georeference>,
    /// The world file and `.prj` written, when georeferenced.
    #[serde(serialize_with = "lossy_paths")]
    pub gis_files: Vec<PathBuf>,
}

/// A path as text, bytes that are not UTF-8 as U+FFFD: serde refuses such a path,
/// and a summary must not fail on the name of what it wrote.
fn lossy_path<S: serde::Serializer>(path: &Path, serializer: S) -> Result<S::Ok, S::Error> {
    serializer.serialize_str(&path.to_string_lossy())
}

fn lossy_paths<S: serde::Serializer>(paths: &[PathBuf], serializer: S) -> Result<S::Ok, S::Error> {
    serializer.collect_seq(paths.iter().map(|path| path.to_string_lossy()))
}

/// The image of a map: cells seen by some frame, from the lowest key to the highest.
struct Raster {
    low_key: [i64; 2],
    size: [usize; 2],
}

impl Raster {
    fn of(cells: &[FusedCell]) -> Self {
        let mut low = [0i64; 2];
        let mut high = [-1i64; 2];
        for (i, cell) in cells.iter().filter(|c| c.observations > 0).enumerate() {
            for axis in 0..2 {
                if i == 0 {
                    (low[axis], high[axis]) = (cell.key[axis], cell.key[axis]);
                }
                low[axis] = low[axis].min(cell.key[axis]);
                high[axis] = high[axis].max(cell.key[axis]);
            }
        }
        // Saturating: a key range no image holds is refused by its size, not wrapped.
        let side = |axis: usize| high[axis].saturating_sub(low[axis]).saturating_add(1) as usize;
        let size = [side(0), side(1)];
        Self { low_key: low, size }
    }

    /// The pixel index (row-major, top row first) of world cell `key`.
    fn pixel(&self, key: [i64; 2]) -> usize {
        let col = (key[0] - self.low_key[0]) as usize;
        let row_from_bottom = (key[1] - self.low_key[1]) as usize;
        (self.size[1] - 1 - row_from_bottom) * self.size[0] + col
    }
}

/// The grey level of a seen cell.
fn grey(cell: &FusedCell, mode: Nav2Mode) -> u8 {
    match mode {
        Nav2Mode::Trinary => match cell.class {
            CellClass::Traversable => FREE,
            CellClass::NonTraversable => OCCUPIED,
            CellClass::Unknown => UNKNOWN,
        },
        Nav2Mode::Scale => (255.0 * cell.probability).round().clamp(0.0, 255.0) as u8,
    }
}

/// The image beside `yaml`: `site.yaml` -> `site.pgm` (trinary) or `site.png` (scale).
pub fn image_path(yaml: &Path, mode: Nav2Mode) -> PathBuf {
    yaml.with_extension(match mode {
        Nav2Mode::Trinary => "pgm",
        Nav2Mode::Scale => "png",
    })
}

/// The world file GIS tools read beside `image` (GDAL: `<image>.<ext>w`).
pub fn gis_world_file(image: &Path) -> PathBuf {
    let mut name = image.as_os_str().to_os_string();
    name.push("w");
    PathBuf::from(name)
}

/// Writes the map of the seen `cells` (on `lattice`, in `frame`) as `yaml` and its
/// image (and, for a georeferenced source, a world file and `.prj` beside the
/// image), staged to appear with the command's other outputs.
pub fn write_nav2_map(
    staged: &mut Staged,
    yaml: &Path,
    cells: &[FusedCell],
    lattice: &Lattice,
    frame: &str,
    mode: Nav2Mode,
    georeference: Option<&Georeference>,
) -> Result<Nav2Map> {
    let seen: Vec<&FusedCell> = cells.iter().filter(|c| c.observations > 0).collect();
    if seen.is_empty() {
        return Err(Error::Write {
            path: yaml.to_path_buf(),
            source: std::io::Error::other("no frame saw any cell: the map would be empty"),
        });
    }
    let resolution_m = lattice.cell_size_m;
    let raster = Raster::of(cells);
    check_image_size(
        "the nav2 map",
        raster.size.map(|n| n as u64),
        ("cell", resolution_m),
        "--frames chooses a stretch",
    )?;
    let image = image_path(yaml, mode);
    let pixels = raster.size[0] * raster.size[1];
    let bytes = match mode {
        Nav2Mode::Trinary => {
            let mut grey_levels = vec![UNKNOWN; pixels];
            for cell in &seen {
                grey_levels[raster.pixel(cell.key)] = grey(cell, mode);
            }
            let mut pgm = format!("P5\n{} {}\n255\n", raster.size[0], raster.size[1]).into_bytes();
            pgm.extend_from_slice(&grey_levels);
            pgm
        }
        Nav2Mode::Scale => {
            let mut grey_alpha = vec![0u8; 2 * pixels];
            for cell in &seen {
                let at = 2 * raster.pixel(cell.key);
                grey_alpha[at] = grey(cell, mode);
                grey_alpha[at + 1] = 255;
            }
            grey_alpha_png(raster.size[0] as u32, raster.size[1] as u32, &grey_alpha)
        }
    };
    let [x, y] = lattice.corner_in_world(raster.low_key);
    let origin = [x, y, 0.0];
    let mut map = Nav2Map {
        yaml: yaml.to_path_buf(),
        image,
        mode,
        width: raster.size[0],
        height: raster.size[1],
        resolution_m,
        origin,
        frame: frame.to_string(),
        georeference: georeference.cloned(),
        gis_files: Vec::new(),
    };
    staged.write(&map.image, &bytes)?;
    staged.write(yaml, map.yaml_text().as_bytes())?;
    if let Some(georeference) = georeference.filter(|g| g.is_planar()) {
        // The world file: the pixel's size and turn, and the centre of the upper-left
        // pixel, in the source's coordinates (x' = A col + B row + C, y' = D col + E
        // row + F; written A, D, B, E, C, F).
        let world_file = gis_world_file(&map.image);
        let (sin, cos) = georeference.yaw_rad().sin_cos();
        let upper_left = [
            origin[0] + 0.5 * resolution_m,
            origin[1] + (map.height as f64 - 0.5) * resolution_m,
        ];
        let [x0, y0, _] = georeference.origin_m;
        let c = x0 + cos * upper_left[0] - sin * upper_left[1];
        let f = y0 + sin * upper_left[0] + cos * upper_left[1];
        let (a, d, b, e) = (
            resolution_m * cos,
            resolution_m * sin,
            resolution_m * sin,
            -resolution_m * cos,
        );
        let text = format!("{a}\n{d}\n{b}\n{e}\n{c}\n{f}\n");
        staged.write(&world_file, text.as_bytes())?;
        map.gis_files.push(world_file);
        if let Some(wkt) = &georeference.crs_wkt {
            let prj = map.image.with_extension("prj");
            staged.write(&prj, wkt.as_bytes())?;
            map.gis_files.push(prj);
        }
    }
    Ok(map)
}

impl Nav2Map {
    /// The YAML map_server reads; `image` relative to the YAML's folder.
    fn yaml_text(&self) -> String {
        let image_name = self
            .image
            .file_name()
            .map(|name| name.to_string_lossy().into_owned())
            .unwrap_or_default();
        let mode = match self.mode {
            Nav2Mode::Trinary => "trinary",
            Nav2Mode::Scale => "scale",
        };
        let mut text = String::new();
        // Writing into a String cannot fail.
        let _ = writeln!(
            text,
            "# travmap {}: the fused traversability map of a drive, in frame `{}` (the drive's own world frame: \
             line it up with your localisation's map frame). Traversable cells are free, the rest occupied.",
            env!("CARGO_PKG_VERSION"),
            self.frame
        );
        if let Some(georeference) = &self.georeference {
            let [x, y, z] = georeference.origin_m;
            match &georeference.frame {
                None => {
                    let _ = writeln!(
                        text,
                        "# The frame is the source file's coordinates minus ({x}, {y}, {z}): add them to `origin` to place the map there{}.",
                        if georeference.crs_wkt.is_some() {
                            " (CRS in the .prj beside the image)"
                        } else {
                            ""
                        }
                    );
                }
                Some(geo) => {
                    let [qx, qy, qz, qw] = georeference.rotation_xyzw;
                    let _ = writeln!(
                        text,
                        "# `{}` lies in the log's `{geo}` frame at ({x}, {y}, {z}), turned by the quaternion (x, y, z, w) ({qx}, {qy}, {qz}, {qw}), from its transforms at the first scan{}.",
                        self.frame,
                        if georeference.is_planar() {
                            "; the world file beside the image places each pixel in it (the log names no zone, so no .prj)"
                        } else {
                            ""
                        }
                    );
                }
            }
        }
        let _ = writeln!(text, "image: {}", yaml_string(&image_name));
        let _ = writeln!(text, "mode: {mode}");
        let _ = writeln!(text, "resolution: {}", self.resolution_m);
        let _ = writeln!(
            text,
            "origin: [{}, {}, {}]",
            self.origin[0], self.origin[1], self.origin[2]
        );
        let _ = writeln!(text, "negate: 0");
        let _ = writeln!(text, "occupied_thresh: {OCCUPIED_THRESH}");
        let _ = writeln!(text, "free_thresh: {FREE_THRESH}");
        text
    }
}

/// A YAML scalar that reads back as `text` (quoted when plain would not).
fn yaml_string(text: &str) -> String {
    let plain = !text.is_empty()
        && text
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "._-/".contains(c));
    if plain {
        text.to_string()
    } else {
        format!("'{}'", text.replace('\'', "''"))
    }
}

fn grey_alpha_png(width: u32, height: u32, grey_alpha: &[u8]) -> Vec<u8> {
    let mut bytes = Vec::new();
    let mut encoder = png::Encoder::new(&mut bytes, width, height);
    encoder.set_color(png::ColorType::GrayscaleAlpha);
    encoder.set_depth(png::BitDepth::Eight);
    // Writing a well-formed image into memory cannot fail.
    let mut writer = encoder.write_header().expect("PNG header in memory");
    writer
        .write_image_data(grey_alpha)
        .expect("PNG data in memory");
    writer.finish().expect("PNG end in memory");
    bytes
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cell(key: [i64; 2], class: CellClass, probability: f64) -> FusedCell {
        FusedCell {
            key,
            x_m: 0.0,
            y_m: 0.0,
            evidence: 0.0,
            probability,
            observations: 1,
            class,
            ground_truth: CellClass::Unknown,
        }
    }

    #[test]
    fn the_top_row_is_the_highest_cell_row_and_the_origin_its_lower_left_corner() {
        let cells = [
            cell([-2, 5], CellClass::Traversable, 0.9),
            cell([1, 3], CellClass::NonTraversable, 0.1),
        ];
        let raster = Raster::of(&cells);
        assert_eq!(raster.low_key, [-2, 3]);
        assert_eq!(raster.size, [4, 3]);
        // [-2, 5] is the top-left pixel, [1, 3] the bottom-right.
        assert_eq!(raster.pixel([-2, 5]), 0);
        assert_eq!(raster.pixel([1, 3]), 2 * 4 + 3);
        assert_eq!(grey(&cells[0], Nav2Mode::Trinary), FREE);
        assert_eq!(grey(&cells[1], Nav2Mode::Trinary), OCCUPIED);
        assert_eq!(grey(&cells[0], Nav2Mode::Scale), 230);
    }

    #[test]
    fn trinary_levels_load_back_as_free_occupied_and_unknown() {
        // map_server's rule, in float32: p = 1 - g / 255; free if p <= free_thresh,
        // else occupied if p >= occupied_thresh, else unknown.
        let load = |g: u8| {
            let p = 1.0f32 - g as f32 / 255.0;
            if p <= FREE_THRESH as f32 {
                0
            } else if p >= OCCUPIED_THRESH as f32 {
                100
            } else {
                -1
            }
        };
        assert_eq!(load(FREE), 0);
        assert_eq!(load(OCCUPIED), 100);
        assert_eq!(load(UNKNOWN), -1);
    }

    #[test]
    fn names_that_yaml_would_misread_are_quoted() {
        assert_eq!(yaml_string("site.pgm"), "site.pgm");
        assert_eq!(yaml_string("my map: 1.pgm"), "'my map: 1.pgm'");
        assert_eq!(yaml_string("it's.pgm"), "'it''s.pgm'");
    }
}
