//! Camera images into [`RgbImage`]s: PNG files and ROS `Image` / `CompressedImage`
//! payloads (PNG or JPEG), bounded so that no header can claim more memory than a
//! camera makes.

use travmap_core::error::{Error, Result};
use travmap_core::frame::RgbImage;
use travmap_formats::ros::MessageEncoding;

/// The largest decoded image, 8192 x 8192 RGBA: above any camera's.
const MAX_IMAGE_BYTES: usize = 8192 * 8192 * 4;

/// Decodes a PNG into 8-bit RGB (grey and RGBA are converted; 16-bit is reduced).
pub fn decode_png(bytes: &[u8], source: &std::path::Path) -> Result<RgbImage> {
    png_pixels(bytes).map_err(|message| Error::Sequence {
        path: source.to_path_buf(),
        message,
    })
}

/// [`decode_png`] with errors that leave naming the source to the caller.
pub fn png_pixels(bytes: &[u8]) -> std::result::Result<RgbImage, String> {
    let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    decoder.set_transformations(png::Transformations::normalize_to_color8());
    let mut reader = decoder
        .read_info()
        .map_err(|e| format!("not a readable PNG: {e}"))?;
    // The header's size alone decides the buffer, and a few hundred bytes of zlib
    // can claim gigabytes: refuse what no camera produces.
    let size = reader
        .output_buffer_size()
        .filter(|&size| size <= MAX_IMAGE_BYTES)
        .ok_or_else(|| {
            let info = reader.info();
            format!(
                "PNG of {}x{} pixels: larger than the {} MiB travmap decodes",
                info.width,
                info.height,
                MAX_IMAGE_BYTES >> 20
            )
        })?;
    let mut buffer = vec![0u8; size];
    let info = reader
        .next_frame(&mut buffer)
        .map_err(|e| format!("PNG data: {e}"))?;
    buffer.truncate(info.buffer_size());
    let pixels = info.width as usize * info.height as usize;
    let rgb = match info.color_type {
        png::ColorType::Rgb => buffer,
        png::ColorType::Rgba => buffer
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect(),
        png::ColorType::Grayscale => buffer.iter().flat_map(|&g| [g, g, g]).collect(),
        png::ColorType::GrayscaleAlpha => buffer
            .chunks_exact(2)
            .flat_map(|p| [p[0], p[0], p[0]])
            .collect(),
        png::ColorType::Indexed => return Err("indexed PNG left unexpanded".into()),
    };
    if rgb.len() != 3 * pixels {
        return Err(format!(
            "{} bytes of RGB for {}x{} pixels",
            rgb.len(),
            info.width,
            info.height
        ));
    }
    Ok(RgbImage {
        width: info.width,
        height: info.height,
        rgb,
    })
}

/// Decodes a JPEG into 8-bit RGB (grey is converted).
pub fn jpeg_pixels(bytes: &[u8]) -> std::result::Result<RgbImage, String> {
    use zune_jpeg::JpegDecoder;
    use zune_jpeg::zune_core::bytestream::ZCursor;
    use zune_jpeg::zune_core::colorspace::ColorSpace;
    use zune_jpeg::zune_core::options::DecoderOptions;

    let options = DecoderOptions::default().jpeg_set_out_colorspace(ColorSpace::RGB);
    let mut decoder = JpegDecoder::new_with_options(ZCursor::new(bytes), options);
    decoder
        .decode_headers()
        .map_err(|e| format!("not a readable JPEG: {e}"))?;
    let (width, height) = decoder.dimensions().ok_or("a JPEG without its size")?;
    // As for PNG: the header alone decides the buffer.
    if decoder
        .output_buffer_size()
        .is_none_or(|size| size > MAX_IMAGE_BYTES)
    {
        return Err(format!(
            "JPEG of {width}x{height} pixels: larger than the {} MiB travmap decodes",
            MAX_IMAGE_BYTES >> 20
        ));
    }
    let pixels = decoder.decode().map_err(|e| format!("JPEG data: {e}"))?;
    // The decoder may keep another colour space than the one asked for.
    let rgb = match decoder.output_colorspace() {
        Some(ColorSpace::RGB) => pixels,
        Some(ColorSpace::Luma) => pixels.iter().flat_map(|&g| [g, g, g]).collect(),
        Some(ColorSpace::RGBA) => pixels
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect(),
        other => return Err(format!("a JPEG decoded as {other:?}, not RGB")),
    };
    if rgb.len() != 3 * width * height {
        return Err(format!(
            "{} bytes of RGB for {width}x{height} pixels",
            rgb.len()
        ));
    }
    Ok(RgbImage {
        width: width as u32,
        height: height as u32,
        rgb,
    })
}

/// The RGB pixels of a `CompressedImage` or, when not `compressed`, a raw `Image`,
/// in `encoding`.
pub fn image_pixels(
    data: &[u8],
    compressed: bool,
    encoding: MessageEncoding,
) -> Result<RgbImage, String> {
    if compressed {
        let message: travmap_formats::ros::CompressedImage = encoding.decode(data)?;
        compressed_pixels(&message.format, &message.data)
    } else {
        raw_image(&encoding.decode(data)?)
    }
}

/// Where red and blue lie in each 2x2 tile of an 8-bit Bayer encoding, (row, col);
/// the greens are on the other diagonal. None for any other encoding.
fn bayer_red_and_blue(encoding: &str) -> Option<[(usize, usize); 2]> {
    match encoding {
        "bayer_rggb8" => Some([(0, 0), (1, 1)]),
        "bayer_bggr8" => Some([(1, 1), (0, 0)]),
        "bayer_gbrg8" => Some([(1, 0), (0, 1)]),
        "bayer_grbg8" => Some([(0, 1), (1, 0)]),
        _ => None,
    }
}

/// The RGB of a Bayer mosaic (at least 2x2), each pixel the colour of the 2x2 tile it
/// lies in: its red, its blue and the mean of its two greens (an odd last row or
/// column takes the tile before it). Chroma at half resolution, which is all the
/// cells' colour histograms need; a uniform colour comes back exactly.
fn debayered(
    data: &[u8],
    width: usize,
    height: usize,
    step: usize,
    [(red_row, red_col), (blue_row, blue_col)]: [(usize, usize); 2],
) -> Vec<u8> {
    let mut rgb = Vec::with_capacity(width * height * 3);
    for y in 0..height {
        let top = (y & !1).min((height - 2) & !1);
        let rows = [&data[top * step..], &data[(top + 1) * step..]];
        for x in 0..width {
            let left = (x & !1).min((width - 2) & !1);
            let at = |row: usize, col: usize| rows[row][left + col];
            let greens = at(red_row, 1 - red_col) as u16 + at(1 - red_row, red_col) as u16;
            rgb.extend_from_slice(&[
                at(red_row, red_col),
                greens.div_ceil(2) as u8,
                at(blue_row, blue_col),
            ]);
        }
    }
    rgb
}

/// A `CompressedImage`'s pixels, PNG or JPEG as its first bytes say: drivers name
/// the format in many ways (`jpeg`, `rgb8; jpeg compressed bgr8`, `png`, ...) and
/// some leave it empty. Both store their colours in the file's own order, whatever
/// the `bgr8` in the name (OpenCV's encoder takes BGR and writes standard files).
fn compressed_pixels(format: &str, data: &[u8]) -> std::result::Result<RgbImage, String> {
    if data.starts_with(b"\x89PNG") {
        png_pixels(data)
    } else if data.starts_with(&[0xFF, 0xD8, 0xFF]) {
        jpeg_pixels(data)
    } else {
        let start: Vec<String> = data.iter().take(4).map(|b| format!("{b:02x}")).collect();
        Err(format!(
            "image format `{format}`, data starting [{}]: travmap decodes PNG and JPEG",
            start.join(" ")
        ))
    }
}

/// How a raw `Image` encoding lays out its pixels.
enum Layout {
    /// `bytes` per pixel, R, G and B at these of them (8-bit RGB, BGR, RGBA, BGRA,
    /// mono).
    Bytes { bytes: usize, rgb_at: [usize; 3] },
    /// 16-bit channels (`channels` of them), R, G and B at these: their high bytes.
    Wide { channels: usize, rgb_at: [usize; 3] },
    /// An 8-bit Bayer mosaic: where red and blue lie in each 2x2 tile.
    Bayer([(usize, usize); 2]),
    /// 4:2:2 YUV, two pixels in four bytes: where their Ys, U and V lie.
    Yuv422 {
        y_at: [usize; 2],
        u_at: usize,
        v_at: usize,
    },
}

/// The raw encodings read, for messages.
const RAW_ENCODINGS: &str = "rgb8, bgr8, rgba8, bgra8, mono8, rgb16, bgr16, rgba16, bgra16, mono16, bayer_rggb8, bayer_bggr8, bayer_gbrg8, bayer_grbg8, yuv422 (UYVY) and yuv422_yuy2 (YUYV)";

impl Layout {
    fn of(encoding: &str) -> Option<Self> {
        let bytes = |bytes, rgb_at| Some(Self::Bytes { bytes, rgb_at });
        let wide = |channels, rgb_at| Some(Self::Wide { channels, rgb_at });
        match encoding {
            "rgb8" => bytes(3, [0, 1, 2]),
            "bgr8" => bytes(3, [2, 1, 0]),
            "rgba8" => bytes(4, [0, 1, 2]),
            "bgra8" => bytes(4, [2, 1, 0]),
            "mono8" => bytes(1, [0, 0, 0]),
            "rgb16" => wide(3, [0, 1, 2]),
            "bgr16" => wide(3, [2, 1, 0]),
            "rgba16" => wide(4, [0, 1, 2]),
            "bgra16" => wide(4, [2, 1, 0]),
            "mono16" => wide(1, [0, 0, 0]),
            "yuv422" | "uyvy" => Some(Self::Yuv422 {
                y_at: [1, 3],
                u_at: 0,
                v_at: 2,
            }),
            "yuv422_yuy2" | "yuyv" => Some(Self::Yuv422 {
                y_at: [0, 2],
                u_at: 1,
                v_at: 3,
            }),
            other => bayer_red_and_blue(other).map(Self::Bayer),
        }
    }

    /// Bytes a row of `width` pixels takes.
    fn row_bytes(&self, width: usize) -> usize {
        match self {
            Self::Bytes { bytes, .. } => width * bytes,
            Self::Wide { channels, .. } => width * channels * 2,
            Self::Bayer(_) => width,
            Self::Yuv422 { .. } => width.div_ceil(2) * 4,
        }
    }
}

/// An RGB image from a raw `sensor_msgs/msg/Image` in one of [`RAW_ENCODINGS`].
fn raw_image(message: &travmap_formats::ros::Image) -> Result<RgbImage, String> {
    let (width, height, step) = (
        message.width as usize,
        message.height as usize,
        message.step as usize,
    );
    let encoding = &message.encoding;
    let layout = Layout::of(encoding)
        .ok_or_else(|| format!("image encoding `{encoding}`: travmap reads {RAW_ENCODINGS}"))?;
    let bayer = matches!(layout, Layout::Bayer(_));
    if width == 0 || height == 0 || (bayer && (width < 2 || height < 2)) {
        return Err(format!("an empty {width}x{height} image"));
    }
    if step < layout.row_bytes(width) || message.data.len() < step * height {
        return Err(format!(
            "{} bytes for {width}x{height} {encoding} with step {step}",
            message.data.len()
        ));
    }
    let rows = || message.data.chunks_exact(step).take(height);
    let rgb = match layout {
        Layout::Bayer(red_and_blue) => debayered(&message.data, width, height, step, red_and_blue),
        Layout::Bytes { bytes, rgb_at } => rows()
            .flat_map(|row| row[..width * bytes].chunks_exact(bytes))
            .flat_map(|px| rgb_at.map(|at| px[at]))
            .collect(),
        Layout::Wide { channels, rgb_at } => {
            // The high byte of each 16-bit value, wherever the message's order puts it.
            let high = if message.is_bigendian != 0 { 0 } else { 1 };
            rows()
                .flat_map(|row| row[..width * channels * 2].chunks_exact(channels * 2))
                .flat_map(|px| rgb_at.map(|at| px[2 * at + high]))
                .collect()
        }
        Layout::Yuv422 { y_at, u_at, v_at } => rows()
            .flat_map(|row| {
                row[..width.div_ceil(2) * 4]
                    .chunks_exact(4)
                    .flat_map(move |pair| {
                        y_at.map(|at| yuv_to_rgb(pair[at], pair[u_at], pair[v_at]))
                    })
                    .take(width)
            })
            .flatten()
            .collect(),
    };
    Ok(RgbImage {
        width: message.width,
        height: message.height,
        rgb,
    })
}

/// RGB of a video-range BT.601 YUV pixel, as OpenCV's `COLOR_YUV2RGB_UYVY` /
/// `_YUY2` (and so cv_bridge) convert it: Y from 16 to 235, U and V centred on 128.
fn yuv_to_rgb(y: u8, u: u8, v: u8) -> [u8; 3] {
    let (y, u, v) = (
        1.164 * (y as f32 - 16.0),
        u as f32 - 128.0,
        v as f32 - 128.0,
    );
    [y + 1.596 * v, y - 0.391 * u - 0.813 * v, y + 2.018 * u]
        .map(|c| c.round().clamp(0.0, 255.0) as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fixture(name: &str) -> Vec<u8> {
        let path = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
            .join("fixtures/camera");
        std::fs::read(path.join(name)).unwrap()
    }

    const JPEGS: [&str; 3] = [
        "kitti-000008-crop.jpg",
        "kitti-000008-crop-progressive.jpg",
        "kitti-000008-grey.jpg",
    ];

    /// Each fixture JPEG against libjpeg-turbo's decoding of it (Pillow 13.0.0, kept
    /// as PNG beside it): decoders may round the inverse DCT and the chroma
    /// upsampling differently, by a level or two, no more.
    #[test]
    fn jpegs_decode_as_libjpeg_turbo_decodes_them() {
        for name in JPEGS {
            let ours = jpeg_pixels(&fixture(name)).unwrap();
            let reference = png_pixels(&fixture(&format!("{name}.png"))).unwrap();
            assert_eq!(
                (ours.width, ours.height),
                (reference.width, reference.height),
                "{name}"
            );
            let differences: Vec<u8> = (ours.rgb.iter().zip(&reference.rgb))
                .map(|(a, b)| a.abs_diff(*b))
                .collect();
            let largest = *differences.iter().max().unwrap();
            let mean =
                differences.iter().map(|&d| d as f64).sum::<f64>() / differences.len() as f64;
            // Measured: largest 4, 3 and 1, means 0.32, 0.31 and 0.01.
            assert!(
                largest <= 6 && mean <= 0.5,
                "{name}: largest {largest}, mean {mean}"
            );
        }
    }

    #[test]
    fn a_compressed_image_is_told_by_its_bytes_not_its_format_name() {
        let (jpeg, png) = (fixture(JPEGS[0]), fixture(&format!("{}.png", JPEGS[0])));
        // Names as drivers and image_transport write them, one empty, one wrong.
        for format in [
            "jpeg",
            "rgb8; jpeg compressed bgr8",
            "bgr8; jpeg compressed bgr8",
            "",
            "png",
        ] {
            let image = compressed_pixels(format, &jpeg).unwrap();
            assert_eq!((image.width, image.height), (192, 96), "{format}");
        }
        assert_eq!(
            compressed_pixels("jpeg", &png).unwrap(),
            png_pixels(&png).unwrap()
        );
        let error = compressed_pixels("theora", b"OggS\0\0").unwrap_err();
        assert!(
            error.contains("`theora`")
                && error.contains("[4f 67 67 53]")
                && error.contains("PNG and JPEG"),
            "{error}"
        );
    }

    /// `image` (RGB) as the 8-bit Bayer mosaic `encoding` a camera would send.
    fn mosaic(image: &RgbImage, encoding: &str) -> travmap_formats::ros::Image {
        let [red, blue] = bayer_red_and_blue(encoding).unwrap();
        let (width, height) = (image.width as usize, image.height as usize);
        let data = (0..height)
            .flat_map(|y| (0..width).map(move |x| (y, x)))
            .map(|(y, x)| {
                let channel = match (y % 2, x % 2) {
                    at if at == red => 0,
                    at if at == blue => 2,
                    _ => 1,
                };
                image.rgb[3 * (y * width + x) + channel]
            })
            .collect();
        travmap_formats::ros::Image {
            header: Default::default(),
            height: image.height,
            width: image.width,
            encoding: encoding.into(),
            is_bigendian: 0,
            step: image.width,
            data,
        }
    }

    #[test]
    fn bayer_mosaics_come_back_as_their_tiles_colours() {
        for encoding in ["bayer_rggb8", "bayer_bggr8", "bayer_gbrg8", "bayer_grbg8"] {
            // A uniform colour, odd sizes included, comes back exactly.
            for (width, height) in [(2, 2), (5, 3), (8, 6)] {
                let uniform = RgbImage {
                    width,
                    height,
                    rgb: [200, 100, 50].repeat((width * height) as usize),
                };
                assert_eq!(
                    raw_image(&mosaic(&uniform, encoding)).unwrap(),
                    uniform,
                    "{encoding}"
                );
            }
            // Two tiles of two colours: each pixel takes its tile's.
            let two = RgbImage {
                width: 4,
                height: 2,
                rgb: [[10, 20, 30], [10, 20, 30], [200, 150, 100], [200, 150, 100]]
                    .repeat(2)
                    .concat(),
            };
            assert_eq!(
                raw_image(&mosaic(&two, encoding)).unwrap(),
                two,
                "{encoding}"
            );
        }
        // The greens of a tile are averaged (rounding up).
        let mut image = mosaic(
            &RgbImage {
                width: 2,
                height: 2,
                rgb: vec![0; 12],
            },
            "bayer_rggb8",
        );
        image.data = vec![9, 100, 101, 7];
        assert_eq!(raw_image(&image).unwrap().rgb, [9, 101, 7].repeat(4));
        image.width = 1;
        assert!(raw_image(&image).unwrap_err().contains("empty 1x2"));
    }

    fn raw(
        encoding: &str,
        width: u32,
        height: u32,
        step: u32,
        data: Vec<u8>,
    ) -> travmap_formats::ros::Image {
        travmap_formats::ros::Image {
            header: Default::default(),
            height,
            width,
            encoding: encoding.into(),
            is_bigendian: 0,
            step,
            data,
        }
    }

    #[test]
    fn yuv_and_16_bit_images_are_read_as_their_colours() {
        // Video range: Y 16 black, 235 white; a red (BT.601: Y 81, U 90, V 240).
        assert_eq!(yuv_to_rgb(16, 128, 128), [0, 0, 0]);
        assert_eq!(yuv_to_rgb(235, 128, 128), [255, 255, 255]);
        let red = yuv_to_rgb(81, 90, 240);
        assert!(red[0] >= 250 && red[1] <= 5 && red[2] <= 5, "{red:?}");
        // UYVY and YUYV of the same two pixels (white, then black), odd width 3
        // (the last pair half used).
        let uyvy = raw(
            "yuv422",
            3,
            1,
            8,
            vec![128, 235, 128, 16, 128, 235, 128, 16],
        );
        let yuyv = raw(
            "yuv422_yuy2",
            3,
            1,
            8,
            vec![235, 128, 16, 128, 235, 128, 16, 128],
        );
        let expected = [255, 255, 255, 0, 0, 0, 255, 255, 255];
        assert_eq!(raw_image(&uyvy).unwrap().rgb, expected);
        assert_eq!(raw_image(&yuyv).unwrap().rgb, expected);
        // 16-bit: the high byte, in either byte order.
        let mut wide = raw("bgr16", 1, 1, 6, vec![0x11, 0x10, 0x22, 0x20, 0x33, 0x30]);
        assert_eq!(raw_image(&wide).unwrap().rgb, [0x30, 0x20, 0x10]);
        wide.is_bigendian = 1;
        assert_eq!(raw_image(&wide).unwrap().rgb, [0x33, 0x22, 0x11]);
        let mono = raw("mono16", 2, 1, 4, vec![0, 0x80, 0xFF, 0x01]);
        assert_eq!(raw_image(&mono).unwrap().rgb, [0x80, 0x80, 0x80, 1, 1, 1]);
        // Too few bytes for the rows, and an encoding travmap does not read.
        assert!(
            raw_image(&raw("yuv422", 4, 1, 6, vec![0; 6]))
                .unwrap_err()
                .contains("with step 6")
        );
        let error = raw_image(&raw("32FC1", 1, 1, 4, vec![0; 4])).unwrap_err();
        assert!(
            error.contains("`32FC1`") && error.contains("yuv422_yuy2"),
            "{error}"
        );
    }

    #[test]
    fn a_cut_or_swollen_jpeg_is_an_error_not_a_panic() {
        let jpeg = fixture(JPEGS[0]);
        // Cut anywhere: a clear error, or (the decoder being lenient, as viewers are)
        // an image of the declared size with the missing part left grey.
        for end in (0..jpeg.len()).step_by(97) {
            if let Ok(image) = jpeg_pixels(&jpeg[..end]) {
                assert_eq!(image.rgb.len(), 3 * 192 * 96, "cut at {end}");
            }
        }
        assert!(jpeg_pixels(&jpeg[..200]).is_err());
        // A frame header (SOF) claiming 65535 x 65535 pixels: refused before decoding.
        let mut swollen = jpeg.clone();
        let sof = (0..swollen.len() - 1)
            .find(|&i| swollen[i] == 0xFF && matches!(swollen[i + 1], 0xC0 | 0xC2))
            .unwrap();
        swollen[sof + 5..sof + 9].copy_from_slice(&[0xFF; 4]);
        let error = jpeg_pixels(&swollen).unwrap_err();
        assert!(error.contains("width 65535"), "{error}");
    }
}
