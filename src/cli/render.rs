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
use flare_core::frame::{self, Device, Drawn, Frame, LayerChoice, Sources};
use flare_core::lut::blend::{BlendMode, LiveLut};
use flare_core::lut::format;
use flare_core::lut::{GhostLut, LutKind};
use flare_core::output::read_plate;
use flare_core::preset::{Document, LutSource};
use flare_core::raytrace::{self};
use flare_core::render::cpu;

use flare_core::frame::parse_size;

use super::common::{OpticsChoice, parse_aperture, parse_pair_f64};

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

/// Where the frame is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum DeviceArg {
    /// wgpu (a software adapter such as lavapipe counts).
    Gpu,
    /// The renderer's CPU twin.
    Cpu,
}

/// Tonemap operators by name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TonemapArg {
    None,
    Reinhard,
    Aces,
}

impl From<TonemapArg> for Tonemap {
    fn from(t: TonemapArg) -> Self {
        match t {
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
    /// Image size, e.g. 1280x720.
    #[arg(long, default_value = "1280x720", value_parser = parse_size)]
    pub size: (u32, u32),
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
    /// Aperture: circle, blades:N[:ROTATION_DEG[:ROUNDNESS]], or image:PATH (grayscale).
    #[arg(long)]
    pub aperture: Option<String>,
    /// Wavelengths: 3 is RGB (650/510/475 nm), 2..32 are CIE-weighted, 1 is the d-line alone.
    #[arg(long)]
    pub spectrum: Option<usize>,
    /// The flare's exposure in stops (its relative irradiance times 2^EV; ghosts are ~1e-6 to 1e-2 of the light).
    #[arg(long, allow_negative_numbers = true)]
    pub exposure_ev: Option<f64>,
    /// The background plate's exposure in stops (0: as shot).
    #[arg(long, allow_negative_numbers = true)]
    pub plate_ev: Option<f64>,
    /// Replaced by --exposure-ev (stops); refused with the conversion.
    #[arg(long, hide = true, allow_negative_numbers = true)]
    pub exposure: Option<f64>,
    /// Tonemapping operator.
    #[arg(long, value_enum)]
    pub tonemap: Option<TonemapArg>,
    /// Leave out the starburst at the light.
    #[arg(long)]
    pub no_starburst: bool,
    /// Background plate (PNG is taken as sRGB, EXR and HDR as linear), shown under the flare at --plate-ev.
    #[arg(long)]
    pub background: Option<PathBuf>,
    /// Most relative irradiance culling may take from any pixel: the faintest sprites are culled while their peaks sum
    /// to at most this (default: a quarter of an 8-bit step at the exposure).
    #[arg(long)]
    pub threshold: Option<f64>,
    /// Accumulate ghosts at 1/N resolution (1, 2 or 4) and upsample: faster on software adapters, a little softer.
    #[arg(long, default_value_t = 1)]
    pub accumulation_divisor: u32,
    /// Where to draw.
    #[arg(long, value_enum, default_value = "gpu")]
    pub device: DeviceArg,
    /// Extra EXR layers (ghosts: one layer per drawn ghost).
    #[arg(long, value_enum)]
    pub layers: Option<Layers>,
    /// Output image, .png (tonemapped) or .exr (linear, layered).
    #[arg(short = 'o', long = "out", alias = "output")]
    pub out: PathBuf,
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
    if let Some(ev) = args.exposure_ev {
        doc.flare_ev = ev;
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
    if let Some(plate) = &args.background {
        doc.background = Some(plate.display().to_string());
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
            Some(flag) => anyhow::anyhow!("{flag}: {reason}"),
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
        "flare_ev" => given(args.exposure_ev.is_some(), "--exposure-ev", format!("{}", args.exposure_ev?)),
        "plate_ev" => given(args.plate_ev.is_some(), "--plate-ev", format!("{}", args.plate_ev?)),
        "aperture.f_number" => {
            given(args.optics.f_number.is_some(), "--f-number", format!("{}", args.optics.f_number?))
        }
        "aperture" | "aperture.roundness" => args.aperture.as_ref().map(|a| format!("--aperture {a}")),
        "cull_threshold" => given(args.threshold.is_some(), "--threshold", format!("{}", args.threshold?)),
        "lens" => args.optics.file.clone(),
        _ => None,
    }
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
fn lut_for(doc: &Document, flare: &PreparedFlare, method: Method) -> Result<GhostLut> {
    let path = match &doc.blend.lut {
        LutSource::Simulated { path } => path.clone(),
        LutSource::Photo { path } => Some(path.clone()),
        LutSource::None => None,
    };
    match path {
        Some(path) => {
            let path = Path::new(&path);
            let lut = format::read_lut(path).with_context(|| format!("reading {}", path.display()))?;
            lut.check_for(&doc.lens, &flare.config).with_context(|| path.display().to_string())?;
            if method == Method::Photo && lut.kind != LutKind::Photo {
                bail!("{}: --method photo needs a photo LUT (this one is ray-traced)", path.display());
            }
            Ok(lut)
        }
        None if method == Method::Photo => bail!("--method photo needs --lut F.flut (made by `flarelab photo-lut`)"),
        None => {
            let renderer = flare.ray_grid_renderer();
            let choice = super::lut::LutChoice::default();
            Ok(super::lut::bake_lut(flare, &renderer, &choice, &Default::default(), None, false)?.0)
        }
    }
}

pub fn run(args: &RenderArgs) -> Result<()> {
    let mut doc = document(args)?;
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
    if args.layers.is_some() && grid.is_some() {
        bail!("--layers ghosts applies to the paraxial, blended and photo methods");
    }
    if ![1, 2, 4].contains(&args.accumulation_divisor) {
        bail!("--accumulation-divisor {}: use 1, 2 or 4", args.accumulation_divisor);
    }
    let choice = LayerChoice { ghosts: args.layers == Some(Layers::Ghosts) };
    // Everything that can be refused is checked before any work: the output's type, the plate.
    frame::check_output(&args.out, choice).map_err(|e| match e {
        frame::FrameError::Request(reason) => anyhow::anyhow!("--layers ghosts: {reason}"),
        other => anyhow::anyhow!("{other}"),
    })?;
    let plate = doc
        .background
        .as_deref()
        .map(|p| read_plate(Path::new(p)))
        .transpose()
        .context("--background: the plate cannot be used")?;
    let config = doc.flare_config().map_err(|e| anyhow::anyhow!("{e}"))?;
    let flare = PreparedFlare::new(&doc.lens, &config).with_context(|| doc.lens.id.clone())?;
    let lut = match method {
        Method::Blended | Method::Photo => Some(LiveLut::new(lut_for(&doc, &flare, method)?)),
        _ => None,
    };
    let (width, height) = args.size;
    // The ray-traced methods write their accumulation at the frame's full size.
    let divisor = if grid.is_some() { 1 } else { args.accumulation_divisor };
    let request = doc.frame_request(&flare.system, width, height, divisor);
    let frame = Frame::build(&flare, lut.as_ref(), &request);
    let sources = Sources { flare: &flare, lut: lut.as_ref(), plate: plate.as_ref() };
    let mut device = match (args.device, grid) {
        (_, Some(_)) | (DeviceArg::Cpu, None) => Device::Cpu,
        (DeviceArg::Gpu, None) => Device::gpu(false).map_err(|e| anyhow::anyhow!("{e} (or use --device cpu)"))?,
    };
    match grid {
        Some(n) => {
            // Ray-traced ghosts replace the paraxial accumulation; starburst, tonemap and writer are the same.
            let started = std::time::Instant::now();
            let traced = flare.ray_grid_renderer().render(doc.light_deg, width, height, n)?;
            let st = traced.stats;
            eprintln!(
                "ray-traced {} ghost x wavelength jobs, {n:?} grid: {} rays, {} triangles, {} jobs with no light, {:.2} s",
                st.jobs,
                st.rays,
                st.triangles,
                st.empty_jobs,
                started.elapsed().as_secs_f64()
            );
            let mut hdr = traced.hdr;
            cpu::starburst_pass(&frame.scene, &flare.starburst_texture, &mut hdr);
            let display = cpu::tonemap_pass(&frame.scene, &hdr, plate.as_ref());
            let drawn = Drawn { hdr, display };
            frame::write_drawn(&mut device, &frame, &sources, &drawn, choice, &args.out)?;
        }
        None => {
            frame::render_to_file(&mut device, &frame, &sources, choice, &args.out)?;
            eprintln!("rendered on {}", device.name());
        }
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
