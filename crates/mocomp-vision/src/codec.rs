//! 16-bit PNG frames and RGB overlays, from and to bytes (the caller reads and writes files).

use crate::error::VisionError;
use image::{DynamicImage, ImageBuffer, ImageFormat, Luma, Rgb};
use std::io::Cursor;

/// A decoded 16-bit grayscale image.
#[derive(Debug, Clone, PartialEq)]
pub struct Gray16 {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Pixels, row-major.
    pub data: Vec<u16>,
}

/// Decodes a 16-bit grayscale PNG; any other pixel format is an error naming what it is.
pub fn decode_gray16_png(bytes: &[u8], what: &str) -> Result<Gray16, VisionError> {
    let img = image::load_from_memory_with_format(bytes, ImageFormat::Png).map_err(|e| {
        VisionError::Decode {
            what: what.to_string(),
            message: e.to_string(),
        }
    })?;
    let (width, height) = (img.width(), img.height());
    if width == 0 || height == 0 {
        return Err(VisionError::Empty {
            what: what.to_string(),
        });
    }
    match img {
        DynamicImage::ImageLuma16(buf) => Ok(Gray16 {
            width,
            height,
            data: buf.into_raw(),
        }),
        other => Err(VisionError::PixelFormat {
            what: what.to_string(),
            found: format!("{:?}", other.color()),
        }),
    }
}

fn encode<P: image::PixelWithColorType>(
    buf: Option<ImageBuffer<P, Vec<P::Subpixel>>>,
    len: usize,
    (width, height): (u32, u32),
    what: &str,
) -> Result<Vec<u8>, VisionError>
where
    [P::Subpixel]: image::EncodableLayout,
{
    let buf = buf.ok_or(VisionError::BufferSize {
        what: "image to encode",
        len,
        width: width as usize,
        height: height as usize,
    })?;
    let mut out = Cursor::new(Vec::new());
    buf.write_to(&mut out, ImageFormat::Png)
        .map_err(|e| VisionError::Decode {
            what: what.to_string(),
            message: e.to_string(),
        })?;
    Ok(out.into_inner())
}

/// Encodes a 16-bit grayscale PNG.
pub fn encode_gray16_png(
    width: u32,
    height: u32,
    data: &[u16],
    what: &str,
) -> Result<Vec<u8>, VisionError> {
    let buf = ImageBuffer::<Luma<u16>, Vec<u16>>::from_raw(width, height, data.to_vec());
    encode(buf, data.len(), (width, height), what)
}

/// Encodes an 8-bit RGB PNG.
pub fn encode_rgb_png(
    width: u32,
    height: u32,
    data: &[u8],
    what: &str,
) -> Result<Vec<u8>, VisionError> {
    let buf = ImageBuffer::<Rgb<u8>, Vec<u8>>::from_raw(width, height, data.to_vec());
    encode(buf, data.len() / 3, (width, height), what)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sixteen_bit_round_trip_and_eight_bit_rejected() {
        let data: Vec<u16> = (0..12).map(|v| v * 5000).collect();
        let png = encode_gray16_png(4, 3, &data, "t").unwrap();
        let back = decode_gray16_png(&png, "t").unwrap();
        assert_eq!((back.width, back.height), (4, 3));
        assert_eq!(back.data, data);
        let rgb = encode_rgb_png(2, 1, &[1, 2, 3, 4, 5, 6], "o").unwrap();
        let e = decode_gray16_png(&rgb, "ir.png").unwrap_err().to_string();
        assert!(
            e.contains("ir.png") && e.contains("16-bit") && e.contains("Rgb8"),
            "{e}"
        );
        let e = decode_gray16_png(b"not a png", "x.png")
            .unwrap_err()
            .to_string();
        assert!(e.contains("x.png"), "{e}");
    }
}
