//! Writing rendered images: PNG (8-bit sRGB, tonemapped) and OpenEXR (linear float), written through a
//! temporary file and a rename so that a crash never leaves half an image; and reading background plates.

use std::io::Cursor;
use std::path::Path;

use super::{DisplayImage, HdrImage};
use crate::optics::formats::write_atomic;

/// Why an image could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    #[error("{path}: {message}")]
    Encode { path: String, message: String },
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("{path}: cannot read the image: {message}")]
    Decode { path: String, message: String },
    #[error("{path}: unknown image type (use .png or .exr)")]
    Extension { path: String },
}

/// Output image kinds, by extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageKind {
    Png,
    Exr,
}

impl ImageKind {
    pub fn from_path(path: &Path) -> Result<Self, ImageError> {
        match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
            Some("png") => Ok(Self::Png),
            Some("exr") => Ok(Self::Exr),
            _ => Err(ImageError::Extension { path: path.display().to_string() }),
        }
    }
}

fn encode(path: &Path, e: impl std::fmt::Display) -> ImageError {
    ImageError::Encode { path: path.display().to_string(), message: e.to_string() }
}

/// Writes an 8-bit sRGB PNG.
pub fn write_png(path: &Path, image: &DisplayImage) -> Result<(), ImageError> {
    let raw: Vec<u8> = image.pixels.iter().flatten().copied().collect();
    let buffer =
        image::RgbaImage::from_raw(image.width, image.height, raw).ok_or_else(|| encode(path, "size mismatch"))?;
    let mut bytes = Vec::new();
    buffer.write_to(&mut Cursor::new(&mut bytes), image::ImageFormat::Png).map_err(|e| encode(path, e))?;
    write_atomic(path, &bytes).map_err(|source| ImageError::Io { path: path.display().to_string(), source })
}

/// Writes a linear float OpenEXR (RGBA, every value finite).
pub fn write_exr(path: &Path, image: &HdrImage) -> Result<(), ImageError> {
    let raw: Vec<f32> = image
        .pixels
        .iter()
        .flat_map(|p| [p[0], p[1], p[2], 1.0])
        .map(|v| if v.is_finite() { v } else { 0.0 })
        .collect();
    let buffer =
        image::Rgba32FImage::from_raw(image.width, image.height, raw).ok_or_else(|| encode(path, "size mismatch"))?;
    let mut bytes = Vec::new();
    image::DynamicImage::ImageRgba32F(buffer)
        .write_to(&mut Cursor::new(&mut bytes), image::ImageFormat::OpenExr)
        .map_err(|e| encode(path, e))?;
    write_atomic(path, &bytes).map_err(|source| ImageError::Io { path: path.display().to_string(), source })
}

/// Reads a background plate (PNG is decoded from sRGB to linear; EXR and Radiance HDR are taken as linear),
/// any size.
pub fn read_plate(path: &Path) -> Result<HdrImage, ImageError> {
    let decode = |message: String| ImageError::Decode { path: path.display().to_string(), message };
    let img = image::open(path).map_err(|e| decode(e.to_string()))?;
    let is_float = matches!(img, image::DynamicImage::ImageRgb32F(_) | image::DynamicImage::ImageRgba32F(_));
    let (width, height) = (img.width(), img.height());
    if width == 0 || height == 0 || (width as u64) * (height as u64) > 16384 * 16384 {
        return Err(decode(format!("{width} x {height} pixels is not a usable plate")));
    }
    let rgba = img.to_rgba32f();
    let linear = |v: f32| {
        let v = if v.is_finite() { v.max(0.0) } else { 0.0 };
        if is_float {
            v
        } else if v <= 0.04045 {
            v / 12.92
        } else {
            ((v + 0.055) / 1.055).powf(2.4)
        }
    };
    let pixels = rgba.pixels().map(|p| [linear(p[0]), linear(p[1]), linear(p[2]), 1.0]).collect();
    Ok(HdrImage { width, height, pixels })
}
