//! Camera images into [`RgbImage`]s: PNG files and ROS `Image` / `CompressedImage`
//! payloads, bounded so that no header can claim more memory than a camera makes.

use crate::error::{Error, Result};
use crate::frame::RgbImage;
use crate::io::ros::MessageEncoding;

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

/// The RGB pixels of a `CompressedImage` (png) or, when not `compressed`, a raw
/// `Image`, in `encoding`.
pub fn image_pixels(
    data: &[u8],
    compressed: bool,
    encoding: MessageEncoding,
) -> Result<RgbImage, String> {
    if compressed {
        let message: crate::io::ros::CompressedImage = encoding.decode(data)?;
        if !message.format.to_ascii_lowercase().contains("png") {
            return Err(format!(
                "image format `{}`: travmap decodes png",
                message.format
            ));
        }
        png_pixels(&message.data)
    } else {
        raw_image(&encoding.decode(data)?)
    }
}

/// An RGB image from a raw `sensor_msgs/msg/Image` (rgb8, bgr8, rgba8, bgra8, mono8).
fn raw_image(message: &crate::io::ros::Image) -> Result<RgbImage, String> {
    let (width, height, step) = (
        message.width as usize,
        message.height as usize,
        message.step as usize,
    );
    let channels = match message.encoding.as_str() {
        "rgb8" | "bgr8" => 3,
        "rgba8" | "bgra8" => 4,
        "mono8" => 1,
        other => {
            return Err(format!(
                "image encoding `{other}`: travmap reads rgb8, bgr8, rgba8, bgra8 and mono8"
            ));
        }
    };
    if width == 0 || height == 0 {
        return Err(format!("an empty {width}x{height} image"));
    }
    if step < width * channels || message.data.len() < step * height {
        return Err(format!(
            "{} bytes for {width}x{height} {} with step {step}",
            message.data.len(),
            message.encoding
        ));
    }
    let bgr = message.encoding.starts_with("bgr");
    let mut rgb = Vec::with_capacity(width * height * 3);
    for row in message.data.chunks_exact(step).take(height) {
        for px in row[..width * channels].chunks_exact(channels) {
            match (channels, bgr) {
                (1, _) => rgb.extend_from_slice(&[px[0], px[0], px[0]]),
                (_, true) => rgb.extend_from_slice(&[px[2], px[1], px[0]]),
                _ => rgb.extend_from_slice(&px[..3]),
            }
        }
    }
    Ok(RgbImage {
        width: message.width,
        height: message.height,
        rgb,
    })
}
