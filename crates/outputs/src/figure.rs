//! Pictures that say what they show: panels side by side under their titles, a scale
//! bar labelled in metres, and a legend of every colour used, on white. The words are
//! drawn in DejaVu Sans, compiled in (`fonts/`, with its licence), so a picture reads
//! the same on every machine and needs no font installed.

use ab_glyph::{Font, FontRef, PxScale, ScaleFont, point};
use travmap_core::frame::RgbImage;

use crate::palette::Palette;

const FONT_BYTES: &[u8] = include_bytes!("fonts/DejaVuSans.ttf");

/// Pixel sizes of the words and the spacing around them.
const TITLE_PX: f32 = 20.0;
const LABEL_PX: f32 = 15.0;
const MARGIN_PX: u32 = 12;
const GAP_PX: u32 = 16;
const SWATCH_PX: u32 = 16;

const WHITE: [u8; 3] = [255, 255, 255];
const INK: [u8; 3] = [0, 0, 0];

/// A panel: its title and its picture.
pub struct Panel {
    pub title: String,
    pub image: RgbImage,
}

/// What a legend entry shows beside its words.
#[derive(Clone, Copy, Debug)]
pub enum Swatch {
    /// A square of a colour.
    Fill([u8; 3]),
    /// The sensor's marker: a triangle pointing where the sensor faces.
    Sensor,
    /// A line of the marker's colour: the trajectory.
    Line,
}

/// An image of `width` x `height` pixels of `colour`.
pub fn blank(width: u32, height: u32, colour: [u8; 3]) -> RgbImage {
    RgbImage {
        width,
        height,
        rgb: std::iter::repeat_n(colour, (width * height) as usize)
            .flatten()
            .collect(),
    }
}

fn font() -> FontRef<'static> {
    FontRef::try_from_slice(FONT_BYTES).expect("the compiled-in font parses")
}

/// The width in pixels of `text` at `size_px`.
pub fn text_width(text: &str, size_px: f32) -> u32 {
    let font = font();
    let scaled = font.as_scaled(PxScale::from(size_px));
    let mut width = 0.0;
    let mut previous = None;
    for ch in text.chars() {
        let id = font.glyph_id(ch);
        if let Some(before) = previous {
            width += scaled.kern(before, id);
        }
        width += scaled.h_advance(id);
        previous = Some(id);
    }
    width.ceil() as u32
}

/// Draws `text` with its top-left at (`x`, `y`), `size_px` high, in `colour`,
/// blended over what is there.
pub fn draw_text(image: &mut RgbImage, x: u32, y: u32, text: &str, size_px: f32, colour: [u8; 3]) {
    let font = font();
    let scale = PxScale::from(size_px);
    let scaled = font.as_scaled(scale);
    let baseline = y as f32 + scaled.ascent();
    let mut caret = x as f32;
    let mut previous = None;
    for ch in text.chars() {
        let id = font.glyph_id(ch);
        if let Some(before) = previous {
            caret += scaled.kern(before, id);
        }
        let glyph = id.with_scale_and_position(scale, point(caret, baseline));
        caret += scaled.h_advance(id);
        previous = Some(id);
        let Some(outlined) = font.outline_glyph(glyph) else {
            continue;
        };
        let bounds = outlined.px_bounds();
        outlined.draw(|gx, gy, coverage| {
            let (px, py) = (
                bounds.min.x as i64 + gx as i64,
                bounds.min.y as i64 + gy as i64,
            );
            blend(image, px, py, colour, coverage);
        });
    }
}

/// `colour` over the pixel (x, y) with `alpha` (0..1); nothing outside the image.
fn blend(image: &mut RgbImage, x: i64, y: i64, colour: [u8; 3], alpha: f32) {
    if x < 0 || y < 0 || x >= image.width as i64 || y >= image.height as i64 {
        return;
    }
    let at = 3 * (y as usize * image.width as usize + x as usize);
    let alpha = alpha.clamp(0.0, 1.0);
    for (pixel, &value) in image.rgb[at..at + 3].iter_mut().zip(&colour) {
        let below = *pixel as f32;
        *pixel = (below + alpha * (value as f32 - below)).round() as u8;
    }
}

/// Fills the axis-aligned rectangle at (x, y) of `width` x `height` with `colour`.
pub fn fill_rect(image: &mut RgbImage, x: i64, y: i64, width: u32, height: u32, colour: [u8; 3]) {
    for dy in 0..height as i64 {
        for dx in 0..width as i64 {
            blend(image, x + dx, y + dy, colour, 1.0);
        }
    }
}

/// The sensor's marker centred on (`x`, `y`): a triangle `size_px` long pointing
/// along `heading_rad` (counter-clockwise from the picture's right, north up), in
/// the marker's colour with an edge.
pub fn draw_sensor(
    image: &mut RgbImage,
    x: f64,
    y: f64,
    heading_rad: f64,
    size_px: f64,
    palette: &Palette,
) {
    for (grow, colour) in [(2.5, palette.marker_edge), (0.0, palette.marker)] {
        let length = size_px + grow;
        let (c, s) = (heading_rad.cos(), heading_rad.sin());
        // Image y grows downwards: a heading's sine goes up the picture.
        let along = |d: f64, across: f64| [x + d * c - across * s, y - d * s - across * c];
        let corners = [
            along(0.6 * length, 0.0),
            along(-0.4 * length, 0.4 * length),
            along(-0.4 * length, -0.4 * length),
        ];
        fill_triangle(image, corners, colour);
    }
}

fn fill_triangle(image: &mut RgbImage, corners: [[f64; 2]; 3], colour: [u8; 3]) {
    let xs = corners.map(|p| p[0]);
    let ys = corners.map(|p| p[1]);
    let low = |v: [f64; 3]| v.iter().copied().fold(f64::INFINITY, f64::min).floor() as i64;
    let high = |v: [f64; 3]| v.iter().copied().fold(f64::NEG_INFINITY, f64::max).ceil() as i64;
    let side = |a: [f64; 2], b: [f64; 2], p: [f64; 2]| {
        (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
    };
    for py in low(ys)..=high(ys) {
        for px in low(xs)..=high(xs) {
            let p = [px as f64 + 0.5, py as f64 + 0.5];
            let s = [
                side(corners[0], corners[1], p),
                side(corners[1], corners[2], p),
                side(corners[2], corners[0], p),
            ];
            if s.iter().all(|&v| v >= 0.0) || s.iter().all(|&v| v <= 0.0) {
                blend(image, px, py, colour, 1.0);
            }
        }
    }
}

/// The longest round length (1, 2 or 5 times a power of ten) of at most `most_m`.
fn round_length_m(most_m: f64) -> f64 {
    let mut best = 0.1;
    for exponent in -1..5 {
        for step in [1.0, 2.0, 5.0] {
            let length = step * 10f64.powi(exponent);
            if length <= most_m {
                best = length;
            }
        }
    }
    best
}

/// Where panel `index` of a composed picture starts (its top-left pixel), when
/// every panel is `panel_width` wide.
pub fn panel_origin(index: usize, panel_width: u32) -> (u32, u32) {
    (
        MARGIN_PX + index as u32 * (panel_width + GAP_PX),
        MARGIN_PX + title_band_px(),
    )
}

fn title_band_px() -> u32 {
    (TITLE_PX * 1.6) as u32
}

/// The picture of `panels` (each `metres_per_pixel`) under their titles, with a
/// scale bar in metres and the legend of `legend`.
pub fn compose(
    panels: &[Panel],
    legend: &[(Swatch, &str)],
    metres_per_pixel: f64,
    palette: &Palette,
) -> RgbImage {
    let panels_width: u32 = panels.iter().map(|p| p.image.width).sum::<u32>()
        + GAP_PX * panels.len().saturating_sub(1) as u32;
    let panel_height = panels.iter().map(|p| p.image.height).max().unwrap_or(0);
    let width = panels_width.max(420) + 2 * MARGIN_PX;
    // The legend's entries in rows that fit the width.
    let entry_width = |words: &str| SWATCH_PX + 6 + text_width(words, LABEL_PX) + 2 * GAP_PX;
    let mut rows: Vec<Vec<(Swatch, &str)>> = vec![Vec::new()];
    let mut row_width = 0;
    for &(swatch, words) in legend {
        let w = entry_width(words);
        if row_width + w > width - 2 * MARGIN_PX && !rows.last().is_some_and(Vec::is_empty) {
            rows.push(Vec::new());
            row_width = 0;
        }
        rows.last_mut()
            .expect("one row at least")
            .push((swatch, words));
        row_width += w;
    }
    let line_px = (LABEL_PX * 1.5) as u32;
    let panels_top = MARGIN_PX + title_band_px();
    let scale_top = panels_top + panel_height + 10;
    let legend_top = scale_top + line_px + 8;
    let height = legend_top + rows.len() as u32 * line_px + MARGIN_PX;
    let mut image = blank(width, height, WHITE);
    let mut x = MARGIN_PX;
    for panel in panels {
        let title_x = x + panel
            .image
            .width
            .saturating_sub(text_width(&panel.title, TITLE_PX))
            / 2;
        draw_text(&mut image, title_x, MARGIN_PX, &panel.title, TITLE_PX, INK);
        for row in 0..panel.image.height {
            let from = 3 * (row * panel.image.width) as usize;
            let to = 3 * ((panels_top + row) * width + x) as usize;
            let len = 3 * panel.image.width as usize;
            image.rgb[to..to + len].copy_from_slice(&panel.image.rgb[from..from + len]);
        }
        x += panel.image.width + GAP_PX;
    }
    // The scale bar: a round length of at most a third of the first panel.
    let first_width = panels.first().map_or(300, |p| p.image.width) as f64;
    let length_m = round_length_m(first_width / 3.0 * metres_per_pixel);
    let bar_px = (length_m / metres_per_pixel).round() as u32;
    let bar_y = scale_top + line_px / 2 - 2;
    fill_rect(&mut image, MARGIN_PX as i64, bar_y as i64, bar_px, 5, INK);
    for end in [MARGIN_PX, MARGIN_PX + bar_px.saturating_sub(2)] {
        fill_rect(&mut image, end as i64, bar_y as i64 - 4, 2, 13, INK);
    }
    let words = match length_m >= 1.0 {
        true => format!("{length_m:.0} m"),
        false => format!("{length_m:.1} m"),
    };
    draw_text(
        &mut image,
        MARGIN_PX + bar_px + 10,
        scale_top,
        &words,
        LABEL_PX,
        INK,
    );
    draw_text(
        &mut image,
        MARGIN_PX + bar_px + 20 + text_width(&words, LABEL_PX),
        scale_top,
        "north up",
        LABEL_PX,
        INK,
    );
    // The legend.
    for (r, row) in rows.iter().enumerate() {
        let y = legend_top + r as u32 * line_px;
        let mut x = MARGIN_PX;
        for &(swatch, words) in row {
            let (sx, sy) = (x as i64, (y + 2) as i64);
            match swatch {
                Swatch::Fill(colour) => {
                    fill_rect(&mut image, sx, sy, SWATCH_PX, SWATCH_PX, INK);
                    fill_rect(
                        &mut image,
                        sx + 1,
                        sy + 1,
                        SWATCH_PX - 2,
                        SWATCH_PX - 2,
                        colour,
                    );
                }
                Swatch::Sensor => {
                    let centre = SWATCH_PX as f64 / 2.0;
                    fill_rect(&mut image, sx, sy, SWATCH_PX, SWATCH_PX, palette.unknown);
                    draw_sensor(
                        &mut image,
                        sx as f64 + centre,
                        sy as f64 + centre,
                        0.0,
                        SWATCH_PX as f64 * 0.8,
                        palette,
                    );
                }
                Swatch::Line => {
                    fill_rect(&mut image, sx, sy, SWATCH_PX, SWATCH_PX, palette.unknown);
                    fill_rect(
                        &mut image,
                        sx + 1,
                        sy + SWATCH_PX as i64 / 2 - 1,
                        SWATCH_PX - 2,
                        2,
                        palette.marker,
                    );
                }
            }
            draw_text(&mut image, x + SWATCH_PX + 6, y, words, LABEL_PX, INK);
            x += entry_width(words);
        }
    }
    image
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_are_drawn_where_asked_and_nowhere_else() {
        let mut image = blank(200, 40, WHITE);
        draw_text(&mut image, 10, 5, "ground truth", 20.0, INK);
        let dark = |x0: u32, x1: u32| {
            (0..40)
                .flat_map(|y| (x0..x1).map(move |x| (x, y)))
                .filter(|&(x, y)| image.rgb[3 * (y * 200 + x) as usize] < 128)
                .count()
        };
        let width = text_width("ground truth", 20.0);
        assert!((100..140).contains(&width), "{width}");
        assert!(dark(10, 10 + width) > 100);
        assert_eq!(dark(0, 9) + dark(12 + width, 200), 0);
    }

    #[test]
    fn the_scale_bar_is_a_round_length() {
        assert_eq!(round_length_m(3.9), 2.0);
        assert_eq!(round_length_m(4.0), 2.0);
        assert_eq!(round_length_m(5.0), 5.0);
        assert_eq!(round_length_m(140.0), 100.0);
        assert_eq!(round_length_m(0.3), 0.2);
    }

    #[test]
    fn the_sensor_points_where_it_faces() {
        let palette = Palette::SAFE;
        // Facing east (0) and north (pi / 2): its tip is right of, then above, the centre.
        for (heading, tip) in [
            (0.0, (35u32, 25u32)),
            (std::f64::consts::FRAC_PI_2, (25, 15)),
        ] {
            let mut image = blank(50, 50, [40, 40, 40]);
            draw_sensor(&mut image, 25.0, 25.0, heading, 20.0, &palette);
            let at = 3 * (tip.1 * 50 + tip.0) as usize;
            assert_eq!(image.rgb[at..at + 3], palette.marker, "{heading}");
        }
    }
}
