//! Image files: the one writer of every frame FlareLab writes ([`write_frame`]: PNG, 8-bit sRGB tonemapped;
//! OpenEXR, linear float with named layers), and the reader of background plates ([`read_plate`]).
//!
//! # How it works
//! A PNG holds the display image: the composite `plate x 2^plate_ev + flare x 2^flare_ev`, tonemapped and
//! sRGB-encoded. An EXR holds the same frame linear, in one part whose channels compositors group by the
//! prefix before the dot: the default layer `R, G, B, A` is the composite (alpha 1), `flare.R/G/B` the flare
//! alone (ghosts, LUT ghosts and starburst, to be added over a plate), `starburst.R/G/B` its starburst,
//! `plate.R/G/B` the exposed plate when there is one, and `ghost_I_J.R/G/B` one layer per drawn ghost when
//! asked for. Channels are 32-bit float, ZIP-compressed; a value that is not finite is written as 0 (none
//! should reach here). Every file is written through [`crate::files::write_atomic`]: a temporary file in the
//! target's folder renamed over it, so a failed write leaves nothing half-written. Plates: PNG and JPEG are
//! decoded from sRGB to linear, EXR and Radiance HDR are taken as linear.

use std::io::Cursor;
use std::path::Path;

use crate::color::srgb_decode;
use crate::files::write_atomic;
use crate::image::{DisplayImage, HdrImage};

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

/// Linear layers of a frame for compositors, each at the frame's size (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct FrameLayers {
    /// `flare + plate`: what the display image shows, before the tonemap.
    pub composite: HdrImage,
    /// The flare alone (ghosts, LUT ghosts and starburst) x `2^flare_ev`, to be added over a plate.
    pub flare: HdrImage,
    /// The starburst's share of the flare.
    pub starburst: HdrImage,
    /// The plate x `2^plate_ev`, when there is one.
    pub plate: Option<HdrImage>,
    /// Per drawn ghost, `ghost_I_J` and its share of the flare (only when asked for).
    pub ghosts: Vec<(String, HdrImage)>,
}

fn encode(path: &Path, e: impl std::fmt::Display) -> ImageError {
    ImageError::Encode { path: path.display().to_string(), message: e.to_string() }
}

fn io(path: &Path, source: std::io::Error) -> ImageError {
    ImageError::Io { path: path.display().to_string(), source }
}

/// Writes a frame: the display image to a PNG, or `layers` to an EXR (by the extension of `path`).
pub fn write_frame(path: &Path, display: &DisplayImage, layers: Option<&FrameLayers>) -> Result<(), ImageError> {
    match ImageKind::from_path(path)? {
        ImageKind::Png => write_png(path, display),
        ImageKind::Exr => match layers {
            Some(layers) => write_exr_layers(path, layers),
            None => Err(encode(path, "an EXR needs the frame's linear layers")),
        },
    }
}

/// Writes an 8-bit sRGB PNG.
pub fn write_png(path: &Path, image: &DisplayImage) -> Result<(), ImageError> {
    let raw: Vec<u8> = image.pixels.iter().flatten().copied().collect();
    let buffer =
        ::image::RgbaImage::from_raw(image.width, image.height, raw).ok_or_else(|| encode(path, "size mismatch"))?;
    let mut bytes = Vec::new();
    buffer.write_to(&mut Cursor::new(&mut bytes), ::image::ImageFormat::Png).map_err(|e| encode(path, e))?;
    write_atomic(path, &bytes).map_err(|e| io(path, e))
}

/// The EXR channels of one layer (`prefix` empty: the default layer), RGB, optionally alpha.
fn channels(prefix: &str, image: &HdrImage, alpha: bool) -> Vec<exr::prelude::AnyChannel<exr::prelude::FlatSamples>> {
    use exr::prelude::{AnyChannel, FlatSamples};
    let name = |c: &str| if prefix.is_empty() { c.to_owned() } else { format!("{prefix}.{c}") };
    let finite = |v: f32| if v.is_finite() { v } else { 0.0 };
    let count = if alpha { 4 } else { 3 };
    (0..count)
        .map(|k| {
            let samples = image.pixels.iter().map(|p| finite(p[k])).collect();
            AnyChannel::new(name(["R", "G", "B", "A"][k]).as_str(), FlatSamples::F32(samples))
        })
        .collect()
}

/// Writes one linear image with no tonemap: an EXR's default layer `R, G, B, A`, or an 8-bit sRGB PNG of the
/// values clamped to [0, 1] (a plate written as it was read: `flarelab dof`'s output).
pub fn write_linear(path: &Path, image: &HdrImage) -> Result<(), ImageError> {
    match ImageKind::from_path(path)? {
        ImageKind::Png => {
            let encode8 = |v: f32| {
                (crate::color::srgb_encode(if v.is_finite() { v.clamp(0.0, 1.0) } else { 0.0 }) * 255.0).round() as u8
            };
            let pixels = image.pixels.iter().map(|p| [encode8(p[0]), encode8(p[1]), encode8(p[2]), 255]).collect();
            write_png(path, &DisplayImage { width: image.width, height: image.height, pixels })
        }
        ImageKind::Exr => write_exr_channels(path, image.width, image.height, channels("", image, true)),
    }
}

/// Writes one float channel named `name` as an EXR (a depth map's `Z`, in metres).
pub fn write_exr_channel(path: &Path, w: u32, h: u32, name: &str, values: &[f32]) -> Result<(), ImageError> {
    use exr::prelude::{AnyChannel, FlatSamples};
    if values.len() != w as usize * h as usize {
        return Err(encode(path, format!("{} values for {w}x{h} pixels", values.len())));
    }
    let samples = values.iter().map(|&v| if v.is_nan() { 0.0 } else { v }).collect();
    write_exr_channels(path, w, h, vec![AnyChannel::new(name, FlatSamples::F32(samples))])
}

/// Writes the layers as one EXR part (see the module documentation).
pub fn write_exr_layers(path: &Path, layers: &FrameLayers) -> Result<(), ImageError> {
    let (w, h) = (layers.composite.width, layers.composite.height);
    let mut list = channels("", &layers.composite, true);
    list.extend(channels("flare", &layers.flare, false));
    list.extend(channels("starburst", &layers.starburst, false));
    if let Some(plate) = &layers.plate {
        list.extend(channels("plate", plate, false));
    }
    for (name, image) in &layers.ghosts {
        list.extend(channels(name, image, false));
    }
    write_exr_channels(path, w, h, list)
}

/// Writes `list` as one EXR part of `w` x `h` pixels, ZIP-compressed, through a temporary file.
fn write_exr_channels(
    path: &Path,
    w: u32,
    h: u32,
    list: Vec<exr::prelude::AnyChannel<exr::prelude::FlatSamples>>,
) -> Result<(), ImageError> {
    use exr::prelude::{AnyChannels, Encoding, Image, Layer, LayerAttributes, SmallVec, WritableImage};
    let layer = Layer::new(
        (w as usize, h as usize),
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(SmallVec::from_vec(list)),
    );
    let mut bytes = Vec::new();
    Image::from_layer(layer).write().to_buffered(Cursor::new(&mut bytes)).map_err(|e| encode(path, e))?;
    write_atomic(path, &bytes).map_err(|e| io(path, e))
}

/// Reads a background plate (PNG and JPEG are decoded from sRGB to linear; EXR and Radiance HDR are taken as
/// linear), any size.
pub fn read_plate(path: &Path) -> Result<HdrImage, ImageError> {
    let decode = |message: String| ImageError::Decode { path: path.display().to_string(), message };
    let img = ::image::open(path).map_err(|e| decode(e.to_string()))?;
    let is_float = matches!(img, ::image::DynamicImage::ImageRgb32F(_) | ::image::DynamicImage::ImageRgba32F(_));
    let (width, height) = (img.width(), img.height());
    if width == 0 || height == 0 || (width as u64) * (height as u64) > 16384 * 16384 {
        return Err(decode(format!("{width} x {height} pixels is not a usable plate")));
    }
    let rgba = img.to_rgba32f();
    let linear = |v: f32| {
        let v = if v.is_finite() { v.max(0.0) } else { 0.0 };
        if is_float { v } else { srgb_decode(v) }
    };
    let pixels = rgba.pixels().map(|p| [linear(p[0]), linear(p[1]), linear(p[2]), 1.0]).collect();
    Ok(HdrImage { width, height, pixels })
}
