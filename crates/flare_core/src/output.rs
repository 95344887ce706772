//! Image files: the one writer of every frame FlareLab writes ([`write_frame`]: PNG, 8-bit sRGB tonemapped;
//! OpenEXR, linear float with named layers), and the reader of background plates ([`read_plate`]).
//!
//! # How it works
//! A PNG holds the display image: the composite `plate x 2^plate_ev + flare x 2^flare_ev`, tonemapped and
//! sRGB-encoded. An EXR holds the same frame linear, in one part whose channels compositors group by the
//! prefix before the dot: the default layer `R, G, B, A` is the composite (alpha 1), `flare.R/G/B` the flare
//! alone (ghosts, LUT ghosts and starburst, to be added over a plate), `starburst.R/G/B` its starburst,
//! `plate.R/G/B` the exposed plate when there is one, and `ghost_I_J.R/G/B` one layer per drawn ghost when
//! asked for (16-bit float, each made as its ghost is drawn: [`ExrLayers`]). The other channels are 32-bit float, ZIP-compressed; a value that is not finite is written as the largest
//! finite float of its sign (+infinity, an overflow, stays the brightest value instead of turning black), NaN as
//! 0 (none should reach here). Every file is written through [`crate::files::write_atomic`]: a temporary file in the
//! target's folder renamed over it, so a failed write leaves nothing half-written. Plates: PNG and JPEG are
//! decoded from sRGB to linear, EXR and Radiance HDR are taken as linear.
//!
//! Every image FlareLab reads (plates, depth maps, aperture images, photo LUTs) goes through [`open_image`]
//! (or, for a depth map's EXR, [`exr_size`]) first: the size is read from the header and refused past
//! [`MAX_IMAGE_SIDE_PX`] a side (the frame's own limit, `--size`) before any pixel is decoded, and the decoder
//! runs with limits to match, so no file can ask for more than about 1 GiB of pixels. A plate's values that
//! are not finite or too large to expose are clamped to [`MAX_PLATE_VALUE`] (the flare is never lost from the
//! composite), NaN and negative ones to 0, and [`read_plate_checked`] says how many it clamped.

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
    // The cause is part of the message and deliberately not a `source`: a chain printed with its sources
    // would say it twice.
    #[error("{path}: {error}")]
    Io { path: String, error: std::io::Error },
    #[error("{path}: cannot read the image: {message}")]
    Decode { path: String, message: String },
    #[error("{path}: unknown image type (use .png or .exr)")]
    Extension { path: String },
    /// A plate refused by [`open_image`] (its message names the file and the reason).
    #[error("{0}")]
    Plate(String),
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

fn io(path: &Path, error: std::io::Error) -> ImageError {
    ImageError::Io { path: path.display().to_string(), error }
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
    let finite = |v: f32| if v.is_nan() { 0.0 } else { v.clamp(-f32::MAX, f32::MAX) };
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

/// An EXR being put together a layer at a time ([`Self::add_ghost`] takes each ghost layer as it is drawn
/// and keeps only its channels), then written whole ([`Self::write`]).
pub struct ExrLayers {
    width: u32,
    height: u32,
    list: Vec<exr::prelude::AnyChannel<exr::prelude::FlatSamples>>,
}

impl ExrLayers {
    /// The frame's own layers (composite, flare, starburst, plate), 32-bit float.
    pub fn new(layers: &FrameLayers) -> Self {
        let mut list = channels("", &layers.composite, true);
        list.extend(channels("flare", &layers.flare, false));
        list.extend(channels("starburst", &layers.starburst, false));
        if let Some(plate) = &layers.plate {
            list.extend(channels("plate", plate, false));
        }
        Self { width: layers.composite.width, height: layers.composite.height, list }
    }

    /// A ghost layer `name.R/G/B` as 16-bit float (the usual depth of a compositor's passes, 3 significant
    /// digits; 6 bytes a pixel, so the zoom's 254 ghost layers fit at 1920x1080); the image can be dropped.
    pub fn add_ghost(&mut self, name: &str, image: &HdrImage) {
        use exr::prelude::{AnyChannel, FlatSamples, f16};
        for k in 0..3 {
            let samples = image.pixels.iter().map(|p| f16::from_f32(if p[k].is_nan() { 0.0 } else { p[k] })).collect();
            self.list
                .push(AnyChannel::new(format!("{name}.{}", ["R", "G", "B"][k]).as_str(), FlatSamples::F16(samples)));
        }
    }

    /// Writes the part through a temporary file (see the module documentation).
    pub fn write(self, path: &Path) -> Result<(), ImageError> {
        write_exr_channels(path, self.width, self.height, self.list)
    }
}

/// Writes the layers as one EXR part (see the module documentation).
pub fn write_exr_layers(path: &Path, layers: &FrameLayers) -> Result<(), ImageError> {
    let mut exr = ExrLayers::new(layers);
    for (name, image) in &layers.ghosts {
        exr.add_ghost(name, image);
    }
    exr.write(path)
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

/// The largest side of any image FlareLab reads (pixels): the frame's own limit (`--size`), so a plate never
/// makes a frame the command line could not draw, and a header cannot ask for more than 8192 x 8192 pixels.
pub const MAX_IMAGE_SIDE_PX: u32 = 8192;

/// The largest plate value kept: a value above it (or +infinity) is clamped to it, so the plate exposed by up
/// to +64 EV stays finite in f32 and the flare is never lost from the composite.
pub const MAX_PLATE_VALUE: f32 = f32::MAX / 1.9e19;

/// The size of the image in `path` from its header alone (no pixel decoded), refused past
/// [`MAX_IMAGE_SIDE_PX`] a side or when empty. `what` names the image in the message ("plate", "depth map").
pub fn image_size(path: &Path, what: &str) -> Result<(u32, u32), String> {
    if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr")) {
        // The exr crate reads the header alone (the image crate checks the chunk table first).
        let (w, h) = exr_size(path, what)?;
        return Ok((w as u32, h as u32));
    }
    let reader = ::image::ImageReader::open(path)
        .map_err(|e| format!("{}: cannot read the {what}: {e}", path.display()))?
        .with_guessed_format()
        .map_err(|e| format!("{}: cannot read the {what}: {e}", path.display()))?;
    let (w, h) = reader.into_dimensions().map_err(|e| format!("{}: cannot read the {what}: {e}", path.display()))?;
    check_side(path, what, w as u64, h as u64)?;
    Ok((w, h))
}

/// The size of an EXR from its header alone, checked as [`image_size`] does (for readers that use the `exr`
/// crate directly: a depth map's channel).
pub fn exr_size(path: &Path, what: &str) -> Result<(usize, usize), String> {
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| format!("{}: cannot read the {what}: {e}", path.display()))?;
    let header = meta.headers.first().ok_or_else(|| format!("{}: the {what} has no image in it", path.display()))?;
    let (w, h) = (header.layer_size.width(), header.layer_size.height());
    check_side(path, what, w as u64, h as u64)?;
    Ok((w, h))
}

fn check_side(path: &Path, what: &str, w: u64, h: u64) -> Result<(), String> {
    let max = u64::from(MAX_IMAGE_SIDE_PX);
    if w == 0 || h == 0 || w > max || h > max {
        return Err(format!(
            "{}: the {what} is {w} x {h} pixels; FlareLab reads images of 1 to {max} pixels a side",
            path.display()
        ));
    }
    Ok(())
}

/// Decodes the image in `path` after checking its header ([`image_size`]), the decoder limited to the same
/// size and to 1.5 GiB of allocations.
pub fn open_image(path: &Path, what: &str) -> Result<::image::DynamicImage, String> {
    image_size(path, what)?;
    let mut reader = ::image::ImageReader::open(path)
        .and_then(|r| r.with_guessed_format())
        .map_err(|e| format!("{}: cannot read the {what}: {e}", path.display()))?;
    let mut limits = ::image::Limits::default();
    limits.max_image_width = Some(MAX_IMAGE_SIDE_PX);
    limits.max_image_height = Some(MAX_IMAGE_SIDE_PX);
    limits.max_alloc = Some(3 << 29);
    reader.limits(limits);
    reader.decode().map_err(|e| format!("{}: cannot read the {what}: {e}", path.display()))
}

/// Reads a background plate (PNG and JPEG are decoded from sRGB to linear; EXR and Radiance HDR are taken as
/// linear), 1 to [`MAX_IMAGE_SIDE_PX`] pixels a side; values clamped as the module documentation says.
pub fn read_plate(path: &Path) -> Result<HdrImage, ImageError> {
    read_plate_checked(path).map(|(plate, _)| plate)
}

/// [`read_plate`], with what it clamped in words (said once, by the caller), if anything.
pub fn read_plate_checked(path: &Path) -> Result<(HdrImage, Option<String>), ImageError> {
    let img = open_image(path, "plate").map_err(ImageError::Plate)?;
    let is_float = matches!(img, ::image::DynamicImage::ImageRgb32F(_) | ::image::DynamicImage::ImageRgba32F(_));
    let (width, height) = (img.width(), img.height());
    let clamped = std::cell::Cell::new(0usize);
    let linear = |v: f32| {
        let v = if is_float { v } else { srgb_decode(v) };
        if v.is_nan() || v <= 0.0 {
            0.0
        } else if v > MAX_PLATE_VALUE {
            clamped.set(clamped.get() + 1);
            MAX_PLATE_VALUE
        } else {
            v
        }
    };
    // Straight from the decoded pixels to the plate's (no RGBA float copy of the whole image in between: at
    // 8192 x 8192 that copy alone was 1 GiB).
    let to_plate = |c: [f32; 3]| [linear(c[0]), linear(c[1]), linear(c[2]), 1.0];
    let byte = |v: u8| f32::from(v) / 255.0;
    let word = |v: u16| f32::from(v) / 65535.0;
    use ::image::DynamicImage as D;
    let pixels: Vec<[f32; 4]> = match &img {
        D::ImageRgb8(i) => i.pixels().map(|p| to_plate(p.0.map(byte))).collect(),
        D::ImageRgba8(i) => i.pixels().map(|p| to_plate([byte(p[0]), byte(p[1]), byte(p[2])])).collect(),
        D::ImageLuma8(i) => i.pixels().map(|p| to_plate([byte(p[0]); 3])).collect(),
        D::ImageRgb16(i) => i.pixels().map(|p| to_plate(p.0.map(word))).collect(),
        D::ImageRgba16(i) => i.pixels().map(|p| to_plate([word(p[0]), word(p[1]), word(p[2])])).collect(),
        D::ImageLuma16(i) => i.pixels().map(|p| to_plate([word(p[0]); 3])).collect(),
        D::ImageRgb32F(i) => i.pixels().map(|p| to_plate(p.0)).collect(),
        D::ImageRgba32F(i) => i.pixels().map(|p| to_plate([p[0], p[1], p[2]])).collect(),
        other => other.to_rgba32f().pixels().map(|p| to_plate([p[0], p[1], p[2]])).collect(),
    };
    drop(img);
    let n = clamped.into_inner();
    let warning = (n > 0).then(|| {
        format!(
            "{}: {n} plate values were infinite or above {MAX_PLATE_VALUE:.1e}, clamped to it (so exposing the \
             plate cannot overflow)",
            path.display()
        )
    });
    Ok((HdrImage { width, height, pixels }, warning))
}
