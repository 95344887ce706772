//! `flarelab render`: a preset's frame (or the default document's) with flags that override its fields, drawn
//! by the one frame pipeline and written by the one writer.
//!
//! The document comes from `--preset` (a file or a shipped name) or is the default one, the same the app
//! starts with; LENS replaces its lens; each flag given replaces one field. The frame is then built from the
//! document exactly as the app builds it ([`flare_core::preset::Document::frame_request`],
//! [`flare_core::frame::Frame::build`]) and drawn on the GPU or its CPU twin; the ray-traced methods replace
//! only the ghosts' accumulation and go through the same writer.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::ValueEnum;
use flare_core::color::Tonemap;
use flare_core::flare::PreparedFlare;
use flare_core::frame::{self, Device, Frame, Sources};
use flare_core::lut::blend::{BlendMode, LiveLut};
use flare_core::lut::format;
use flare_core::lut::{GhostLut, LutKind};
use flare_core::output::read_plate;
use flare_core::preset::{Document, LutSource};
use flare_core::raytrace::{self};

use flare_core::footage::pattern::FramePattern;
use flare_core::frame::parse_size;
use flare_core::shot::{
    self,
    sequence::{FrameOutcome, SequenceOptions, ShotSources, render_sequence, write_log},
    track::read_track,
};
use flare_core::traced::TracedGhosts;
use indicatif::{ProgressBar, ProgressStyle};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use super::common::{DeviceArg, OpticsChoice, parse_aperture, parse_pair_f64};

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

#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// The document: LENS, --preset (a .json file or a shipped name: `flarelab preset list`), --coating and
    /// --f-number; the other flags override its fields too.
    #[command(flatten)]
    pub optics: OpticsChoice,
    /// Where the light appears in the frame, as horizontal and vertical field angles in degrees.
    #[arg(long, allow_hyphen_values = true, value_parser = parse_pair_f64)]
    pub light_deg: Option<(f64, f64)>,
    /// Image size, e.g. 1280x720 (default: the plate's size, else 1280x720).
    #[arg(long, value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// Render the frames A-B of the timeline (or one frame N) as a sequence; -o must have a frame field
    /// (`out/flare.####.exr` or `%04d`).
    #[arg(long, allow_hyphen_values = true, value_parser = parse_frames)]
    pub frames: Option<(i64, i64)>,
    /// The timeline frame of a still (default: the timeline's first frame).
    #[arg(long, allow_negative_numbers = true, conflicts_with = "frames")]
    pub frame: Option<i64>,
    /// Where the light is: found in the plate (auto), or the keys.
    #[arg(long, value_enum)]
    pub light: Option<LightArg>,
    /// A tracker's 2D track of the light: CSV rows `frame,x_px,y_px[,intensity_ev]`, pixels of the frame from
    /// its top-left corner, y down (a header row is fine); they become light keys.
    #[arg(long)]
    pub track: Option<PathBuf>,
    /// The sensor width the frame (and the plate) spans, in mm (default: the preset's, 36).
    #[arg(long)]
    pub sensor_mm: Option<f64>,
    /// --light auto: the luminance above which a plate pixel belongs to the light (default 4; an 8-bit plate
    /// clips at 1).
    #[arg(long)]
    pub light_threshold: Option<f64>,
    /// --light auto: the light's unoccluded power (sum of its luminance; default: the largest in the range).
    #[arg(long)]
    pub light_power: Option<f64>,
    /// --light auto: an optional denoise of the measured visibility over this many frames, odd (default 1:
    /// none, the flare follows each frame's visibility).
    #[arg(long)]
    pub light_smooth: Option<usize>,
    /// EXR values: auto (half where a layer's values fit, as the ghost layers do; float for the layers holding
    /// the light's core), half (values beyond 65504 clamped) or float. Default: the preset's, auto.
    #[arg(long, value_enum)]
    pub exr_type: Option<ExrTypeArg>,
    /// EXR compression: none, rle, zips, zip (default), piz, pxr24 (DWAA/DWAB and B44/B44A are not written).
    #[arg(long, value_parser = parse_exr_compression)]
    pub exr_compression: Option<flare_core::output::ExrCompression>,
    /// The shutter in degrees (default: the preset's, 0): a light that moves while it is open streaks its
    /// ghosts (180: open half of each frame, the streak is half the light's motion per frame).
    #[arg(long, allow_negative_numbers = true)]
    pub shutter_deg: Option<f64>,
    /// A sequence: one JSON record per frame (frame, light_px, light_deg, visibility, ms, status).
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// A sequence: leave frames whose file exists as they are (resume a stopped render).
    #[arg(long)]
    pub skip_existing: bool,
    /// A sequence on the CPU twin: draw the frames one after another instead of in parallel (to measure).
    #[arg(long, hide = true)]
    pub frames_in_turn: bool,
    /// Print where the command's time went (reading, preparing the lens, the frame's passes, writing), in
    /// milliseconds of wall time.
    #[arg(long)]
    pub timings: bool,
    /// How the ghosts are made (default: blended or photo when the preset uses a LUT, else paraxial).
    #[arg(long, value_enum)]
    pub method: Option<Method>,
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
    /// Aperture: circle, blades:N[:ROTATION_DEG[:ROUNDNESS]], or image:PATH (grayscale).
    #[arg(long)]
    pub aperture: Option<String>,
    /// Wavelengths: 3 is RGB (650/510/475 nm), 2..32 are CIE-weighted, 1 is the d-line alone.
    #[arg(long)]
    pub spectrum: Option<usize>,
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
    #[arg(long)]
    pub look: Option<String>,
    /// A .cube (or other LUT file OCIO reads) applied as a look, in the config's color_timing space.
    #[arg(long)]
    pub cube: Option<PathBuf>,
    /// The colour space of plate files (an OCIO colour space, or `display` for the inverse of the display and
    /// view: a plate at 0 EV with no flare then comes out as shot). Default: by file type.
    #[arg(long)]
    pub input_space: Option<String>,
    /// Leave out the starburst at the light.
    #[arg(long)]
    pub no_starburst: bool,
    /// The starburst's brightness in stops relative to the physical one (default: the preset's, 0).
    #[arg(long, allow_negative_numbers = true)]
    pub starburst_ev: Option<f64>,
    /// Deliver the frame desqueezed: the sensor stretched along x by X (1/4 to 4; the frame is drawn on the
    /// sensor at X times --size's rows, or 1/X times its columns below 1, then averaged down), or `auto` for an
    /// anamorphic lens's own squeeze EFL_y / EFL_x (default: the preset's, 1).
    #[arg(long)]
    pub desqueeze: Option<String>,
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
    /// Background plate (PNG is taken as sRGB, EXR and HDR as linear), shown under the flare at --plate-ev; a
    /// sequence when it has a frame field (`plates/shot.####.exr` or `%04d`).
    #[arg(long)]
    pub background: Option<PathBuf>,
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
    #[arg(long, value_parser = super::common::parse_pair_u32)]
    pub focus_px: Option<(u32, u32)>,
    /// Depth of field: live (layered gather, the default) or reference (every pixel's kernel scattered).
    #[arg(long, value_enum)]
    pub dof_method: Option<super::common::MethodArg>,
    /// Depth of field: each of R, G and B defocused at its own wavelength (axial colour).
    #[arg(long)]
    pub axial_colour: bool,
    /// Leave the depth of field off even when the preset has it on.
    #[arg(long)]
    pub no_dof: bool,
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
    /// Extra EXR layers (ghosts: one layer per drawn ghost).
    #[arg(long, value_enum)]
    pub layers: Option<Layers>,
    /// Output image, .png (tonemapped) or .exr (linear, layered); with --frames, a pattern such as
    /// `out/flare.####.exr`.
    #[arg(short = 'o', long = "out", alias = "output")]
    pub out: PathBuf,
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

/// What the flare's exposure was and why.
fn exposure_line(doc: &Document) -> String {
    if doc.exposure_auto {
        format!(
            "flare exposure {:+.2} EV (auto: the brightest ghost at display level {}; --exposure-ev N locks it)",
            doc.flare_ev,
            flare_core::exposure::AUTO_DISPLAY_LEVEL
        )
    } else {
        format!("flare exposure {:+.2} EV", doc.flare_ev)
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

/// The document `args` describe: the preset (or the default), then LENS, then every flag given.
pub fn document(args: &RenderArgs) -> Result<Document> {
    if let Some(linear) = args.exposure {
        let stops = if linear > 0.0 { format!("--exposure-ev {:.2}", linear.log2()) } else { "--exposure-ev".into() };
        bail!("--exposure {linear}: exposures are in stops now; use {stops}");
    }
    let mut doc = args.optics.document()?;
    if let Some((x, y)) = args.light_deg {
        doc.light_deg = [x, y];
    }
    if let Some(spec) = &args.aperture {
        let f_number = args.optics.f_number.or(doc.aperture.f_number);
        doc.aperture = parse_aperture(spec, f_number)?;
    }
    if let Some(n) = args.spectrum {
        doc.wavelengths = n;
    }
    match args.exposure_ev {
        Some(Exposure::Auto) => doc.exposure_auto = true,
        Some(Exposure::Stops(ev)) => {
            doc.flare_ev = ev;
            doc.exposure_auto = false;
        }
        None => {}
    }
    if let Some(ev) = args.plate_ev {
        doc.plate_ev = ev;
    }
    if let Some(t) = args.tonemap {
        doc.tonemap = t.into();
    }
    if args.no_starburst {
        doc.starburst = false;
    }
    if let Some(ev) = args.starburst_ev {
        doc.starburst_ev = ev;
    }
    if let Some(spec) = &args.desqueeze {
        doc.desqueeze = match spec.as_str() {
            "auto" => flare_core::optics::FirstOrder::d_line(&doc.lens)
                .ok()
                .and_then(|fo| fo.squeeze())
                .with_context(|| format!("--desqueeze auto: {} is not anamorphic (no squeeze to undo)", doc.lens.id))?,
            number => {
                number.parse().with_context(|| format!("--desqueeze {spec}: a number from 0.25 to 4, or auto"))?
            }
        };
    }
    if let Some(spec) = &args.dirt {
        super::common::parse_dirt(spec, &mut doc.dirt)?;
    }
    if let Some(amount) = args.dirt_amount {
        doc.dirt.amount = amount;
    }
    if let Some(spread) = args.dirt_spread_deg {
        doc.dirt.spread_deg = spread;
    }
    if let Some(plate) = &args.background {
        doc.background = Some(plate.display().to_string());
    }
    if let Some(w) = args.sensor_mm {
        doc.sensor_width_mm = w;
    }
    let color = &mut doc.color;
    for (value, field) in [
        (&args.ocio_config, &mut color.config),
        (&args.display, &mut color.display),
        (&args.view, &mut color.view),
        (&args.look, &mut color.looks),
        (&args.input_space, &mut color.input_space),
    ] {
        if let Some(v) = value {
            *field = Some(v.clone());
        }
    }
    if args.display.is_some() && args.view.is_none() {
        // Another display: its own default view, unless one is given.
        color.view = None;
    }
    if let Some(cube) = &args.cube {
        color.cube = Some(cube.display().to_string());
    }
    if let Some(t) = args.exr_type {
        doc.exr.pixel_type = t.into();
    }
    if let Some(c) = args.exr_compression {
        doc.exr.compression = c;
    }
    if let Some(deg) = args.shutter_deg {
        doc.timeline.shutter_deg = deg;
    }
    if let Some(depth) = &args.depth {
        doc.dof.enabled = true;
        doc.dof.depth = Some(depth.clone());
    }
    if args.depth_range.is_some() {
        doc.dof.depth_range_m = args.depth_range;
    }
    if let Some(f) = args.focus_m {
        doc.dof.focus_m = f;
        doc.dof.focus_px = None;
    }
    if let Some((x, y)) = args.focus_px {
        doc.dof.focus_px = Some([x, y]);
    }
    if let Some(method) = args.dof_method {
        doc.dof.method = method.into();
    }
    if args.axial_colour {
        doc.dof.axial_colour = true;
    }
    if args.no_dof {
        doc.dof.enabled = false;
    }
    match args.light {
        Some(LightArg::Auto) => {
            let auto = doc.auto_light.get_or_insert_with(Default::default);
            if let Some(t) = args.light_threshold {
                auto.threshold = t;
            }
            if args.light_power.is_some() {
                auto.reference_power = args.light_power;
            }
            if let Some(n) = args.light_smooth {
                auto.smooth_frames = n;
            }
        }
        Some(LightArg::Keys) => doc.auto_light = None,
        None => {}
    }
    if doc.auto_light.is_none()
        && (args.light_threshold.is_some() || args.light_power.is_some() || args.light_smooth.is_some())
    {
        bail!("--light-threshold, --light-power and --light-smooth apply to --light auto");
    }
    if let Some(t) = args.threshold {
        doc.cull_threshold = Some(t);
    }
    if let Some(mode) = &args.blend {
        BlendMode::parse(mode).map_err(|e| anyhow::anyhow!("--blend {e}"))?;
        doc.blend.mode = mode.clone();
    }
    if let Some(path) = &args.lut {
        doc.blend.lut = LutSource::Simulated { path: Some(path.display().to_string()) };
    }
    doc.check().map_err(|e| match &e {
        // A value a flag gave is refused in the flag's name.
        flare_core::preset::PresetError::Value { field, reason } => match flag_of(args, field) {
            Some(flag) => anyhow::anyhow!("{}: {reason}", flare_core::files::shorten_numbers(&flag)),
            None => anyhow::anyhow!("{e}"),
        },
        _ => anyhow::anyhow!("{e}"),
    })?;
    Ok(doc)
}

/// The flag of `args` that set the document's `field`, if one did.
fn flag_of(args: &RenderArgs, field: &str) -> Option<String> {
    let given = |set: bool, flag: &str, value: String| set.then(|| format!("{flag} {value}"));
    match field {
        "wavelengths" => given(args.spectrum.is_some(), "--spectrum", format!("{}", args.spectrum?)),
        "light_deg" => args.light_deg.map(|(x, y)| format!("--light-deg {x},{y}")),
        "flare_ev" => match args.exposure_ev? {
            Exposure::Stops(ev) => Some(format!("--exposure-ev {ev}")),
            Exposure::Auto => None,
        },
        "plate_ev" => given(args.plate_ev.is_some(), "--plate-ev", format!("{}", args.plate_ev?)),
        "starburst_ev" => args.starburst_ev.map(|ev| format!("--starburst-ev {ev}")),
        "desqueeze" => args.desqueeze.as_ref().map(|d| format!("--desqueeze {d}")),
        "dirt.amount" => args.dirt_amount.map(|a| format!("--dirt-amount {a}")),
        "dirt.spread_deg" => args.dirt_spread_deg.map(|d| format!("--dirt-spread-deg {d}")),
        "dirt.image" => args.dirt.as_ref().map(|d| format!("--dirt {d}")),
        "aperture.f_number" => {
            given(args.optics.f_number.is_some(), "--f-number", format!("{}", args.optics.f_number?))
        }
        "aperture" | "aperture.roundness" => args.aperture.as_ref().map(|a| format!("--aperture {a}")),
        "cull_threshold" => given(args.threshold.is_some(), "--threshold", format!("{}", args.threshold?)),
        "sensor_width_mm" => given(args.sensor_mm.is_some(), "--sensor-mm", format!("{}", args.sensor_mm?)),
        "auto_light.threshold" => args.light_threshold.map(|t| format!("--light-threshold {t}")),
        "auto_light.reference_power" => args.light_power.map(|p| format!("--light-power {p}")),
        "auto_light.smooth_frames" => args.light_smooth.map(|n| format!("--light-smooth {n}")),
        "timeline.shutter_deg" => args.shutter_deg.map(|d| format!("--shutter-deg {d}")),
        "color.config" => args.ocio_config.as_ref().map(|c| format!("--ocio-config {c}")),
        "color.display" => args.display.as_ref().map(|d| format!("--display {d}")),
        "color.view" => args.view.as_ref().map(|v| format!("--view {v}")),
        "color.looks" => args.look.as_ref().map(|l| format!("--look {l}")),
        "color.cube" => args.cube.as_ref().map(|c| format!("--cube {}", c.display())),
        "color.input_space" => args.input_space.as_ref().map(|i| format!("--input-space {i}")),
        "background" => args.background.as_ref().map(|b| format!("--background {}", b.display())),
        "dof.depth" => args.depth.as_ref().map(|d| format!("--depth {d}")),
        "dof.focus_m" => args.focus_m.map(|f| format!("--focus-m {f}")),
        "lens" => args.optics.file.clone(),
        _ => None,
    }
}

/// `--exr-type`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
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

/// The method: the flag, else what the document's LUT source implies.
fn method_of(args: &RenderArgs, doc: &Document) -> Method {
    args.method.unwrap_or(match doc.blend.lut {
        LutSource::None => Method::Paraxial,
        LutSource::Simulated { .. } => Method::Blended,
        LutSource::Photo { .. } => Method::Photo,
    })
}

/// The LUT of the document's source: read from its file (checked against the lens), or baked in memory.
/// The LUT a blended or photo frame draws: `--lut`, the preset's, else the cached bake (baked now on a miss).
/// Given `near_theta_deg` (a still's light angle), only the images drawn at that angle are read from a file.
fn lut_for(doc: &Document, flare: &PreparedFlare, method: Method, near_theta_deg: Option<f64>) -> Result<GhostLut> {
    let path = match &doc.blend.lut {
        LutSource::Simulated { path } => path.clone(),
        LutSource::Photo { path } => Some(path.clone()),
        LutSource::None => None,
    };
    match path {
        Some(path) => {
            let path = Path::new(&path);
            let lut =
                format::read_lut_near(path, near_theta_deg).with_context(|| format!("reading {}", path.display()))?;
            lut.check_for(&doc.lens, &flare.config).with_context(|| path.display().to_string())?;
            if method == Method::Photo && lut.kind != LutKind::Photo {
                bail!("{}: --method photo needs a photo LUT (this one is ray-traced)", path.display());
            }
            Ok(lut)
        }
        None if method == Method::Photo => bail!("--method photo needs --lut F.flut (made by `flarelab photo-lut`)"),
        None => {
            if let Err(why) = flare_core::lut::Symmetry::of(&doc.lens, &flare.config.aperture) {
                // Said before any classification or device probing: the bake would refuse it after.
                bail!("--method blended: no LUT ghosts: {why}");
            }
            // The LUT baked for this lens and these settings: the app's and this command's shared cache, else
            // baked now (and cached for next time).
            let settings = flare_core::bake::BakeSettings::default();
            let cache = flare_core::bake::cache::LutCache::user();
            if let Some(cache) = &cache {
                match cache.load_near(&doc.lens, &flare.config, &settings, near_theta_deg) {
                    flare_core::bake::cache::Lookup::Hit(lut) => {
                        eprintln!("LUT ghosts from the cache ({})", cache.dir.display());
                        return Ok(*lut);
                    }
                    flare_core::bake::cache::Lookup::Rejected(reason) => eprintln!("{reason}: baking it again"),
                    flare_core::bake::cache::Lookup::Miss => {}
                }
            }
            let renderer = flare.ray_grid_renderer();
            let choice = super::lut::LutChoice::default();
            let gpu = super::lut::bake_gpu(crate::cli::common::DeviceArg::Auto, false)?;
            let lut = super::lut::bake_lut(flare, &renderer, &choice, &settings, None, gpu.as_ref(), false)?.0;
            if let Some(cache) = &cache {
                match cache.store(&doc.lens, &flare.config, &settings, &lut) {
                    Ok(path) => eprintln!("cached the LUT as {}", path.display()),
                    Err(e) => eprintln!("the LUT could not be cached in {}: {e}", cache.dir.display()),
                }
            }
            Ok(lut)
        }
    }
}

pub fn run(args: &RenderArgs) -> Result<()> {
    if args.timings {
        flare_core::timing::start();
    }
    let started = std::time::Instant::now();
    let result = run_timed(args);
    if args.timings {
        print_timings(&flare_core::timing::finish(), started.elapsed());
    }
    result
}

/// `--timings`: the spans the command made, indented under the span they lie in, and the command's whole time.
fn print_timings(spans: &[flare_core::timing::Span], total: std::time::Duration) {
    eprintln!("timings (wall ms; an indented span lies inside the one above it):");
    for s in spans {
        let indent = (2 * s.depth).min(16);
        eprintln!("  {:indent$}{:<width$} {:>9.1}", "", s.name, s.ms, width = 32 - indent);
    }
    let top: f64 = spans.iter().filter(|s| s.depth == 0).map(|s| s.ms).sum();
    let total_ms = total.as_secs_f64() * 1e3;
    eprintln!("  {:<32} {:>9.1}", "the rest (checks, messages)", (total_ms - top).max(0.0));
    eprintln!("  {:<32} {:>9.1}", "the command (from its arguments)", total_ms);
}

fn run_timed(args: &RenderArgs) -> Result<()> {
    use flare_core::timing::span;
    let mut doc = span("read the document", || document(args))?;
    let method = method_of(args, &doc);
    let grid = match (method, args.grid) {
        (Method::Paraxial | Method::Blended | Method::Photo, Some(_)) => {
            bail!("--grid applies to --method raygrid or reference")
        }
        (Method::Paraxial | Method::Blended | Method::Photo, None) => None,
        (Method::Raygrid, None) => bail!("--method raygrid needs --grid N (Hullin 2011 used 16 to 128)"),
        (Method::Raygrid, Some(n)) => Some(raytrace::Grid::Fixed(n)),
        (Method::Reference, n) => Some(raytrace::Grid::Adaptive(n.unwrap_or(raytrace::REFERENCE_GRID))),
    };
    if let Some(n) = grid.map(raytrace::Grid::cells)
        && !raytrace::GRID_RANGE.contains(&n)
    {
        bail!("--grid {n}: use {} to {}", raytrace::GRID_RANGE.start(), raytrace::GRID_RANGE.end());
    }
    if args.lut.is_some() && !matches!(method, Method::Blended | Method::Photo) {
        bail!("--lut applies to --method blended or photo");
    }
    if method == Method::Photo
        && let Some(path) = &args.lut
    {
        doc.blend.lut = LutSource::Photo { path: path.display().to_string() };
    }
    match method {
        Method::Blended if doc.blend.lut == LutSource::None => doc.blend.lut = LutSource::Simulated { path: None },
        Method::Blended | Method::Photo => {}
        _ => doc.blend.lut = LutSource::None,
    }
    if args.gpu_samples > 8 {
        bail!("--gpu-samples {}: use 0 (the box filter) or 1 to 8 samples a pixel across", args.gpu_samples);
    }
    if ![1, 2, 4].contains(&args.accumulation_divisor) {
        bail!("--accumulation-divisor {}: use 1, 2 or 4", args.accumulation_divisor);
    }
    let choice = doc.layer_choice(args.layers == Some(Layers::Ghosts));
    // Everything that can be refused is checked before any work: the output's name and type, the range, the
    // plate, the track.
    let out_text = args.out.display().to_string();
    let out_pattern = FramePattern::parse(&out_text).map_err(|e| anyhow::anyhow!("-o {e}"))?;
    let sequence = match (args.frames, out_pattern) {
        (Some(_), Some(pattern)) => Some(pattern),
        (Some(_), None) => bail!(
            "-o {out_text}: a sequence needs a frame field in the file name, e.g. out/flare.####.exr or \
             out/flare.%04d.exr"
        ),
        (None, Some(_)) => bail!("-o {out_text}: the name has a frame field; give --frames A-B to render a sequence"),
        (None, None) => None,
    };
    if grid.is_some() && doc.auto_light.is_some() {
        bail!("--light auto applies to the paraxial, blended and photo methods");
    }
    if grid.is_some() && doc.timeline.shutter_deg > 0.0 {
        bail!(
            "--shutter-deg {}: motion blur applies to the paraxial, blended and photo methods (a ray-traced frame \
             is traced at one instant); give --shutter-deg 0",
            doc.timeline.shutter_deg
        );
    }
    frame::check_output(&args.out, choice).map_err(|e| match e {
        frame::FrameError::Request(reason) => anyhow::anyhow!("--layers ghosts: {reason}"),
        other => anyhow::anyhow!("{other}"),
    })?;
    // The folder takes the files now, before a bake, a trace or the first frame (a sequence makes its folder).
    match sequence {
        Some(_) => flare_core::files::check_sequence_target(&args.out),
        None => flare_core::files::check_target(&args.out),
    }
    .map_err(|e| anyhow::anyhow!("-o {e}"))?;
    let range = match args.frames {
        Some((a, b)) => a..=b,
        None => {
            let f = args.frame.unwrap_or(doc.timeline.first_frame);
            f..=f
        }
    };
    shot::plan::check_range(&doc, &range).map_err(|e| anyhow::anyhow!("--background: {e}"))?;
    if doc.auto_light.is_some() && doc.background.is_none() {
        bail!("--light auto finds the light in the plate: give --background (a plate or a sequence)");
    }
    if let Some(background) = doc.background.as_deref()
        && !FramePattern::is_pattern(background)
    {
        read_plate(Path::new(background)).context("--background: the plate cannot be used")?;
    }
    let track = args
        .track
        .as_deref()
        .map(|p| read_track(p).map_err(|e| anyhow::anyhow!("--track {}: {e}", p.display())))
        .transpose()?;
    let config = doc.flare_config().map_err(|e| anyhow::anyhow!("{e}"))?;
    let flare =
        span("prepare the lens", || PreparedFlare::new(&doc.lens, &config)).with_context(|| doc.lens.id.clone())?;
    doc.resolve_exposure(&flare.system);
    if let (Some(rows), Some(path)) = (&track, &args.track) {
        let (width, height) = shot::plan::frame_size(&doc, &range, args.size)?;
        let (position, intensity) =
            shot::track::to_keys(rows, &flare.system.mapping, doc.sensor_width_mm, (width, height), doc.desqueeze)
                .map_err(|e| anyhow::anyhow!("--track {}: {e}", path.display()))?;
        doc.timeline.light_deg = position;
        if !intensity.is_empty() {
            doc.timeline.light_ev = intensity;
        }
    }
    // Ray grids trace on the GPU too (`render::raygrid`); the reference is the f64 CPU tracer.
    let mut device = match (args.device, grid) {
        (DeviceArg::Gpu, Some(raytrace::Grid::Adaptive(_))) => bail!(
            "--device gpu: the reference is the f64 CPU tracer; for ray grids on the GPU use --method raygrid --grid N"
        ),
        (_, Some(raytrace::Grid::Adaptive(_))) | (DeviceArg::Cpu, _) => Device::Cpu,
        (DeviceArg::Gpu, _) => Device::gpu(false).map_err(|e| anyhow::anyhow!("{e} (or use --device cpu)"))?,
        (DeviceArg::Auto, _) => Device::gpu(false).unwrap_or_else(|e| {
            eprintln!("no GPU ({e}): drawing on the CPU twin");
            Device::Cpu
        }),
    };
    let cancel = AtomicBool::new(false);
    let scanning = (doc.auto_light.is_some() && range.clone().count() > 1)
        .then(|| progress_bar(range.clone().count(), "finding the light"));
    let plan = span("plan the shot", || {
        shot::plan::plan(
            &doc,
            &flare.system,
            range,
            args.size,
            &|done, _| {
                if let Some(bar) = &scanning {
                    bar.set_position(done as u64);
                }
            },
            &cancel,
        )
    })?;
    if let Some(bar) = scanning {
        bar.finish_and_clear();
    }
    // A still without motion blur draws the LUT's images at one light angle: only those are read.
    let near_theta_deg = match plan.frames.as_slice() {
        [still] if doc.timeline.shutter_deg <= 0.0 => {
            let u = flare_core::ghost::light_slopes_for_frame_position(still.light_deg[0], still.light_deg[1]);
            Some(flare_core::lut::light_direction_deg(u).0)
        }
        _ => None,
    };
    let lut = match method {
        Method::Blended | Method::Photo => {
            Some(span("load the LUT", || lut_for(&doc, &flare, method, near_theta_deg).map(LiveLut::new))?)
        }
        _ => None,
    };
    // The ray-traced methods write their accumulation at the frame's full size.
    let divisor = if grid.is_some() { 1 } else { args.accumulation_divisor };
    // The ray-traced methods trace each frame's ghosts, stills and sequences alike (`flare_core::traced`).
    let traced = grid.map(|n| Arc::new(TracedGhosts::new(&flare, n, args.gpu_samples, &device)));
    if let Some(out) = sequence {
        let sources = ShotSources { doc: &doc, flare: &flare, lut: lut.as_ref(), plan: &plan };
        let options = SequenceOptions {
            out,
            layers: choice,
            skip_existing: args.skip_existing,
            divisor,
            parallel_frames: !args.frames_in_turn,
            traced,
        };
        let result = render_frames(args, &mut device, &sources, &options, &cancel);
        eprintln!("{}", exposure_line(&doc));
        return result;
    }
    let planned = &plan.frames[0];
    let (width, height) = (plan.width, plan.height);
    // The plate, then its depth of field: each error blamed on what caused it (a bad depth map is not the plate's).
    let plate = match planned.plate.as_deref() {
        Some(p) => match shot::plate::frame_plate(&doc, &flare, planned.frame, p) {
            Ok((plate, warning)) => {
                if let Some(warning) = warning {
                    eprintln!("warning: {warning}");
                }
                Some(plate)
            }
            Err(shot::plate::FramePlateError::Plate(e)) => {
                return Err(anyhow::anyhow!(e))
                    .with_context(|| format!("--background: frame {}: the plate cannot be used", planned.frame));
            }
            Err(shot::plate::FramePlateError::DepthOfField(e)) => bail!("frame {}: {e}", planned.frame),
        },
        None => None,
    };
    if doc.dof.enabled {
        match &plate {
            Some(_) => eprintln!(
                "depth of field: {} method, focus {}, f/{:.1}",
                doc.dof.method.word(),
                doc.dof.focus_px.map_or(format!("{} m", doc.dof.focus_m), |[x, y]| format!("on pixel ({x}, {y})")),
                flare.system.first_order.f_number / flare.system.settings.stop_scale
            ),
            None => {
                eprintln!("the preset's depth of field is on, but there is no plate to defocus (give --background)")
            }
        }
    }
    let request = plan.request(&doc, &flare.system, planned, divisor);
    let frame = span("build the frame", || Frame::build(&flare, lut.as_ref(), &request));
    let sources = Sources { flare: &flare, lut: lut.as_ref(), plate: plate.as_ref() };
    match &traced {
        Some(t) => {
            // Ray-traced ghosts replace the paraxial accumulation; starburst, tonemap and writer are the same.
            let traced =
                span("draw and write (ray-traced)", || t.render_to_file(&device, &frame, &sources, choice, &args.out))?;
            eprintln!("{traced}");
        }
        None => {
            let made = span("draw", || frame::draw_for_file(&mut device, &frame, &sources, choice, &args.out))?;
            span("write", || frame::write_made(&mut device, &frame, &sources, &made, choice, &args.out))?;
            eprintln!("rendered on {}", device.name());
        }
    }
    eprintln!("{}", exposure_line(&doc));
    if let Some(s) = &frame.shutter {
        eprintln!(
            "motion blur ({} degree shutter): up to {} time samples, {:.1} a ghost on average; the fastest ghost moves \
             {:.1} px while it is open, at most {:.2} px between samples",
            doc.timeline.shutter_deg,
            s.count,
            s.mean_per_ghost(),
            s.longest_px,
            s.max_gap_px
        );
    }
    if doc.tonemap == flare_core::color::Tonemap::View
        && let Some(view) = &frame.request.view
    {
        let looks = if view.looks.is_empty() { String::new() } else { format!(", looks {}", view.looks) };
        eprintln!("display: {} / {}{looks} ({})", view.display, view.view, view.config);
    }
    let st = frame.sprites.stats;
    eprintln!(
        "wrote {} ({width}x{height}): {} ghosts x {} wavelengths, {} sprites drawn, culled {} dim / {} off sensor / {} empty entrance{}",
        args.out.display(),
        flare.system.ghosts.len(),
        config.spectrum.len(),
        frame.scene.instances.len(),
        st.below_threshold,
        st.off_sensor,
        st.empty_entrance_region,
        match (&lut, &frame.lut) {
            (Some(live), Some(l)) =>
                format!(", {} LUT images from {} LUT ghosts", l.instances.len(), live.lut.ghosts.len()),
            _ => String::new(),
        }
    );
    Ok(())
}

/// A terminal progress bar with the rate and the time left.
fn progress_bar(total: usize, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(total as u64);
    let style = ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} frames, {per_sec}, ETA {eta}")
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ");
    bar.set_style(style);
    bar.set_message(what.to_string());
    bar
}

/// `frames` for a message: at most 10 numbers, then how many more (`frames 1, 2, 3 and 997 more`).
fn frame_list(frames: impl Iterator<Item = i64>) -> String {
    let all: Vec<i64> = frames.collect();
    let shown: Vec<String> = all.iter().take(10).map(i64::to_string).collect();
    let more = all.len().saturating_sub(10);
    let word = if all.len() == 1 { "frame" } else { "frames" };
    if more == 0 {
        format!("{word} {}", shown.join(", "))
    } else {
        format!("{word} {} and {more} more", shown.join(", "))
    }
}

/// Renders the planned frames to the sequence `out` with a progress bar; the log when asked; an error (a
/// non-zero exit) when any frame failed, after all the others were rendered.
fn render_frames(
    args: &RenderArgs,
    device: &mut Device,
    sources: &ShotSources,
    options: &SequenceOptions,
    cancel: &AtomicBool,
) -> Result<()> {
    if let Some(dir) = Path::new(&options.out.text).parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("-o: cannot create {}", dir.display()))?;
    }
    let total = sources.plan.frames.len();
    let bar = progress_bar(total, "rendering");
    let started = std::time::Instant::now();
    let report = render_sequence(
        device,
        sources,
        options,
        &|record, done, _| {
            bar.set_position(done as u64);
            if let FrameOutcome::Failed(e) = &record.outcome {
                bar.suspend(|| eprintln!("failed: {e}"));
            }
        },
        cancel,
    );
    bar.finish_and_clear();
    if let Some(log) = &args.log {
        write_log(log, &report).with_context(|| format!("--log {}", log.display()))?;
    }
    if let Some(warning) = &report.plate_warning {
        eprintln!("warning: {warning}");
    }
    let median = report.median_ms();
    eprintln!(
        "{} of {total} frames rendered ({} skipped, {} failed) in {:.1} s on {}, {}x{}: median {median:.0} ms a frame",
        report.rendered(),
        report.skipped(),
        report.failed(),
        started.elapsed().as_secs_f64(),
        device.name(),
        sources.plan.width,
        sources.plan.height,
    );
    let failed = report.failures();
    if !failed.is_empty() {
        // Exactly what was written: none, all but the failed ones, or the rest skipped as already there.
        let frames = frame_list(failed.iter().map(|(f, _)| *f));
        let others = match (report.rendered(), report.skipped()) {
            (0, 0) => "no frame was written".to_string(),
            (0, s) => format!("{s} were already there (skipped); none was written"),
            (r, 0) => format!("the other {r} were written"),
            (r, s) => format!("{r} were written and {s} already there (skipped)"),
        };
        bail!("{} of {total} frames failed ({frames}; the first: {}); {others}", failed.len(), failed[0].1);
    }
    Ok(())
}
