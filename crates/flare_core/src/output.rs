//! Image files: the one writer of every frame FlareLab writes (`write_frame`: PNG, 8-bit display values;
//! OpenEXR, linear with named layers), and the reader of background plates ([`read_plate`]).
//!
//! # How it works
//! A PNG holds the display image: the composite `plate x 2^plate_ev + flare x 2^flare_ev` through the
//! document's display transform ([`crate::view_transform`]). An EXR holds the same frame linear, in the working
//! space [`WORKING_SPACE`] (named in a `colorspace` and an `oiio:ColorSpace` attribute, its primaries in
//! `chromaticities`): the default layer `R, G, B, A` is the composite (alpha 1), `flare.R/G/B` the flare alone
//! (ghosts, LUT ghosts, starburst and the front dirt's glow, to be added over a plate), `starburst.R/G/B` its
//! starburst, `dirt.R/G/B` its dirt glow (a dirty lens only),
//! `plate.R/G/B` the exposed plate when there is one; with ghost layers (`ExrLayers`, each made as its
//! ghost is drawn) the file has several parts: those layers in the part `rgba`, and one part `ghost_I_J` per
//! ghost whose data window is the smallest rectangle holding its lit pixels. Values are 16- or 32-bit floats as
//! [`ExrSettings::pixel_type`] says ([`ExrPixel::Auto`]: half for a layer whose values all fit half's range,
//! else float), compressed as [`ExrSettings::compression`] says (ZIP by default). A value that is not finite is
//! written as the largest finite value of its sign (+infinity, an overflow, stays the brightest value instead
//! of turning black), NaN as 0 (none should reach here). Every file is written through
//! [`crate::files::write_atomic`]: a temporary file in the target's folder renamed over it, so a failed write
//! leaves nothing half-written. [`read_exr_channels`] reads every part of an EXR back, placed in its display
//! window. Plates: PNG and JPEG are decoded from sRGB to linear, EXR and HDR are taken as linear
//! (`read_plate_values` also gives a file's own values, for an OCIO input space to convert).
//!
//! Every image FlareLab reads (plates, depth maps, aperture images, photo LUTs) goes through `open_image`
//! (or, for a depth map's EXR, `exr_size`) first: the size is read from the header and refused past
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
    /// A plate refused by `open_image` (its message names the file and the reason).
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
    /// The front dirt's glow, its share of the flare (`None` for a clean lens: no layer).
    pub dirt: Option<HdrImage>,
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
pub(crate) fn write_frame(path: &Path, display: &DisplayImage, layers: Option<&FrameLayers>) -> Result<(), ImageError> {
    match ImageKind::from_path(path)? {
        ImageKind::Png => write_png(path, display),
        ImageKind::Exr => match layers {
            Some(layers) => write_exr_layers(path, layers, ExrSettings::default()),
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

/// How an EXR stores its values (`--exr-type`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ExrPixel {
    /// Each layer 16-bit float when all its values fit half's range (at most [`HALF_MAX`]), else 32-bit: the
    /// ghost layers (and a plate) are half, the composite, flare and starburst that hold the light's core
    /// (millions at the default exposure) stay float.
    #[default]
    Auto,
    /// Every layer 16-bit float; values beyond [`HALF_MAX`] (the light's core) are clamped to it.
    Half,
    /// Every layer 32-bit float.
    Float,
}

impl ExrPixel {
    pub const ALL: [Self; 3] = [Self::Auto, Self::Half, Self::Float];

    /// The name on the command line and in presets.
    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Half => "half",
            Self::Float => "float",
        }
    }
}

/// The largest finite 16-bit float.
pub const HALF_MAX: f32 = 65504.0;

/// How an EXR's pixels are compressed (`--exr-compression`): the methods the `exr` crate writes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ExrCompression {
    None,
    Rle,
    /// ZIP, one scan line a block.
    Zips,
    /// ZIP, 16 scan lines a block (lossless; the default).
    #[default]
    Zip,
    /// Wavelet (lossless), good on noisy plates.
    Piz,
    /// Lossy for 32-bit floats (24 bits kept), lossless for half.
    Pxr24,
    /// Lossy 4x4 blocks of half floats: named so that a preset naming it is refused with the reason
    /// ([`ExrCompression::refusal`]), never written.
    B44,
    /// B44 with flat blocks stored smaller: refused like [`Self::B44`].
    B44a,
}

impl ExrCompression {
    /// The compressions written (B44 and B44A are refused: [`Self::refusal`]).
    pub const ALL: [Self; 6] = [Self::None, Self::Rle, Self::Zips, Self::Zip, Self::Piz, Self::Pxr24];

    /// Why this compression is not written, if it is not. The `exr` crate's B44 encoder (issue 61) panicked
    /// on a rayon thread, aborting the process, for any part one pixel tall and about 50 wide (a thin streak
    /// ghost's layer), and where it wrote it lost values: half's largest value 65504 came back 0, the plate's
    /// negatives 0, and 640 of the 772 channels of a still with ghost layers were off by all of their peak
    /// (OpenEXR's own B44 on the same pixels: at most 16 %). So B44 and B44A are refused up front, for every
    /// layer, rather than written wrong.
    pub fn refusal(self) -> Option<String> {
        matches!(self, Self::B44 | Self::B44a).then(|| {
            format!(
                "`{}`: B44 compression is not written here (the exr crate's B44 encoder loses values, 65504 and \
                 negatives among them, and fails on one-pixel-tall layers); use zip or piz (lossless) or pxr24 \
                 (lossy)",
                self.name()
            )
        })
    }

    /// The name on the command line and in presets.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Rle => "rle",
            Self::Zips => "zips",
            Self::Zip => "zip",
            Self::Piz => "piz",
            Self::Pxr24 => "pxr24",
            Self::B44 => "b44",
            Self::B44a => "b44a",
        }
    }

    /// The compression called `name`; DWAA and DWAB are refused with the reason (the `exr` crate reads them
    /// but cannot write them).
    pub fn parse(name: &str) -> Result<Self, String> {
        let key = name.trim().to_ascii_lowercase();
        if key == "dwaa" || key == "dwab" {
            return Err(format!(
                "`{key}`: DWA compression cannot be written here (the exr crate reads it but has no encoder); use \
                 zip or piz (lossless) or pxr24 (lossy)"
            ));
        }
        if let Some(refusal) = [Self::B44, Self::B44a].into_iter().find(|c| c.name() == key).and_then(Self::refusal) {
            return Err(refusal);
        }
        Self::ALL.into_iter().find(|c| c.name() == key).ok_or_else(|| {
            format!(
                "`{}`: not an EXR compression ({})",
                crate::files::shorten(name),
                Self::ALL.map(Self::name).join(", ")
            )
        })
    }

    fn exr(self) -> exr::prelude::Compression {
        use exr::prelude::Compression as C;
        match self {
            Self::None => C::Uncompressed,
            Self::Rle => C::RLE,
            Self::Zips => C::ZIP1,
            Self::Zip => C::ZIP16,
            Self::Piz => C::PIZ,
            Self::Pxr24 => C::PXR24,
            Self::B44 => C::B44,
            Self::B44a => C::B44A,
        }
    }
}

/// How EXR files are written: the value type and the compression (a document's `exr`, shared by the app
/// and the command line).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct ExrSettings {
    pub pixel_type: ExrPixel,
    pub compression: ExrCompression,
}

/// The colour space every linear layer is in: FlareLab's working space (its OCIO name, as OpenImageIO
/// writes it in a `colorspace` attribute), with its primaries and white in the `chromaticities` attribute.
pub const WORKING_SPACE: &str = "Linear Rec.709 (sRGB)";

/// The Rec. 709 primaries and D65 white of [`WORKING_SPACE`].
fn rec709() -> exr::meta::attribute::Chromaticities {
    use exr::math::Vec2;
    exr::meta::attribute::Chromaticities {
        red: Vec2(0.64, 0.33),
        green: Vec2(0.30, 0.60),
        blue: Vec2(0.15, 0.06),
        white: Vec2(0.3127, 0.3290),
    }
}

/// A value for a file: NaN is 0, an infinity the largest finite value of its sign.
fn finite(v: f32) -> f32 {
    if v.is_nan() { 0.0 } else { v.clamp(-f32::MAX, f32::MAX) }
}

/// The channels `names` of `values` (one per channel, each `width x height` in rows) at `pixel`: half where
/// `pixel` says so or, for [`ExrPixel::Auto`], when every value fits half's range.
fn typed_channels(
    names: &[String],
    values: Vec<Vec<f32>>,
    pixel: ExrPixel,
) -> Vec<exr::prelude::AnyChannel<exr::prelude::FlatSamples>> {
    use exr::prelude::{AnyChannel, FlatSamples, f16};
    let fits = values.iter().flatten().all(|v| v.abs() <= HALF_MAX);
    let half = match pixel {
        ExrPixel::Half => true,
        ExrPixel::Float => false,
        ExrPixel::Auto => fits,
    };
    names
        .iter()
        .zip(values)
        .map(|(name, v)| {
            let samples = if half {
                FlatSamples::F16(v.into_iter().map(|x| f16::from_f32(x.clamp(-HALF_MAX, HALF_MAX))).collect())
            } else {
                FlatSamples::F32(v)
            };
            AnyChannel::new(name.as_str(), samples)
        })
        .collect()
}

/// The EXR channels of one layer (`prefix` empty: the default layer), RGB, optionally alpha: half where `pixel`
/// says so or, for [`ExrPixel::Auto`], when every value of the layer fits half's range ([`typed_channels`]'s
/// rule), each channel made in one pass over the pixels, in parallel.
fn channels(
    prefix: &str,
    image: &HdrImage,
    alpha: bool,
    pixel: ExrPixel,
) -> Vec<exr::prelude::AnyChannel<exr::prelude::FlatSamples>> {
    use exr::prelude::{AnyChannel, FlatSamples, f16};
    use rayon::prelude::*;
    let name = |c: &str| if prefix.is_empty() { c.to_owned() } else { format!("{prefix}.{c}") };
    let count = if alpha { 4 } else { 3 };
    let half = match pixel {
        ExrPixel::Half => true,
        ExrPixel::Float => false,
        ExrPixel::Auto => image.pixels.par_iter().all(|p| p[..count].iter().all(|&v| finite(v).abs() <= HALF_MAX)),
    };
    (0..count)
        .map(|k| {
            let values = image.pixels.par_iter().map(move |p| finite(p[k]));
            let samples = if half {
                FlatSamples::F16(values.map(|x| f16::from_f32(x.clamp(-HALF_MAX, HALF_MAX))).collect())
            } else {
                FlatSamples::F32(values.collect())
            };
            AnyChannel::new(name(["R", "G", "B", "A"][k]).as_str(), samples)
        })
        .collect()
}

/// Writes one linear image with no tonemap: an EXR's default layer `R, G, B, A` (32-bit), or an 8-bit sRGB
/// PNG of the values clamped to [0, 1] (a plate written as it was read: `flarelab dof`'s output).
pub fn write_linear(path: &Path, image: &HdrImage) -> Result<(), ImageError> {
    match ImageKind::from_path(path)? {
        ImageKind::Png => {
            let encode8 = |v: f32| {
                (crate::color::srgb_encode(if v.is_finite() { v.clamp(0.0, 1.0) } else { 0.0 }) * 255.0).round() as u8
            };
            let pixels = image.pixels.iter().map(|p| [encode8(p[0]), encode8(p[1]), encode8(p[2]), 255]).collect();
            write_png(path, &DisplayImage { width: image.width, height: image.height, pixels })
        }
        ImageKind::Exr => {
            let list = channels("", image, true, ExrPixel::Float);
            write_exr_parts(path, (image.width, image.height), ExrSettings::default(), list, Vec::new())
        }
    }
}

/// Writes one float channel named `name` as an EXR (a depth map's `Z`, in metres).
pub fn write_exr_channel(path: &Path, w: u32, h: u32, name: &str, values: &[f32]) -> Result<(), ImageError> {
    if values.len() != w as usize * h as usize {
        return Err(encode(path, format!("{} values for {w}x{h} pixels", values.len())));
    }
    // No image holds a NaN or an infinity (an infinity as the largest float of its sign).
    let samples = values.iter().map(|&v| finite(v)).collect();
    let list = typed_channels(&[name.to_owned()], vec![samples], ExrPixel::Float);
    write_exr_parts(path, (w, h), ExrSettings::default(), list, Vec::new())
}

/// One ghost layer of an EXR: its own part, whose data window covers only its lit pixels.
struct GhostPart {
    name: String,
    origin: (u32, u32),
    size: (u32, u32),
    list: Vec<exr::prelude::AnyChannel<exr::prelude::FlatSamples>>,
}

/// An EXR being put together a layer at a time ([`Self::add_ghost`] takes each ghost layer as it is drawn
/// and keeps only its channels, cropped to its lit pixels), then written whole ([`Self::write`]).
pub(crate) struct ExrLayers {
    width: u32,
    height: u32,
    settings: ExrSettings,
    list: Vec<exr::prelude::AnyChannel<exr::prelude::FlatSamples>>,
    ghosts: Vec<GhostPart>,
}

impl ExrLayers {
    /// The frame's own layers (composite, flare, starburst, plate) at `settings`.
    pub fn new(layers: &FrameLayers, settings: ExrSettings) -> Self {
        let pixel = settings.pixel_type;
        let mut list = channels("", &layers.composite, true, pixel);
        list.extend(channels("flare", &layers.flare, false, pixel));
        list.extend(channels("starburst", &layers.starburst, false, pixel));
        if let Some(dirt) = &layers.dirt {
            list.extend(channels("dirt", dirt, false, pixel));
        }
        if let Some(plate) = &layers.plate {
            list.extend(channels("plate", plate, false, pixel));
        }
        Self { width: layers.composite.width, height: layers.composite.height, settings, list, ghosts: Vec::new() }
    }

    /// A ghost layer `name.R/G/B` in a part of its own whose data window is the smallest rectangle holding
    /// every pixel it lights (a pixel at the top-left corner when it lights none); the image can be dropped.
    pub fn add_ghost(&mut self, name: &str, image: &HdrImage) {
        let (w, h) = (image.width, image.height);
        let lit = |p: &[f32; 4]| p[..3].iter().any(|&v| finite(v) != 0.0);
        let (mut x0, mut y0, mut x1, mut y1) = (w, h, 0, 0);
        for y in 0..h {
            for x in 0..w {
                if lit(&image.pixels[(y * w + x) as usize]) {
                    (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x + 1), y1.max(y + 1));
                }
            }
        }
        if x0 >= x1 || y0 >= y1 {
            (x0, y0, x1, y1) = (0, 0, 1.min(w), 1.min(h));
        }
        let names: Vec<String> = ["R", "G", "B"].iter().map(|c| format!("{name}.{c}")).collect();
        let values = (0..3)
            .map(|k| {
                (y0..y1)
                    .flat_map(|y| (x0..x1).map(move |x| (x, y)))
                    .map(|(x, y)| finite(image.pixels[(y * w + x) as usize][k]))
                    .collect()
            })
            .collect();
        let list = typed_channels(&names, values, self.settings.pixel_type);
        self.ghosts.push(GhostPart { name: name.to_owned(), origin: (x0, y0), size: (x1 - x0, y1 - y0), list });
    }

    /// Writes the file through a temporary file: one part without ghost layers, else the frame's part
    /// (`rgba`) and one part per ghost layer (see the module documentation).
    pub fn write(self, path: &Path) -> Result<(), ImageError> {
        write_exr_parts(path, (self.width, self.height), self.settings, self.list, self.ghosts)
    }
}

/// Writes the layers as an EXR (see the module documentation).
pub fn write_exr_layers(path: &Path, layers: &FrameLayers, settings: ExrSettings) -> Result<(), ImageError> {
    let mut exr = ExrLayers::new(layers, settings);
    for (name, image) in &layers.ghosts {
        exr.add_ghost(name, image);
    }
    exr.write(path)
}

/// Writes `list` as an EXR part of `w` x `h` pixels, and each of `ghosts` as a part of its own (a multi-part
/// file then), compressed as `settings` says, the working space named in the header, through a temporary file.
fn write_exr_parts(
    path: &Path,
    size: (u32, u32),
    settings: ExrSettings,
    list: Vec<exr::prelude::AnyChannel<exr::prelude::FlatSamples>>,
    ghosts: Vec<GhostPart>,
) -> Result<(), ImageError> {
    if let Some(refusal) = settings.compression.refusal() {
        return Err(ImageError::Encode { path: path.display().to_string(), message: refusal });
    }
    let bytes = encode_exr(&exr_image(size, settings, list, ghosts)).map_err(|message| encode(path, message))?;
    write_atomic(path, &bytes).map_err(|e| io(path, e))
}

/// The EXR image of [`write_exr_parts`], not yet encoded.
type ExrImage = exr::prelude::Image<
    exr::prelude::SmallVec<[exr::prelude::Layer<exr::prelude::AnyChannels<exr::prelude::FlatSamples>>; 2]>,
>;

/// The parts of [`write_exr_parts`] as one image, its compression whatever `settings` says (refused ones
/// included: the caller refuses them).
fn exr_image(
    (w, h): (u32, u32),
    settings: ExrSettings,
    list: Vec<exr::prelude::AnyChannel<exr::prelude::FlatSamples>>,
    ghosts: Vec<GhostPart>,
) -> ExrImage {
    use exr::math::Vec2;
    use exr::meta::attribute::{AttributeValue, Text};
    use exr::prelude::{
        AnyChannels, Blocks, Encoding, Image, ImageAttributes, Layer, LayerAttributes, LineOrder, SmallVec,
    };
    let encoding = Encoding {
        compression: settings.compression.exr(),
        blocks: Blocks::ScanLines,
        line_order: LineOrder::Increasing,
    };
    let mut attributes = ImageAttributes::with_size((w as usize, h as usize));
    attributes.chromaticities = Some(rec709());
    for key in ["colorspace", "oiio:ColorSpace"] {
        attributes.other.insert(Text::from(key), AttributeValue::Text(Text::from(WORKING_SPACE)));
    }
    let main_attributes = if ghosts.is_empty() { LayerAttributes::default() } else { LayerAttributes::named("rgba") };
    let mut parts = SmallVec::new();
    parts.push(Layer::new(
        (w as usize, h as usize),
        main_attributes,
        encoding,
        AnyChannels::sort(SmallVec::from_vec(list)),
    ));
    for ghost in ghosts {
        let mut attributes = LayerAttributes::named(ghost.name.as_str());
        attributes.layer_position = Vec2(ghost.origin.0 as i32, ghost.origin.1 as i32);
        parts.push(Layer::new(
            (ghost.size.0 as usize, ghost.size.1 as usize),
            attributes,
            encoding,
            AnyChannels::sort(SmallVec::from_vec(ghost.list)),
        ));
    }
    Image::from_layers(attributes, parts)
}

/// How many blocks [`encode_exr`] compresses at once: enough to keep every core busy, few enough that the
/// uncompressed copies stay a small part of the image (a ZIP block is 16 scan lines).
const BLOCKS_PER_BATCH: usize = 256;

/// The bytes of `image` as an EXR file. Its blocks are compressed on the current rayon pool (all cores: the
/// `exr` crate's own parallel writer builds a new thread pool for every file and aborts the process when a
/// compressor panics on one of its threads), in batches of [`BLOCKS_PER_BATCH`], and written in the file's
/// order. A compressor that panics is contained ([`contain_panic`]) and the file refused with its message.
fn encode_exr(image: &ExrImage) -> Result<Vec<u8>, String> {
    use exr::block::writer::ChunksWriter;
    use exr::image::write::layers::{LayersWriter, WritableLayers};
    use exr::prelude::WritableImage;
    use rayon::prelude::*;
    let headers = image.write().infer_meta_data();
    let layers = image.layer_data.create_writer(&headers);
    let mut bytes = Vec::new();
    exr::block::write(Cursor::new(&mut bytes), headers, true, |meta, chunks| {
        let mut blocks =
            meta.collect_ordered_block_data(|index| layers.extract_uncompressed_block(&meta.headers, index));
        loop {
            let batch: Vec<_> = blocks.by_ref().take(BLOCKS_PER_BATCH).collect();
            if batch.is_empty() {
                return Ok(());
            }
            let compressed: Vec<_> = batch
                .into_par_iter()
                .map(|(index, block)| {
                    contain_panic(|| block.compress_to_chunk(&meta.headers))
                        .map_err(|message| {
                            exr::error::Error::Invalid(format!("the compressor failed: {message}").into())
                        })
                        .and_then(|chunk| chunk.map(|chunk| (index, chunk)))
                })
                .collect();
            for result in compressed {
                let (index, chunk) = result?;
                chunks.write_chunk(index, chunk)?;
            }
        }
    })
    .map_err(|e| e.to_string())?;
    Ok(bytes)
}

thread_local! {
    /// Whether this thread is inside [`contain_panic`].
    static CONTAINING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Whether a panic on this thread is being contained (a compressor of `write_frame`'s EXR): a process's
/// panic hook stays quiet for it (the panic becomes an error that names it instead of an "internal error").
pub fn panic_is_contained() -> bool {
    CONTAINING.with(|c| c.get())
}

/// `work()`, or its panic's message as an error: for code of other crates that panics on input it cannot
/// handle (the `exr` crate's compressors), so that a panic on a rayon thread becomes a refusal instead of
/// aborting the process.
fn contain_panic<T>(work: impl FnOnce() -> T) -> Result<T, String> {
    let outer = CONTAINING.with(|c| c.replace(true));
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(work));
    CONTAINING.with(|c| c.set(outer));
    result.map_err(|payload| {
        let message = panic_message(payload.as_ref()).unwrap_or_else(|| "a panic".to_owned());
        crate::files::shorten(&message.replace('\n', " "))
    })
}

/// A panic's message, when its payload is text (`panic!` with a literal or a format).
pub fn panic_message(payload: &(dyn std::any::Any + Send)) -> Option<String> {
    payload.downcast_ref::<&str>().map(|s| (*s).to_owned()).or_else(|| payload.downcast_ref::<String>().cloned())
}

/// Every channel of an EXR written by FlareLab (or any scan-line EXR), read from every part and placed in
/// the file's display window at its part's data window (zero outside it): what a compositor sees.
#[derive(Clone, Debug, PartialEq)]
pub struct ExrChannels {
    pub width: u32,
    pub height: u32,
    /// Channel name (`flare.R`, `ghost_2_5.G`, ...) to its values, row by row.
    pub channels: std::collections::BTreeMap<String, Vec<f32>>,
    /// Per part: its name (if any), data window origin and size, and its channels' sample types (16 or 32).
    pub parts: Vec<ExrPart>,
}

/// One part of an EXR as read back.
#[derive(Clone, Debug, PartialEq)]
pub struct ExrPart {
    pub name: Option<String>,
    pub origin: (i32, i32),
    pub size: (usize, usize),
    pub bits: Vec<(String, u32)>,
}

/// The most bytes [`read_exr_channels`] spends on the channels it places at the display window's size.
pub(crate) const MAX_READ_CHANNEL_BYTES: u64 = 2 << 30;

/// Reads every channel of every part of `path` (see [`ExrChannels`]); refused, before any pixel is read,
/// past [`MAX_IMAGE_SIDE_PX`] a side (the display window or any part) or when its channels at the display
/// window's size would take more than `MAX_READ_CHANNEL_BYTES`.
pub fn read_exr_channels(path: &Path) -> Result<ExrChannels, ImageError> {
    use exr::prelude::{FlatSamples, read_all_flat_layers_from_file};
    let refuse = |reason: String| ImageError::Plate(format!("{}: {reason}", path.display()));
    crate::files::open_regular(path).map_err(ImageError::Plate)?;
    let meta =
        exr::meta::MetaData::read_from_file(path, false).map_err(|e| refuse(format!("cannot read the EXR: {e}")))?;
    let first = meta.headers.first().ok_or_else(|| refuse("the EXR has no image in it".into()))?;
    let display = first.shared_attributes.display_window;
    check_side(path, "EXR", display.size.0 as u64, display.size.1 as u64).map_err(ImageError::Plate)?;
    let mut count = 0u64;
    for header in &meta.headers {
        check_side(path, "EXR part", header.layer_size.width() as u64, header.layer_size.height() as u64)
            .map_err(ImageError::Plate)?;
        count += header.channels.list.len() as u64;
    }
    let (w, h) = (display.size.0, display.size.1);
    let need = count * w as u64 * h as u64 * 4;
    if need > MAX_READ_CHANNEL_BYTES {
        return Err(refuse(format!(
            "{count} channels at {w}x{h} need {:.1} GB, more than the {:.1} GB allowed",
            need as f64 / 1e9,
            MAX_READ_CHANNEL_BYTES as f64 / 1e9
        )));
    }
    let image = read_all_flat_layers_from_file(path)
        .map_err(|e| ImageError::Decode { path: path.display().to_string(), message: e.to_string() })?;
    let display = image.attributes.display_window;
    let (dx, dy) = (display.position.0, display.position.1);
    let mut channels = std::collections::BTreeMap::new();
    let mut parts = Vec::new();
    for layer in &image.layer_data {
        let origin = (layer.attributes.layer_position.0, layer.attributes.layer_position.1);
        let size = (layer.size.0, layer.size.1);
        let mut bits = Vec::new();
        for channel in &layer.channel_data.list {
            let name = channel.name.to_string();
            bits.push((name.clone(), if matches!(channel.sample_data, FlatSamples::F16(_)) { 16 } else { 32 }));
            let full = channels.entry(name).or_insert_with(|| vec![0.0f32; w * h]);
            for (k, v) in channel.sample_data.values_as_f32().enumerate() {
                let (x, y) = (origin.0 - dx + (k % size.0) as i32, origin.1 - dy + (k / size.0) as i32);
                if x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h {
                    full[y as usize * w + x as usize] = v;
                }
            }
        }
        parts.push(ExrPart { name: layer.attributes.layer_name.as_ref().map(|n| n.to_string()), origin, size, bits });
    }
    Ok(ExrChannels { width: w as u32, height: h as u32, channels, parts })
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
        // The exr crate reads the header alone (the image crate checks the chunk table first). A plate is decoded
        // at its display window (the data window padded out to it): that is its size.
        let (_, (w, h)) = exr_windows(path, what)?;
        return Ok((w as u32, h as u32));
    }
    crate::files::open_regular(path)?;
    let reader = ::image::ImageReader::open(path)
        .map_err(|e| format!("{}: cannot read the {what}: {e}", path.display()))?
        .with_guessed_format()
        .map_err(|e| format!("{}: cannot read the {what}: {e}", path.display()))?;
    let (w, h) = reader.into_dimensions().map_err(|e| format!("{}: cannot read the {what}: {e}", path.display()))?;
    check_side(path, what, w as u64, h as u64)?;
    Ok((w, h))
}

/// The data and display windows an EXR's first header states, read from its bytes (the first 64 KiB), for a
/// message when the `exr` crate refuses the header ("display window 1073741824 x 1073741824 pixels").
fn raw_exr_windows(path: &Path) -> Option<String> {
    use std::io::Read;
    let mut head = Vec::new();
    crate::files::open_regular(path).ok()?.take(1 << 16).read_to_end(&mut head).ok()?;
    let mut said = Vec::new();
    for (name, words) in
        [(&b"dataWindow\0box2i\0"[..], "data window"), (&b"displayWindow\0box2i\0"[..], "display window")]
    {
        let at = head.windows(name.len()).position(|w| w == name)? + name.len() + 4;
        let int =
            |k: usize| Some(i64::from(i32::from_le_bytes(head.get(at + 4 * k..at + 4 * k + 4)?.try_into().ok()?)));
        let (x0, y0, x1, y1) = (int(0)?, int(1)?, int(2)?, int(3)?);
        said.push(format!("{words} {} x {} pixels", x1 - x0 + 1, y1 - y0 + 1));
    }
    Some(said.join(", "))
}

/// The size of an EXR from its header alone, checked as [`image_size`] does (for readers that use the `exr`
/// crate directly: a depth map's channel).
pub(crate) fn exr_size(path: &Path, what: &str) -> Result<(usize, usize), String> {
    exr_windows(path, what).map(|(data, _)| data)
}

/// A width and a height in pixels.
type SizePx = (usize, usize);

/// The data window's and the display window's sizes of an EXR, from one read of its header, each checked as
/// [`exr_size`] says.
fn exr_windows(path: &Path, what: &str) -> Result<(SizePx, SizePx), String> {
    crate::files::open_regular(path)?;
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| {
        // The crate's reason names no size: the windows as the header states them, when it can be read.
        let windows = raw_exr_windows(path).map_or(String::new(), |w| format!(" ({w})"));
        format!("{}: cannot read the {what}: {e}{windows}", path.display())
    })?;
    let header = meta.headers.first().ok_or_else(|| format!("{}: the {what} has no image in it", path.display()))?;
    // The decoder pads the data window out to the display window: both are checked (issue 61: a 3.6 KB EXR of
    // 16x16 pixels in an 8192x8192 display window passed the check and aborted at 5.4 GB).
    let display = header.shared_attributes.display_window.size;
    check_side(path, &format!("{what}'s display window"), display.0 as u64, display.1 as u64)?;
    let (w, h) = (header.layer_size.width(), header.layer_size.height());
    check_side(path, what, w as u64, h as u64)?;
    Ok(((w, h), (display.0, display.1)))
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

/// The grey values of the image in `path` ([`open_image`]) resampled to `size` x `size` (triangle filter), row
/// by row from the top, in [0, 1]: what aperture and dirt images are read as. Each pixel is brought into [0, 1]
/// before the resampling (NaN as 0, +inf as 1): a NaN or an infinity once spread through the filter to the
/// whole image, and an aperture of white pixels beside one NaN was refused as "black everywhere" (issue 61).
pub(crate) fn read_grey_square(path: &Path, what: &str, size: usize) -> Result<Vec<f32>, String> {
    let mut gray = open_image(path, what)?.to_luma32f();
    for v in gray.iter_mut() {
        *v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
    }
    let resized = ::image::imageops::resize(&gray, size as u32, size as u32, ::image::imageops::FilterType::Triangle);
    Ok(resized.into_raw().into_iter().map(|v| if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) }).collect())
}

/// Decodes the image in `path` after checking its header ([`image_size`]), the decoder limited to the same
/// size and to 1.5 GiB of allocations.
pub(crate) fn open_image(path: &Path, what: &str) -> Result<::image::DynamicImage, String> {
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
    read_plate_values(path, true)
}

/// A plate's pixels: with `decode`, PNG and JPEG decoded from sRGB (EXR and HDR as stored), else every file's
/// values as stored (a PNG's encoded ones in [0, 1], for an OCIO input space to convert); clamped as
/// [`read_plate`] says, with what it clamped in words.
pub(crate) fn read_plate_values(path: &Path, decode: bool) -> Result<(HdrImage, Option<String>), ImageError> {
    let img = open_image(path, "plate").map_err(ImageError::Plate)?;
    let is_float =
        !decode || matches!(img, ::image::DynamicImage::ImageRgb32F(_) | ::image::DynamicImage::ImageRgba32F(_));
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Channels `R, G, B` of `w` x `h` half pixels of a ramp.
    fn ramp(prefix: &str, w: u32, h: u32) -> Vec<exr::prelude::AnyChannel<exr::prelude::FlatSamples>> {
        let names: Vec<String> = ["R", "G", "B"].iter().map(|c| format!("{prefix}{c}")).collect();
        let values = (0..3).map(|k| (0..w * h).map(|i| (i + k) as f32 * 0.25).collect()).collect();
        typed_channels(&names, values, ExrPixel::Half)
    }

    /// Issue 61: the `exr` crate's B44 compressor panics for a part of half values one pixel tall and 193 or
    /// more wide ("range end index ... out of range"), and on a thread of its own pool that aborted the process. The compressors now run on rayon's pool under
    /// [`contain_panic`]: the same parts (B44 is refused before this point in every real path) give an error
    /// naming the panic, and the test process lives on to say so.
    #[test]
    fn a_compressor_that_panics_on_a_pool_thread_is_an_error_not_an_abort() {
        let settings = ExrSettings { pixel_type: ExrPixel::Half, compression: ExrCompression::B44 };
        let ghosts = (0..12)
            .map(|i| GhostPart {
                name: format!("ghost_{i}"),
                origin: (0, i),
                size: (256, 1),
                list: ramp(&format!("ghost_{i}."), 256, 1),
            })
            .collect();
        let image = exr_image((256, 64), settings, ramp("", 256, 64), ghosts);
        let pool = rayon::ThreadPoolBuilder::new().num_threads(4).build().expect("a pool");
        let Err(error) = pool.install(|| encode_exr(&image)) else { panic!("B44 on 256x1 parts was written") };
        assert!(error.contains("the compressor failed: range end index"), "{error}");
        assert!(!panic_is_contained(), "the flag is put back");
    }

    /// Every compression that is written comes back exactly (the lossless ones and half values under PXR24)
    /// through the encoder's own batches, a multi-part file with more blocks than one batch included.
    #[test]
    fn the_parallel_encoder_writes_what_the_reader_reads() {
        let dir = tempfile::tempdir().expect("a folder");
        for compression in ExrCompression::ALL {
            let settings = ExrSettings { pixel_type: ExrPixel::Half, compression };
            let ghosts = vec![GhostPart {
                name: "ghost_1_2".into(),
                origin: (3, 5),
                size: (7, 2),
                list: ramp("ghost_1_2.", 7, 2),
            }];
            let path = dir.path().join(format!("{}.exr", compression.name()));
            write_exr_parts(&path, (40, 4200), settings, ramp("", 40, 4200), ghosts).expect("written");
            let back = read_exr_channels(&path).expect("read");
            assert_eq!(back.parts.len(), 2, "{}", compression.name());
            let r = &back.channels["R"];
            assert!((0..40 * 4200).all(|i| r[i] == f16_of(i as f32 * 0.25)), "{}", compression.name());
            let g = &back.channels["ghost_1_2.G"];
            assert_eq!(g[5 * 40 + 3], 0.25, "{}", compression.name());
            assert_eq!(g[6 * 40 + 9], (7 + 6 + 1) as f32 * 0.25, "{}", compression.name());
        }
    }

    fn f16_of(v: f32) -> f32 {
        exr::prelude::f16::from_f32(v).to_f32()
    }
}
