//! `flarelab render`'s flags, in the groups `--help` shows them in, and the one map from flags to the document's
//! fields.
//!
//! Each group is a struct flattened into [`RenderArgs`] with its own heading: the optics (shared with `classify`
//! and `bake`), the light, the look, the camera, colour, the shot, depth of field, the method and the output.
//! [`FLAGS`] lists every flag that sets a field of the document ([`Document`]), in the order [`document`] applies
//! them after the preset and LENS: each entry says which fields it sets (as `Document::check` names them), how
//! the user gave it (for a refusal's message: `--spectrum 99: ...`) and how it sets them. A flag that sets
//! nothing of the document (the method, the output, the frame range) is read where it is used.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::ValueEnum;
use flare_core::color::Tonemap;
use flare_core::frame::parse_size;
use flare_core::lut::blend::BlendMode;
use flare_core::preset::{Document, LutSource};

use crate::cli::common::{
    DeviceArg, MethodArg, OpticsChoice, parse_aperture, parse_dirt, parse_pair_f64, parse_pair_u32,
};

/// Every flag of `flarelab render`, by group.
#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// The document: LENS, --preset (a .json file or a shipped name: `flarelab preset list`), --coating and
    /// --f-number; the other flags override its fields too.
    #[command(flatten)]
    pub optics: OpticsChoice,
    #[command(flatten)]
    pub stop: StopFlags,
    #[command(flatten)]
    pub light: LightFlags,
    #[command(flatten)]
    pub look: LookFlags,
    #[command(flatten)]
    pub camera: CameraFlags,
    #[command(flatten)]
    pub colour: ColourFlags,
    #[command(flatten)]
    pub shot: ShotFlags,
    #[command(flatten)]
    pub dof: DofFlags,
    #[command(flatten)]
    pub method: MethodFlags,
    #[command(flatten)]
    pub output: OutputFlags,
}

/// The stop and the spectrum, beside the lens, the preset, the coating and the f-number.
#[derive(clap::Args, Debug)]
#[command(next_help_heading = "Optics")]
pub struct StopFlags {
    /// Aperture: circle, blades:N[:ROTATION_DEG[:ROUNDNESS]], or image:PATH (grayscale).
    #[arg(long)]
    pub aperture: Option<String>,
    /// Wavelengths: 3 is RGB (650/510/475 nm), 2..32 are CIE-weighted, 1 is the d-line alone.
    #[arg(long)]
    pub spectrum: Option<usize>,
}

/// Where the light is, and how it is found in a plate.
#[derive(clap::Args, Debug)]
#[command(next_help_heading = "Light")]
pub struct LightFlags {
    /// Where the light appears in the frame, as horizontal and vertical field angles in degrees.
    #[arg(long, allow_hyphen_values = true, value_parser = parse_pair_f64)]
    pub light_deg: Option<(f64, f64)>,
    /// Where the light is: found in the plate (auto), or the keys.
    #[arg(id = "light", long = "light", value_name = "LIGHT", value_enum)]
    pub source: Option<LightArg>,
    /// A tracker's 2D track of the light: CSV rows `frame,x_px,y_px[,intensity_ev]`, pixels of the frame from
    /// its top-left corner, y down (a header row is fine); they become light keys.
    #[arg(long)]
    pub track: Option<PathBuf>,
    /// --light auto: the luminance above which a plate pixel belongs to the light (default 4; an 8-bit plate
    /// clips at 1).
    #[arg(id = "light_threshold", long = "light-threshold", value_name = "LIGHT_THRESHOLD")]
    pub threshold: Option<f64>,
    /// --light auto: the light's unoccluded power (sum of its luminance; default: the largest in the range).
    #[arg(id = "light_power", long = "light-power", value_name = "LIGHT_POWER")]
    pub power: Option<f64>,
    /// --light auto: an optional denoise of the measured visibility over this many frames, odd (default 1:
    /// none, the flare follows each frame's visibility).
    #[arg(id = "light_smooth", long = "light-smooth", value_name = "LIGHT_SMOOTH")]
    pub smooth: Option<usize>,
}

/// The flare's look: exposures in stops, the starburst, dirt on the front element.
#[derive(clap::Args, Debug)]
#[command(next_help_heading = "Look")]
pub struct LookFlags {
    /// The flare's exposure in stops (its relative irradiance times 2^EV; ghosts are ~1e-6 to 1e-2 of the light),
    /// or `auto`: the brightest ghost at a fixed display level, from the optics (default: the preset's choice,
    /// auto for the default document).
    #[arg(long, allow_negative_numbers = true, value_parser = parse_exposure)]
    pub exposure_ev: Option<Exposure>,
    /// The background plate's exposure in stops (0: as shot).
    #[arg(long, allow_negative_numbers = true)]
    pub plate_ev: Option<f64>,
    /// Replaced by --exposure-ev (stops); refused with the conversion.
    #[arg(long, hide = true, allow_negative_numbers = true)]
    pub exposure: Option<f64>,
    /// Leave out the starburst at the light.
    #[arg(long)]
    pub no_starburst: bool,
    /// The starburst's brightness in stops relative to the physical one (default: the preset's, 0).
    #[arg(long, allow_negative_numbers = true)]
    pub starburst_ev: Option<f64>,
    /// Dirt on the front element: none, dust[:SEED], smudges[:SEED], haze, or image:PATH (grey, white is dirt);
    /// it scatters a share of the light into a glow (default: the preset's, none).
    #[arg(long)]
    pub dirt: Option<String>,
    /// The share of the light the dirt scatters where it is densest, 0 to 1 (default: the preset's, 0.01).
    #[arg(long)]
    pub dirt_amount: Option<f64>,
    /// The dirt's scattering lobe, its half width at half peak in degrees (0.5 to 60; default 8).
    #[arg(long)]
    pub dirt_spread_deg: Option<f64>,
}

/// The camera around the lens: its sensor, the delivered squeeze and the shutter.
#[derive(clap::Args, Debug)]
#[command(next_help_heading = "Camera")]
pub struct CameraFlags {
    /// The sensor width the frame (and the plate) spans, in mm (default: the preset's, 36).
    #[arg(long)]
    pub sensor_mm: Option<f64>,
    /// Deliver the frame desqueezed: the sensor stretched along x by X (1/4 to 4; the frame is drawn on the
    /// sensor at X times --size's rows, or 1/X times its columns below 1, then averaged down), or `auto` for an
    /// anamorphic lens's own squeeze EFL_y / EFL_x (default: the preset's, 1).
    #[arg(long)]
    pub desqueeze: Option<String>,
    /// The shutter in degrees (default: the preset's, 0): a light that moves while it is open streaks its
    /// ghosts (180: open half of each frame, the streak is half the light's motion per frame).
    #[arg(long, allow_negative_numbers = true)]
    pub shutter_deg: Option<f64>,
}

/// How the frame is displayed: the OCIO view or one of FlareLab's curves, and the plates' colour space.
#[derive(clap::Args, Debug)]
#[command(next_help_heading = "Colour")]
pub struct ColourFlags {
    /// How the frame is displayed: view, the OCIO display and view (default), or one of FlareLab's own curves
    /// followed by the sRGB encoding (none, reinhard, aces: Narkowicz's fit), which bypass the view and looks.
    #[arg(long, value_enum)]
    pub tonemap: Option<TonemapArg>,
    /// OCIO config: a .ocio/.ocioz file or a built-in ocio://NAME (default: ocio://studio-config-latest).
    #[arg(long)]
    pub ocio_config: Option<String>,
    /// OCIO display (default: the config's).
    #[arg(long)]
    pub display: Option<String>,
    /// OCIO view of the display (default: the display's).
    #[arg(long)]
    pub view: Option<String>,
    /// OCIO looks applied before the view, comma-separated.
    #[arg(id = "look", long = "look", value_name = "LOOK")]
    pub looks: Option<String>,
    /// A .cube (or other LUT file OCIO reads) applied as a look, in the config's color_timing space.
    #[arg(long)]
    pub cube: Option<PathBuf>,
    /// The colour space of plate files (an OCIO colour space, or `display` for the inverse of the display and
    /// view: a plate at 0 EV with no flare then comes out as shot). Default: by file type.
    #[arg(long)]
    pub input_space: Option<String>,
}

/// The shot: the plate under the flare and the frames of the timeline drawn.
#[derive(clap::Args, Debug)]
#[command(next_help_heading = "Shot")]
pub struct ShotFlags {
    /// Background plate (PNG is taken as sRGB, EXR and HDR as linear), shown under the flare at --plate-ev; a
    /// sequence when it has a frame field (`plates/shot.####.exr` or `%04d`).
    #[arg(long)]
    pub background: Option<PathBuf>,
    /// Render the frames A-B of the timeline (or one frame N) as a sequence; -o must have a frame field
    /// (`out/flare.####.exr` or `%04d`).
    #[arg(long, allow_hyphen_values = true, value_parser = parse_frames)]
    pub frames: Option<(i64, i64)>,
    /// The timeline frame of a still (default: the timeline's first frame).
    #[arg(long, allow_negative_numbers = true, conflicts_with = "frames")]
    pub frame: Option<i64>,
    /// A sequence: one JSON record per frame (frame, light_px, light_deg, visibility, ms, status).
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// A sequence: leave frames whose file exists as they are (resume a stopped render).
    #[arg(long)]
    pub skip_existing: bool,
    /// A sequence on the CPU twin: draw the frames one after another instead of in parallel (to measure).
    #[arg(long, hide = true)]
    pub frames_in_turn: bool,
}

/// Depth of field: the plate defocused through the lens's own aperture from a depth map.
#[derive(clap::Args, Debug)]
#[command(next_help_heading = "Depth of field")]
pub struct DofFlags {
    /// Depth of field: the plate's depth map (EXR in metres, channel Z; a sequence when it has a frame field):
    /// the plate is defocused through the lens's own aperture before the flare is added.
    #[arg(long)]
    pub depth: Option<String>,
    /// Depth of field: NEAR:FAR metres of a 16-bit PNG depth map.
    #[arg(long, value_parser = flare_core::dof::depth::PngRange::parse)]
    pub depth_range: Option<flare_core::dof::depth::PngRange>,
    /// Depth of field: the focus distance from the entrance pupil (m).
    #[arg(long)]
    pub focus_m: Option<f64>,
    /// Depth of field: focus on the depth at this plate pixel, X,Y from the top-left.
    #[arg(long, value_parser = parse_pair_u32)]
    pub focus_px: Option<(u32, u32)>,
    /// Depth of field: live (layered gather, the default) or reference (every pixel's kernel scattered).
    #[arg(long, value_enum)]
    pub dof_method: Option<MethodArg>,
    /// Depth of field: each of R, G and B defocused at its own wavelength (axial colour).
    #[arg(long)]
    pub axial_colour: bool,
    /// Leave the depth of field off even when the preset has it on.
    #[arg(long)]
    pub no_dof: bool,
}

/// How the ghosts are made and where the frame is drawn.
#[derive(clap::Args, Debug)]
#[command(next_help_heading = "Method")]
pub struct MethodFlags {
    /// How the ghosts are made (default: blended or photo when the preset uses a LUT, else paraxial).
    #[arg(id = "method", long = "method", value_name = "METHOD", value_enum)]
    pub kind: Option<Method>,
    /// LUT file (.flut) for --method blended or photo.
    #[arg(long)]
    pub lut: Option<PathBuf>,
    /// How LUT ghosts blend with the paraxial flare: additive, alpha, linear:FROM:TO or smooth:FROM:TO (degrees).
    #[arg(long)]
    pub blend: Option<String>,
    /// Grid cells across each ghost's entrance region, for raygrid and reference.
    #[arg(long)]
    pub grid: Option<usize>,
    /// Ray grids on the GPU: 0 (the default) box-filters every triangle exactly in a compute pass, as the CPU
    /// does; 1 to 8 rasterise the triangles at N x N samples a pixel and average them (the earlier path, kept to
    /// compare).
    #[arg(long, default_value_t = flare_core::render::raygrid::SUPERSAMPLE)]
    pub gpu_samples: u32,
    /// Most relative irradiance culling may take from any pixel: the faintest sprites are culled while their peaks sum
    /// to at most this (default: a quarter of an 8-bit step at the exposure).
    #[arg(long)]
    pub threshold: Option<f64>,
    /// Accumulate ghosts at 1/N resolution (1, 2 or 4) and upsample: faster on software adapters, a little softer.
    #[arg(long, default_value_t = 1)]
    pub accumulation_divisor: u32,
    /// Where to draw.
    #[arg(long, value_enum, default_value = "auto")]
    pub device: DeviceArg,
}

/// What is written, at what size, in which form.
#[derive(clap::Args, Debug)]
#[command(next_help_heading = "Output")]
pub struct OutputFlags {
    /// Output image, .png (tonemapped) or .exr (linear, layered); with --frames, a pattern such as
    /// `out/flare.####.exr`.
    #[arg(short = 'o', long = "out", alias = "output")]
    pub out: PathBuf,
    /// Image size, e.g. 1280x720 (default: the plate's size, else 1280x720).
    #[arg(long, value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// EXR values: auto (half where a layer's values fit, as the ghost layers do; float for the layers holding
    /// the light's core), half (values beyond 65504 clamped) or float. Default: the preset's, auto.
    #[arg(long, value_enum)]
    pub exr_type: Option<ExrTypeArg>,
    /// EXR compression: none, rle, zips, zip (default), piz, pxr24 (DWAA/DWAB and B44/B44A are not written).
    #[arg(long, value_parser = parse_exr_compression)]
    pub exr_compression: Option<flare_core::output::ExrCompression>,
    /// Extra EXR layers (ghosts: one layer per drawn ghost).
    #[arg(long, value_enum)]
    pub layers: Option<Layers>,
    /// Print where the command's time went (reading, preparing the lens, the frame's passes, writing), in
    /// milliseconds of wall time.
    #[arg(long)]
    pub timings: bool,
}

/// How the ghosts are made.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Method {
    /// Paraxial sprites (live).
    Paraxial,
    /// Paraxial sprites with LUT ghosts (--lut, the preset's LUT, or baked in memory).
    Blended,
    /// A photo LUT played back alone (--lut).
    Photo,
    /// Hullin 2011: a coarse grid of exactly traced rays per ghost (needs --grid).
    Raygrid,
    /// The ray-traced ground truth (--grid defaults to the converged size).
    Reference,
}

/// Where the light is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum LightArg {
    /// Found in the plate on every frame: the brightest region above --light-threshold, its visibility
    /// driving the flare's intensity.
    Auto,
    /// The timeline's light keys (or the static light): turns off a preset's auto light.
    Keys,
}

/// Tonemap operators by name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TonemapArg {
    /// The OCIO display and view (--display, --view; the default).
    View,
    None,
    Reinhard,
    Aces,
}

impl From<TonemapArg> for Tonemap {
    fn from(t: TonemapArg) -> Self {
        match t {
            TonemapArg::View => Tonemap::View,
            TonemapArg::None => Tonemap::None,
            TonemapArg::Reinhard => Tonemap::Reinhard,
            TonemapArg::Aces => Tonemap::Aces,
        }
    }
}

/// Extra EXR layers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Layers {
    /// One layer per drawn ghost, `ghost_I_J.R/G/B`.
    Ghosts,
}

/// `--exr-type`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ExrTypeArg {
    Auto,
    Half,
    Float,
}

impl From<ExrTypeArg> for flare_core::output::ExrPixel {
    fn from(t: ExrTypeArg) -> Self {
        match t {
            ExrTypeArg::Auto => Self::Auto,
            ExrTypeArg::Half => Self::Half,
            ExrTypeArg::Float => Self::Float,
        }
    }
}

fn parse_exr_compression(s: &str) -> Result<flare_core::output::ExrCompression, String> {
    flare_core::output::ExrCompression::parse(s)
}

/// `--exposure-ev`: automatic, or a number of stops (which locks it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Exposure {
    Auto,
    Stops(f64),
}

fn parse_exposure(s: &str) -> Result<Exposure, String> {
    if s.eq_ignore_ascii_case("auto") {
        return Ok(Exposure::Auto);
    }
    match s.trim().parse::<f64>() {
        Ok(ev) if ev.is_finite() => Ok(Exposure::Stops(ev)),
        _ => Err(format!("`{s}` is neither `auto` nor a number of stops")),
    }
}

/// Parses `A-B` or `N` (frames may be negative: `-5--1`).
fn parse_frames(s: &str) -> Result<(i64, i64), String> {
    let bad = || format!("`{s}` is not a frame range A-B (or one frame N)");
    if let Ok(n) = s.trim().parse::<i64>() {
        return Ok((n, n));
    }
    let split = s.char_indices().skip(1).find(|&(_, c)| c == '-').map(|(i, _)| i).ok_or_else(bad)?;
    let (a, b) = (s[..split].trim().parse::<i64>(), s[split + 1..].trim().parse::<i64>());
    match (a, b) {
        (Ok(a), Ok(b)) if a <= b => flare_core::timeline::check_frame_count(a, b).map(|()| (a, b)),
        (Ok(a), Ok(b)) => Err(format!("`{s}`: the range runs backwards ({a} > {b})")),
        _ => Err(bad()),
    }
}

/// One flag and the fields of the document it sets: an entry of [`FLAGS`].
pub struct FlagField {
    /// The document's fields the flag sets, as `Document::check` names them in a refusal.
    pub fields: &'static [&'static str],
    /// The flag as the user gave it (`--spectrum 99`; LENS as its file name), `None` when it was not given.
    pub given: fn(&RenderArgs) -> Option<String>,
    /// Sets the fields from the flag; called only when it was given, in the order of [`FLAGS`].
    pub apply: fn(&RenderArgs, &mut Document) -> Result<()>,
}

/// `"--flag value"` when the flag has a value.
fn shown<T: std::fmt::Display>(flag: &str, value: Option<T>) -> Option<String> {
    value.map(|v| format!("{flag} {v}"))
}

/// An entry of [`FLAGS`] for a flag whose value is the field's: `value!("--plate-ev", "plate_ev", look.plate_ev
/// => plate_ev)` sets `doc.plate_ev` to `--plate-ev`'s value; `value!(..., Some)` sets an optional field to
/// `Some` of it.
macro_rules! value {
    ($flag:literal, $field:literal, $($arg:ident).+ => $($doc:ident).+ $(, $wrap:ident)?) => {
        FlagField {
            fields: &[$field],
            given: |a| shown($flag, a.$($arg).+.as_ref()),
            apply: |a, d| {
                if let Some(v) = &a.$($arg).+ {
                    d.$($doc).+ = $($wrap)?(v.clone());
                }
                Ok(())
            },
        }
    };
}

/// The flags the preset's fields come from, in the order [`document`] applies them. LENS, --coating and
/// --f-number are applied first, with --preset, by [`OpticsChoice::document`] (shared with `classify` and
/// `bake`): their entries name them for refusals only.
pub const FLAGS: &[FlagField] = &[
    FlagField { fields: &["lens"], given: |a| a.optics.file.clone(), apply: |_, _| Ok(()) },
    FlagField {
        fields: &["aperture.f_number"],
        given: |a| shown("--f-number", a.optics.f_number),
        apply: |_, _| Ok(()),
    },
    FlagField {
        fields: &["light_deg"],
        given: |a| a.light.light_deg.map(|(x, y)| format!("--light-deg {x},{y}")),
        apply: |a, d| {
            if let Some((x, y)) = a.light.light_deg {
                d.light_deg = [x, y];
            }
            Ok(())
        },
    },
    FlagField {
        fields: &["aperture", "aperture.roundness"],
        given: |a| shown("--aperture", a.stop.aperture.as_ref()),
        apply: |a, d| {
            if let Some(spec) = &a.stop.aperture {
                let f_number = a.optics.f_number.or(d.aperture.f_number);
                d.aperture = parse_aperture(spec, f_number)?;
            }
            Ok(())
        },
    },
    value!("--spectrum", "wavelengths", stop.spectrum => wavelengths),
    FlagField {
        fields: &["flare_ev"],
        given: |a| match a.look.exposure_ev? {
            Exposure::Stops(ev) => Some(format!("--exposure-ev {ev}")),
            Exposure::Auto => None,
        },
        apply: |a, d| {
            if let Some(Exposure::Stops(ev)) = a.look.exposure_ev {
                (d.flare_ev, d.exposure_auto) = (ev, false);
            }
            Ok(())
        },
    },
    FlagField {
        // `--exposure-ev auto` sets no value a refusal could name.
        fields: &[],
        given: |a| matches!(a.look.exposure_ev, Some(Exposure::Auto)).then(|| "--exposure-ev auto".to_owned()),
        apply: |_, d| {
            d.exposure_auto = true;
            Ok(())
        },
    },
    value!("--plate-ev", "plate_ev", look.plate_ev => plate_ev),
    FlagField {
        fields: &["tonemap"],
        given: |a| a.colour.tonemap.map(|t| format!("--tonemap {t:?}").to_lowercase()),
        apply: |a, d| {
            if let Some(t) = a.colour.tonemap {
                d.tonemap = t.into();
            }
            Ok(())
        },
    },
    FlagField {
        fields: &["starburst"],
        given: |a| a.look.no_starburst.then(|| "--no-starburst".to_owned()),
        apply: |_, d| {
            d.starburst = false;
            Ok(())
        },
    },
    value!("--starburst-ev", "starburst_ev", look.starburst_ev => starburst_ev),
    FlagField {
        fields: &["desqueeze"],
        given: |a| shown("--desqueeze", a.camera.desqueeze.as_ref()),
        apply: |a, d| {
            let Some(spec) = &a.camera.desqueeze else { return Ok(()) };
            d.desqueeze = match spec.as_str() {
                "auto" => {
                    flare_core::optics::FirstOrder::d_line(&d.lens).ok().and_then(|fo| fo.squeeze()).with_context(
                        || format!("--desqueeze auto: {} is not anamorphic (no squeeze to undo)", d.lens.id),
                    )?
                }
                number => {
                    number.parse().with_context(|| format!("--desqueeze {spec}: a number from 0.25 to 4, or auto"))?
                }
            };
            Ok(())
        },
    },
    FlagField {
        fields: &["dirt.image"],
        given: |a| shown("--dirt", a.look.dirt.as_ref()),
        apply: |a, d| a.look.dirt.as_ref().map_or(Ok(()), |spec| parse_dirt(spec, &mut d.dirt)),
    },
    value!("--dirt-amount", "dirt.amount", look.dirt_amount => dirt.amount),
    value!("--dirt-spread-deg", "dirt.spread_deg", look.dirt_spread_deg => dirt.spread_deg),
    FlagField {
        fields: &["background"],
        given: |a| shown("--background", a.shot.background.as_ref().map(|b| b.display())),
        apply: |a, d| {
            d.background = a.shot.background.as_ref().map(|p| p.display().to_string());
            Ok(())
        },
    },
    value!("--sensor-mm", "sensor_width_mm", camera.sensor_mm => sensor_width_mm),
    value!("--ocio-config", "color.config", colour.ocio_config => color.config, Some),
    FlagField {
        fields: &["color.display"],
        given: |a| shown("--display", a.colour.display.as_ref()),
        apply: |a, d| {
            d.color.display = a.colour.display.clone();
            // Another display: its own default view, unless one is given (--view, applied next).
            d.color.view = None;
            Ok(())
        },
    },
    value!("--view", "color.view", colour.view => color.view, Some),
    value!("--look", "color.looks", colour.looks => color.looks, Some),
    value!("--input-space", "color.input_space", colour.input_space => color.input_space, Some),
    FlagField {
        fields: &["color.cube"],
        given: |a| shown("--cube", a.colour.cube.as_ref().map(|c| c.display())),
        apply: |a, d| {
            d.color.cube = a.colour.cube.as_ref().map(|c| c.display().to_string());
            Ok(())
        },
    },
    FlagField {
        fields: &["exr.pixel_type"],
        given: |a| a.output.exr_type.map(|t| format!("--exr-type {t:?}").to_lowercase()),
        apply: |a, d| {
            if let Some(t) = a.output.exr_type {
                d.exr.pixel_type = t.into();
            }
            Ok(())
        },
    },
    FlagField {
        fields: &["exr.compression"],
        given: |a| a.output.exr_compression.map(|c| format!("--exr-compression {c:?}").to_lowercase()),
        apply: |a, d| {
            d.exr.compression = a.output.exr_compression.unwrap_or(d.exr.compression);
            Ok(())
        },
    },
    value!("--shutter-deg", "timeline.shutter_deg", camera.shutter_deg => timeline.shutter_deg),
    FlagField {
        fields: &["dof.depth"],
        given: |a| shown("--depth", a.dof.depth.as_ref()),
        apply: |a, d| {
            d.dof.enabled = true;
            d.dof.depth = a.dof.depth.clone();
            Ok(())
        },
    },
    FlagField {
        fields: &[],
        given: |a| a.dof.depth_range.map(|_| "--depth-range".to_owned()),
        apply: |a, d| {
            d.dof.depth_range_m = a.dof.depth_range;
            Ok(())
        },
    },
    FlagField {
        fields: &["dof.focus_m"],
        given: |a| shown("--focus-m", a.dof.focus_m),
        apply: |a, d| {
            d.dof.focus_m = a.dof.focus_m.unwrap_or(d.dof.focus_m);
            d.dof.focus_px = None;
            Ok(())
        },
    },
    FlagField {
        fields: &[],
        given: |a| a.dof.focus_px.map(|(x, y)| format!("--focus-px {x},{y}")),
        apply: |a, d| {
            d.dof.focus_px = a.dof.focus_px.map(|(x, y)| [x, y]).or(d.dof.focus_px);
            Ok(())
        },
    },
    FlagField {
        fields: &[],
        given: |a| a.dof.dof_method.map(|m| format!("--dof-method {m:?}").to_lowercase()),
        apply: |a, d| {
            if let Some(method) = a.dof.dof_method {
                d.dof.method = method.into();
            }
            Ok(())
        },
    },
    FlagField {
        fields: &[],
        given: |a| a.dof.axial_colour.then(|| "--axial-colour".to_owned()),
        apply: |_, d| {
            d.dof.axial_colour = true;
            Ok(())
        },
    },
    FlagField {
        fields: &[],
        given: |a| a.dof.no_dof.then(|| "--no-dof".to_owned()),
        apply: |_, d| {
            d.dof.enabled = false;
            Ok(())
        },
    },
    FlagField {
        fields: &[],
        given: |a| a.light.source.map(|l| format!("--light {l:?}").to_lowercase()),
        apply: |a, d| {
            match a.light.source {
                Some(LightArg::Auto) => _ = d.auto_light.get_or_insert_with(Default::default),
                Some(LightArg::Keys) => d.auto_light = None,
                None => {}
            }
            Ok(())
        },
    },
    FlagField {
        fields: &["auto_light.threshold"],
        given: |a| shown("--light-threshold", a.light.threshold),
        apply: |a, d| {
            auto_light(d)?.threshold = a.light.threshold.unwrap_or_default();
            Ok(())
        },
    },
    FlagField {
        fields: &["auto_light.reference_power"],
        given: |a| shown("--light-power", a.light.power),
        apply: |a, d| {
            auto_light(d)?.reference_power = a.light.power;
            Ok(())
        },
    },
    FlagField {
        fields: &["auto_light.smooth_frames"],
        given: |a| shown("--light-smooth", a.light.smooth),
        apply: |a, d| {
            auto_light(d)?.smooth_frames = a.light.smooth.unwrap_or_default();
            Ok(())
        },
    },
    value!("--threshold", "cull_threshold", method.threshold => cull_threshold, Some),
    FlagField {
        fields: &["blend.mode"],
        given: |a| shown("--blend", a.method.blend.as_ref()),
        apply: |a, d| {
            let Some(mode) = &a.method.blend else { return Ok(()) };
            BlendMode::parse(mode).map_err(|e| anyhow::anyhow!("--blend {e}"))?;
            d.blend.mode = mode.clone();
            Ok(())
        },
    },
    FlagField {
        fields: &[],
        given: |a| shown("--lut", a.method.lut.as_ref().map(|p| p.display())),
        apply: |a, d| {
            let path = a.method.lut.as_ref().map(|p| p.display().to_string());
            d.blend.lut = LutSource::Simulated { path };
            Ok(())
        },
    },
];

/// The document's light found in the plate, which --light-threshold, --light-power and --light-smooth tune.
fn auto_light(doc: &mut Document) -> Result<&mut flare_core::footage::detect::AutoLight> {
    doc.auto_light.as_mut().context("--light-threshold, --light-power and --light-smooth apply to --light auto")
}

/// The document `args` describe: the preset (or the default), then LENS, then every flag given ([`FLAGS`], in
/// order), checked; a refused value is named by the flag that set it.
pub fn document(args: &RenderArgs) -> Result<Document> {
    if let Some(linear) = args.look.exposure {
        let stops = if linear > 0.0 { format!("--exposure-ev {:.2}", linear.log2()) } else { "--exposure-ev".into() };
        bail!("--exposure {linear}: exposures are in stops now; use {stops}");
    }
    let mut doc = args.optics.document()?;
    for flag in FLAGS.iter().filter(|f| (f.given)(args).is_some()) {
        (flag.apply)(args, &mut doc)?;
    }
    doc.check().map_err(|e| match &e {
        flare_core::preset::PresetError::Value { field, reason } => match flag_of(args, field) {
            Some(flag) => anyhow::anyhow!("{}: {reason}", flare_core::files::shorten_numbers(&flag)),
            None => anyhow::anyhow!("{e}"),
        },
        _ => anyhow::anyhow!("{e}"),
    })?;
    Ok(doc)
}

/// The flag of `args` that set the document's `field` ([`FLAGS`]), if one did.
pub fn flag_of(args: &RenderArgs, field: &str) -> Option<String> {
    FLAGS.iter().filter(|f| f.fields.contains(&field)).find_map(|f| (f.given)(args))
}
