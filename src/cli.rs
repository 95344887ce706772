//! The command line: `flarelab lens info|list|convert`, `flarelab trace`.
//!
//! Every command reads a lens from a file (`.json`, `.zmx`, `.dat`, by extension or content) or from the
//! built-in library by name, and prints human-readable text or, with `--json`, one JSON document.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand, ValueEnum};
use flare_core::aperture::{Aperture, ApertureShape, DEFAULT_MASK_SIZE};
use flare_core::flare::{FlareConfig, PreparedFlare};
use flare_core::ghost::{FrameSettings, GhostSettings, GhostSystem};
use flare_core::optics::formats::{load_lens_file, pbrt, to_json, write_atomic, zmx};
use flare_core::optics::glass::D_LINE_NM;
use flare_core::optics::library::{DEFAULT_LENS_ID, builtin_lens, ids};
use flare_core::optics::{
    Coating, CoatingLayer, FirstOrder, Lens, LightPath, PathKind, TraceOptions, TraceStatus, Tracer, pupil_ray,
};
use flare_core::raytrace;
use flare_core::render::{DisplaySettings, Tonemap, cpu, gpu, output};
use flare_core::spectrum::Spectrum;
use serde_json::json;

#[derive(Parser, Debug)]
#[command(
    name = "flarelab",
    version,
    about = "FlareLab: physically based lens flares. With no subcommand, opens the desktop app.",
    after_help = "LENS is a file (.json, .zmx, .dat) or the name of a built-in lens (see `flarelab lens list`)."
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Inspect, list and convert lenses.
    #[command(subcommand)]
    Lens(LensCommand),
    /// Trace one ray exactly through the lens (or along a ghost path) to the sensor.
    Trace(TraceArgs),
    /// Every two-reflection ghost for a light direction: sprite, brightness, colour, and whether it is culled.
    Ghosts(GhostsArgs),
    /// Render a flare to an image (PNG: tonemapped 8-bit sRGB; EXR: linear float).
    Render(RenderArgs),
    /// Run time against error of every method (paraxial, ray grids) versus the ray-traced reference.
    Bench(crate::bench::BenchArgs),
    /// Measure every ghost's paraxial error against ray tracing over light angles: which are non-linear.
    Classify(crate::lut_cli::ClassifyArgs),
    /// Bake the non-linear ghosts into a LUT file (.flut) by exact ray tracing.
    Bake(crate::lut_cli::BakeArgs),
    /// Import a folder of photographs of a flare swept over theta as a photo LUT (.flut).
    PhotoLut(crate::lut_cli::PhotoArgs),
}

#[derive(clap::Args, Debug)]
pub struct GhostsArgs {
    /// Lens file or built-in lens name.
    file: String,
    /// Field angle of the light in the y-z plane, degrees (incoming slope tan T, as in `trace`).
    #[arg(long, allow_negative_numbers = true)]
    field_deg: f64,
    /// One wavelength (the sprite is then exactly the stop's image); default: RGB at 650 / 510 / 475 nm.
    #[arg(long, allow_negative_numbers = true)]
    wavelength_nm: Option<f64>,
    /// Coating on every surface instead of the lens's own: none, quarter-wave[:NM], multilayer:N/T,N/T...
    #[arg(long)]
    coating: Option<String>,
    #[arg(long)]
    json: bool,
}

#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// Lens file or built-in lens name.
    lens: String,
    /// Where the light appears in the frame, as horizontal and vertical field angles in degrees.
    #[arg(long, default_value = "6,4", allow_hyphen_values = true, value_parser = parse_pair_f64)]
    light_deg: (f64, f64),
    /// Image size, e.g. 1280x720.
    #[arg(long, default_value = "1280x720", value_parser = parse_size)]
    size: (u32, u32),
    /// Rendering method: paraxial (sprites, live), blended (paraxial + LUT ghosts; --lut, or baked in memory),
    /// photo (a photo LUT played back alone, --lut), raygrid (Hullin 2011: a coarse grid of exactly traced rays
    /// per ghost, needs --grid) or reference (the ray-traced ground truth; --grid defaults to the converged size).
    #[arg(long, default_value = "paraxial")]
    method: String,
    /// LUT file (.flut) for --method blended or photo.
    #[arg(long)]
    lut: Option<PathBuf>,
    /// How LUT ghosts blend with the paraxial flare: additive, alpha, linear:FROM:TO or smooth:FROM:TO (degrees).
    #[arg(long, default_value = "additive")]
    blend: String,
    /// Grid cells across each ghost's entrance region, for raygrid and reference.
    #[arg(long)]
    grid: Option<usize>,
    /// Aperture: circle, blades:N[:ROTATION_DEG[:ROUNDNESS]], or image:PATH (grayscale).
    #[arg(long, default_value = "blades:6")]
    aperture: String,
    /// f-number (default: wide open).
    #[arg(long)]
    f_number: Option<f64>,
    /// Coating on every surface instead of the lens's own: none, quarter-wave[:NM], multilayer:N/T,N/T...
    #[arg(long)]
    coating: Option<String>,
    /// Wavelengths: 3 is RGB (650/510/475 nm), 2..32 are CIE-weighted, 1 is the d-line alone.
    #[arg(long, default_value_t = 3)]
    spectrum: usize,
    /// Linear exposure before tonemapping (ghost irradiances are ~1e-6 to 1e-2 of the light's).
    #[arg(long, default_value_t = 100.0)]
    exposure: f32,
    /// Tonemapping operator: none, reinhard, aces.
    #[arg(long, default_value = "aces")]
    tonemap: String,
    /// Leave out the starburst at the light.
    #[arg(long)]
    no_starburst: bool,
    /// Background plate (PNG is taken as sRGB, EXR as linear).
    #[arg(long)]
    background: Option<PathBuf>,
    /// Most relative irradiance culling may take from any pixel: the faintest sprites are culled while their peaks sum
    /// to at most this (default: a quarter of an 8-bit step at the exposure).
    #[arg(long)]
    threshold: Option<f64>,
    /// Accumulate ghosts at 1/N resolution (1, 2 or 4) and upsample: faster on software adapters, a little softer.
    #[arg(long, default_value_t = 1)]
    accumulation_divisor: u32,
    /// gpu (wgpu; a software adapter such as lavapipe counts) or cpu (the renderer's CPU twin).
    #[arg(long, default_value = "gpu")]
    device: String,
    /// Output image, .png or .exr.
    #[arg(short, long)]
    output: PathBuf,
}

pub fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(|| format!("`{s}` is not WIDTHxHEIGHT"))?;
    let (w, h): (u32, u32) = (
        w.trim().parse().map_err(|_| format!("`{s}` is not WIDTHxHEIGHT"))?,
        h.trim().parse().map_err(|_| format!("`{s}` is not WIDTHxHEIGHT"))?,
    );
    if !(1..=8192).contains(&w) || !(1..=8192).contains(&h) {
        return Err(format!("`{s}`: each side must be 1 to 8192 pixels"));
    }
    Ok((w, h))
}

#[derive(Subcommand, Debug)]
pub enum LensCommand {
    /// First-order data, surfaces and ghost count of a lens.
    Info {
        /// Lens file or built-in lens name.
        file: String,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
        /// Wavelength of the first-order data.
        #[arg(long, default_value_t = D_LINE_NM, allow_negative_numbers = true)]
        wavelength_nm: f64,
    },
    /// The built-in lenses.
    List {
        #[arg(long)]
        json: bool,
    },
    /// Write a lens in another format (through a temporary file: the target is never half-written).
    Convert {
        file: String,
        /// Output format.
        #[arg(long, value_enum)]
        to: OutputFormat,
        /// Output file.
        #[arg(short, long)]
        output: PathBuf,
    },
}

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum OutputFormat {
    Json,
    Zmx,
    Dat,
}

#[derive(clap::Args, Debug)]
pub struct TraceArgs {
    /// Lens file or built-in lens name.
    file: String,
    /// Field angle of the light in the y-z plane, degrees (|T| < 90).
    #[arg(long, allow_negative_numbers = true)]
    field_deg: f64,
    /// Point of the entrance pupil in units of its radius, e.g. 0,0.5.
    #[arg(long, allow_hyphen_values = true, value_parser = parse_pair_f64)]
    pupil: (f64, f64),
    /// Follow the ghost reflected at J, then at I (surfaces numbered from 0), e.g. 2,5.
    #[arg(long, value_parser = parse_pair_usize)]
    ghost: Option<(usize, usize)>,
    /// Wavelength (default: the d-line).
    #[arg(long, default_value_t = D_LINE_NM, allow_negative_numbers = true)]
    wavelength_nm: f64,
    /// Stop the ray at the first clear aperture it passes outside (default: only report them).
    #[arg(long)]
    apply_apertures: bool,
    #[arg(long)]
    json: bool,
}

fn parse_pair<T: std::str::FromStr>(s: &str, what: &str) -> Result<(T, T), String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    match parts.as_slice() {
        [a, b] => match (a.parse(), b.parse()) {
            (Ok(a), Ok(b)) => Ok((a, b)),
            _ => Err(format!("`{s}` is not two {what} separated by a comma")),
        },
        _ => Err(format!("`{s}` is not two {what} separated by a comma")),
    }
}

fn parse_pair_f64(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = parse_pair::<f64>(s, "numbers")?;
    if a.is_finite() && b.is_finite() { Ok((a, b)) } else { Err(format!("`{s}` is not finite")) }
}

fn parse_pair_usize(s: &str) -> Result<(usize, usize), String> {
    parse_pair(s, "surface numbers")
}

/// Opens a lens: a file if the path exists, else a built-in lens by name.
pub fn open_lens(name: &str) -> Result<Lens> {
    let path = Path::new(name);
    if path.exists() {
        return load_lens_file(path).with_context(|| name.to_string());
    }
    let looks_like_path = name.contains(['/', '\\']) || name.contains('.');
    match builtin_lens(name) {
        Ok(lens) => Ok(lens),
        Err(_) if looks_like_path => bail!("{name}: no such file"),
        Err(e) => bail!("{name}: no such file, and {e}"),
    }
}

fn check_wavelength(nm: f64) -> Result<()> {
    if !(200.0..=3000.0).contains(&nm) {
        bail!("--wavelength-nm {nm}: outside 200-3000 nm");
    }
    Ok(())
}

pub fn run(command: Command) -> Result<()> {
    match command {
        Command::Lens(LensCommand::Info { file, json, wavelength_nm }) => lens_info(&file, json, wavelength_nm),
        Command::Lens(LensCommand::List { json }) => lens_list(json),
        Command::Lens(LensCommand::Convert { file, to, output }) => lens_convert(&file, to, &output),
        Command::Trace(args) => trace(&args),
        Command::Ghosts(args) => ghosts(&args),
        Command::Render(args) => render(&args),
        Command::Bench(args) => crate::bench::run(&args),
        Command::Classify(args) => crate::lut_cli::classify_command(&args),
        Command::Bake(args) => crate::lut_cli::bake_command(&args),
        Command::PhotoLut(args) => crate::lut_cli::photo_command(&args),
    }
}

fn lens_info(file: &str, as_json: bool, wavelength_nm: f64) -> Result<()> {
    check_wavelength(wavelength_nm)?;
    let lens = open_lens(file)?;
    let fo = FirstOrder::compute(&lens, wavelength_nm).with_context(|| file.to_string())?;
    let ghosts = lens.ghost_pairs();
    let assumed: Vec<usize> =
        (0..lens.surfaces.len()).filter(|&k| lens.surfaces[k].medium.dispersion().is_assumed()).collect();
    if as_json {
        let table: Vec<_> = lens
            .surfaces
            .iter()
            .enumerate()
            .map(|(k, s)| {
                json!({
                    "surface": k, "radius_mm": s.radius_mm, "thickness_mm": s.thickness_mm,
                    "nd": s.medium.n_d, "vd": s.medium.v_d, "glass": s.medium.glass,
                    "semi_aperture_mm": s.semi_aperture_mm, "stop": s.stop,
                    "dispersion": s.medium.dispersion().describe(),
                })
            })
            .collect();
        let out = json!({
            "id": lens.id, "name": lens.name, "wavelength_nm": wavelength_nm,
            "efl_mm": fo.efl_mm, "bfd_mm": fo.bfd_mm,
            "entrance_pupil_z_mm": fo.entrance_pupil_z_mm,
            "entrance_pupil_diameter_mm": fo.entrance_pupil_diameter_mm,
            "f_number": fo.f_number, "exit_pupil_z_mm": fo.exit_pupil_z_mm,
            "total_track_mm": fo.total_track_mm, "stop_surface": fo.stop_surface,
            "surfaces": lens.surfaces.len(), "ghost_count": ghosts.len(),
            "reflecting_surfaces": lens.reflecting_surfaces(),
            "dispersion_assumed_surfaces": assumed,
            "surface_table": table,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    println!("{} ({})", lens.name, lens.id);
    println!(
        "  {} surfaces, stop at surface {}, {} two-reflection ghosts",
        lens.surfaces.len(),
        fo.stop_surface,
        ghosts.len()
    );
    println!("  at {wavelength_nm} nm:");
    println!("    focal length (EFL)        {:>12.6} mm", fo.efl_mm);
    println!("    back focal distance       {:>12.6} mm", fo.bfd_mm);
    println!("    f-number                  {:>12.6}", fo.f_number);
    println!(
        "    entrance pupil            {:>12.6} mm diameter, {:.6} mm behind the first vertex",
        fo.entrance_pupil_diameter_mm, fo.entrance_pupil_z_mm
    );
    println!("    exit pupil                {:>12.6} mm from the last vertex", fo.exit_pupil_z_mm);
    println!("    total track (to sensor)   {:>12.6} mm", fo.total_track_mm);
    println!();
    println!(
        "  {:>3} {:>12} {:>10} {:>8} {:>6} {:>8} {:>9}  dispersion",
        "#", "radius", "thickness", "nd", "vd", "glass", "semi-ap"
    );
    for (k, s) in lens.surfaces.iter().enumerate() {
        let radius = if s.is_flat() { "flat".to_owned() } else { format!("{:.4}", s.radius_mm) };
        let thickness = s.thickness_mm.map(|t| format!("{t:.4}")).unwrap_or_else(|| "-".to_owned());
        let vd = s.medium.v_d.map(|v| format!("{v:.1}")).unwrap_or_else(|| "-".to_owned());
        let glass = s.medium.glass.clone().unwrap_or_else(|| "-".to_owned());
        println!(
            "  {k:>3} {radius:>12} {thickness:>10} {:>8.4} {vd:>6} {glass:>8} {:>9.3}  {}{}",
            s.medium.n_d,
            s.semi_aperture_mm,
            s.medium.dispersion().describe(),
            if s.stop { "  (stop)" } else { "" }
        );
    }
    if !assumed.is_empty() {
        println!();
        println!("  note: surfaces {assumed:?} give no Abbe number or known glass; their dispersion is assumed.");
    }
    Ok(())
}

fn lens_list(as_json: bool) -> Result<()> {
    let mut rows = Vec::new();
    for id in ids() {
        let lens = builtin_lens(id)?;
        let fo = FirstOrder::d_line(&lens)?;
        rows.push((id, lens, fo));
    }
    if as_json {
        let out: Vec<_> = rows
            .iter()
            .map(|(id, lens, fo)| json!({"id": id, "name": lens.name, "efl_mm": fo.efl_mm, "f_number": fo.f_number,
                "surfaces": lens.surfaces.len(), "ghost_count": lens.ghost_pairs().len(), "default": *id == DEFAULT_LENS_ID}))
            .collect();
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        for (id, lens, fo) in rows {
            let mark = if id == DEFAULT_LENS_ID { " (default)" } else { "" };
            println!(
                "{id:<28} f = {:>7.2} mm  f/{:<5.2} {:>2} surfaces  {}{mark}",
                fo.efl_mm,
                fo.f_number,
                lens.surfaces.len(),
                lens.name
            );
        }
    }
    Ok(())
}

fn lens_convert(file: &str, to: OutputFormat, output: &Path) -> Result<()> {
    let lens = open_lens(file)?;
    let text = match to {
        OutputFormat::Json => to_json(&lens),
        OutputFormat::Zmx => zmx::write(&lens),
        OutputFormat::Dat => pbrt::write(&lens),
    };
    write_atomic(output, text.as_bytes()).with_context(|| format!("writing {}", output.display()))?;
    eprintln!("wrote {}", output.display());
    Ok(())
}

fn trace(args: &TraceArgs) -> Result<()> {
    check_wavelength(args.wavelength_nm)?;
    if !(args.field_deg.is_finite() && args.field_deg.abs() < 90.0) {
        bail!("--field-deg {}: must be finite and strictly between -90 and 90", args.field_deg);
    }
    let lens = open_lens(&args.file)?;
    let fo = FirstOrder::d_line(&lens).with_context(|| args.file.clone())?;
    let kind = match args.ghost {
        Some((i, j)) => PathKind::Ghost { i, j },
        None => PathKind::Image,
    };
    let path = LightPath::new(&lens, kind)?;
    let tracer = Tracer::new(&lens, &path, args.wavelength_nm, fo.sensor_z_mm());
    let (px, py) = args.pupil;
    let ray = pupil_ray(&fo.entrance_pupil(), args.field_deg.to_radians(), px, py);
    let out = tracer.trace(&ray, TraceOptions { apply_apertures: args.apply_apertures, record_points: false });
    let landing = out.sensor_point_mm;
    let path_name = match kind {
        PathKind::Image => "image".to_owned(),
        PathKind::Ghost { i, j } => format!("ghost {i},{j}"),
    };
    if args.json {
        let out = json!({
            "status": out.status.word(),
            "surface": out.status.surface(),
            "x_mm": landing.map(|p| p.x),
            "y_mm": landing.map(|p| p.y),
            "sensor_z_mm": fo.sensor_z_mm(),
            "direction": out.sensor_direction.map(|d| [d.x, d.y, d.z]),
            "clipped_at": out.clipped_at,
            "path": path_name,
            "field_deg": args.field_deg,
            "pupil": [px, py],
            "wavelength_nm": args.wavelength_nm,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    match out.status {
        TraceStatus::Landed => {
            let p = landing.unwrap_or_default();
            println!("ok: lands at x = {:.9} mm, y = {:.9} mm on the sensor ({path_name} path)", p.x, p.y);
        }
        TraceStatus::Vignetted { surface } => println!("vignetted: stopped by the clear aperture of surface {surface}"),
        TraceStatus::Tir { surface } => println!("tir: total internal reflection at surface {surface}"),
        TraceStatus::Missed { surface } if surface == lens.surfaces.len() => {
            println!("missed: the ray never meets the sensor")
        }
        TraceStatus::Missed { surface } => println!("missed: the ray does not meet surface {surface}"),
        TraceStatus::Backward => println!("backward: the ray leaves the lens travelling away from the sensor"),
    }
    if !out.clipped_at.is_empty() {
        println!("  passes outside the clear aperture of surfaces {:?} (in path order)", out.clipped_at);
    }
    Ok(())
}

/// Parses a coating: none, quarter-wave[:NM], multilayer:INDEX/THICKNESS_NM,...
pub fn parse_coating(spec: &str) -> Result<Coating> {
    let (kind, rest) = spec.split_once(':').unwrap_or((spec, ""));
    let coating = match kind {
        "none" | "uncoated" => Coating::Uncoated,
        "quarter-wave" | "qw" => Coating::QuarterWave {
            design_wavelength_nm: if rest.is_empty() {
                550.0
            } else {
                rest.parse().with_context(|| format!("--coating {spec}: `{rest}` is not a wavelength"))?
            },
            layer_index: None,
        },
        "multilayer" => {
            let mut layers = Vec::new();
            for layer in rest.split(',').filter(|l| !l.is_empty()) {
                let (n, t) = layer
                    .split_once('/')
                    .with_context(|| format!("--coating {spec}: layer `{layer}` is not INDEX/THICKNESS_NM"))?;
                let (index, thickness_nm) = (n.parse::<f64>(), t.parse::<f64>());
                let (Ok(index), Ok(thickness_nm)) = (index, thickness_nm) else {
                    bail!("--coating {spec}: layer `{layer}` is not two numbers")
                };
                layers.push(CoatingLayer { index, thickness_nm });
            }
            if layers.is_empty() {
                bail!("--coating {spec}: a multilayer needs at least one INDEX/THICKNESS_NM layer");
            }
            Coating::Multilayer { layers }
        }
        other => bail!("--coating {other}: use none, quarter-wave[:NM] or multilayer:N/T,..."),
    };
    // Validate through a lens surface so that the rules are the lens file's rules.
    let mut probe = flare_core::optics::library::default_lens();
    probe.surfaces[0].coating = coating.clone();
    probe.validate().map_err(|e| anyhow::anyhow!("--coating {spec}: {e}"))?;
    Ok(coating)
}

/// Parses an aperture: circle, blades:N[:ROTATION_DEG[:ROUNDNESS]], image:PATH.
pub fn parse_aperture(spec: &str, f_number: Option<f64>) -> Result<Aperture> {
    let mut parts = spec.split(':');
    let shape = match parts.next().unwrap_or("") {
        "circle" => ApertureShape::Circle,
        "blades" => {
            let count =
                parts.next().unwrap_or("6").parse().with_context(|| format!("--aperture {spec}: blade count"))?;
            let mut optional = |what: &str| -> Result<f64> {
                let value = parts.next().map(str::parse::<f64>).transpose();
                Ok(value.with_context(|| format!("--aperture {spec}: {what}"))?.unwrap_or(0.0))
            };
            let rotation_deg = optional("rotation")?;
            let roundness = optional("roundness")?;
            ApertureShape::Blades { count, rotation_deg, roundness }
        }
        "image" => {
            let path = spec.split_once(':').map(|(_, p)| p).unwrap_or("");
            Aperture::image_shape_from_file(Path::new(path), DEFAULT_MASK_SIZE)?
        }
        other => bail!("--aperture {other}: use circle, blades:N[:ROTATION_DEG[:ROUNDNESS]] or image:PATH"),
    };
    let aperture = Aperture { shape, f_number };
    aperture.validate().map_err(|e| anyhow::anyhow!("--aperture {spec}: {e}"))?;
    Ok(aperture)
}

fn ghosts(args: &GhostsArgs) -> Result<()> {
    if !(args.field_deg.is_finite() && args.field_deg.abs() < 90.0) {
        bail!("--field-deg {}: must be finite and strictly between -90 and 90", args.field_deg);
    }
    let spectrum = match args.wavelength_nm {
        Some(w) => Spectrum::single(w).map_err(|e| anyhow::anyhow!("--wavelength-nm: {e}"))?,
        None => Spectrum::rgb(),
    };
    let lens = open_lens(&args.file)?;
    let coating_override = args.coating.as_deref().map(parse_coating).transpose()?;
    let settings = GhostSettings { spectrum: spectrum.clone(), stop_scale: 1.0, coating_override };
    let system = GhostSystem::build(&lens, &settings).with_context(|| args.file.clone())?;
    let u = [0.0, args.field_deg.to_radians().tan()];
    let frame_settings = FrameSettings::default();
    let frame = system.frame(u, &frame_settings);
    let reported = spectrum.len() / 2; // the single wavelength, or G of RGB
    let mut rows = Vec::with_capacity(system.ghosts.len());
    for (g, ghost) in system.ghosts.iter().enumerate() {
        let sprites: Vec<_> = frame.sprites.iter().filter(|s| s.ghost == g).collect();
        let mut rgb = [0.0; 3];
        for s in &sprites {
            for (sum, c) in rgb.iter_mut().zip(s.rgb) {
                *sum += c;
            }
        }
        let intensity = sprites.iter().map(|s| s.irradiance).sum::<f64>() / sprites.len().max(1) as f64;
        let culled = if sprites.iter().all(|s| s.culled.is_some()) {
            sprites.first().and_then(|s| s.culled).map(|c| c.word())
        } else {
            None
        };
        let sprite = system.stop_image_sprite(g, reported, u);
        let per_wavelength: Vec<_> = (0..spectrum.len())
            .map(|w| {
                let s = system.stop_image_sprite(g, w, u);
                json!({"wavelength_nm": spectrum.wavelengths_nm[w], "center_mm": s.map(|s| s.0.map(|v| v + 0.0)), "radius_mm": s.map(|s| s.1)})
            })
            .collect();
        rows.push(json!({
            "i": ghost.i, "j": ghost.j,
            "center_mm": sprite.map(|s| s.0.map(|v| v + 0.0)), "radius_mm": sprite.map(|s| s.1),
            "intensity": intensity, "rgb": rgb,
            "straddles_stop": ghost.straddles_stop,
            "stop_crossings": if ghost.straddles_stop { 3 } else { 1 },
            "culled": culled,
            "per_wavelength": per_wavelength,
        }));
    }
    let st = frame.stats;
    if args.json {
        let out = json!({
            "lens": lens.id, "field_deg": args.field_deg, "wavelengths_nm": spectrum.wavelengths_nm,
            "reported_wavelength_nm": spectrum.wavelengths_nm[reported],
            "sensor_mm": [frame_settings.sensor.width_mm, frame_settings.sensor.height_mm],
            "ghosts": rows,
            "sprites": {"total": st.sprites, "drawn": st.drawn, "below_threshold": st.below_threshold,
                        "off_sensor": st.off_sensor, "empty_entrance_region": st.empty_entrance_region},
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    println!(
        "{} at {} deg: {} ghosts, {} sprites drawn, culled {} dim / {} off sensor / {} empty entrance",
        lens.id,
        args.field_deg,
        system.ghosts.len(),
        st.drawn,
        st.below_threshold,
        st.off_sensor,
        st.empty_entrance_region
    );
    println!("  {:>3} {:>3}  {:>10} {:>9}  {:>10}  {:<8} culled", "i", "j", "centre y", "radius", "intensity", "stop");
    let mut order: Vec<usize> = (0..rows.len()).collect();
    order.sort_by(|&a, &b| {
        rows[b]["intensity"].as_f64().partial_cmp(&rows[a]["intensity"].as_f64()).unwrap_or(std::cmp::Ordering::Equal)
    });
    for k in order {
        let r = &rows[k];
        let centre = r["center_mm"][1].as_f64().map(|v| format!("{v:.3}")).unwrap_or_else(|| "-".into());
        let radius = r["radius_mm"].as_f64().map(|v| format!("{v:.3}")).unwrap_or_else(|| "-".into());
        println!(
            "  {:>3} {:>3}  {centre:>10} {radius:>9}  {:>10.3e}  {:<8} {}",
            r["i"],
            r["j"],
            r["intensity"].as_f64().unwrap_or(0.0),
            if r["straddles_stop"] == true { "3 times" } else { "once" },
            r["culled"].as_str().unwrap_or("")
        );
    }
    Ok(())
}

fn render(args: &RenderArgs) -> Result<()> {
    let grid = match (args.method.as_str(), args.grid) {
        ("paraxial" | "blended" | "photo", None) => None,
        ("blended" | "photo", Some(_)) => bail!("--grid applies to --method raygrid or reference"),
        ("paraxial", Some(_)) => bail!("--grid applies to --method raygrid or reference"),
        ("raygrid", None) => bail!("--method raygrid needs --grid N (Hullin 2011 used 16 to 128)"),
        ("raygrid", Some(n)) => Some(raytrace::Grid::Fixed(n)),
        ("reference", n) => Some(raytrace::Grid::Adaptive(n.unwrap_or(raytrace::REFERENCE_GRID))),
        (other, _) => bail!("--method {other}: available methods: paraxial, blended, photo, raygrid, reference"),
    };
    if let Some(n) = grid.map(raytrace::Grid::cells)
        && !raytrace::GRID_RANGE.contains(&n)
    {
        bail!("--grid {n}: use {} to {}", raytrace::GRID_RANGE.start(), raytrace::GRID_RANGE.end());
    }
    let blend = flare_core::lut::blend::BlendSettings {
        mode: flare_core::lut::blend::BlendMode::parse(&args.blend).map_err(|e| anyhow::anyhow!("--blend {e}"))?,
        ..Default::default()
    };
    if args.lut.is_some() && !["blended", "photo"].contains(&args.method.as_str()) {
        bail!("--lut applies to --method blended or photo");
    }
    if args.method == "photo" && args.lut.is_none() {
        bail!("--method photo needs --lut F.flut (made by `flarelab photo-lut`)");
    }
    let (x, y) = args.light_deg;
    if !(x.abs() < 89.0 && y.abs() < 89.0) {
        bail!("--light-deg {x},{y}: each angle must be within +-89 degrees");
    }
    let kind = output::ImageKind::from_path(&args.output)?;
    let tonemap = match args.tonemap.as_str() {
        "none" => Tonemap::None,
        "reinhard" => Tonemap::Reinhard,
        "aces" => Tonemap::Aces,
        other => bail!("--tonemap {other}: use none, reinhard or aces"),
    };
    if ![1, 2, 4].contains(&args.accumulation_divisor) {
        bail!("--accumulation-divisor {}: use 1, 2 or 4", args.accumulation_divisor);
    }
    if !(args.exposure.is_finite() && args.exposure >= 0.0) {
        bail!("--exposure {}: must be finite and not negative", args.exposure);
    }
    let lens = open_lens(&args.lens)?;
    let config = FlareConfig {
        aperture: parse_aperture(&args.aperture, args.f_number)?,
        spectrum: Spectrum::with_count(args.spectrum).map_err(|e| anyhow::anyhow!("--spectrum: {e}"))?,
        coating_override: args.coating.as_deref().map(parse_coating).transpose()?,
        intensity_threshold: args.threshold,
        display: DisplaySettings {
            exposure: args.exposure,
            tonemap,
            starburst: !args.no_starburst,
            accumulation_divisor: args.accumulation_divisor,
            ..DisplaySettings::default()
        },
    };
    let background = args.background.as_deref().map(output::read_plate).transpose()?;
    let flare = PreparedFlare::new(&lens, &config).with_context(|| args.lens.clone())?;
    let (width, height) = args.size;
    let (scene, frame) = flare.scene([x, y], width, height);
    let starburst_texture = cpu::StarburstTexture::from_starburst(&flare.starburst);
    if matches!(args.method.as_str(), "blended" | "photo") {
        return crate::lut_cli::render_with_lut(
            &flare,
            &lens,
            args.lut.as_deref(),
            args.method == "photo",
            &blend,
            [x, y],
            (width, height),
            &args.device,
            background.as_ref(),
            &args.output,
        );
    }
    let (display, hdr) = match (grid, args.device.as_str()) {
        (Some(n), _) => {
            // Ray-traced ghosts, then the same starburst and tonemap passes as the CPU twin.
            let started = std::time::Instant::now();
            let traced = raytrace::RayGridRenderer::new(&flare).render([x, y], width, height, n)?;
            let st = traced.stats;
            eprintln!(
                "ray-traced {} ghost x wavelength jobs, {n:?} grid: {} rays, {} triangles, {} jobs with no light, {:.2} s",
                st.jobs,
                st.rays,
                st.triangles,
                st.empty_jobs,
                started.elapsed().as_secs_f64()
            );
            // The tonemap pass reads the accumulation at full size.
            let scene = flare_core::render::FlareScene { hdr_width: width, hdr_height: height, ..scene.clone() };
            let mut hdr = traced.hdr;
            if config.display.starburst {
                cpu::starburst_pass(&scene, &starburst_texture, &mut hdr);
            }
            (cpu::tonemap_pass(&scene, &hdr, background.as_ref()), hdr)
        }
        (None, "cpu") => {
            let hdr = cpu::render_hdr(&scene, &flare.mask, config.display.starburst.then_some(&starburst_texture));
            (cpu::tonemap_pass(&scene, &hdr, background.as_ref()), hdr)
        }
        (None, "gpu") => {
            let ctx = gpu::GpuContext::headless(false).map_err(|e| anyhow::anyhow!("{e} (or use --device cpu)"))?;
            let mut renderer = gpu::FlareRenderer::new(&ctx.device, &ctx.queue, wgpu::TextureFormat::Rgba8Unorm);
            renderer.set_aperture(&ctx.device, &ctx.queue, &flare.mask);
            renderer.set_starburst(&ctx.device, &ctx.queue, &flare.starburst);
            renderer.set_background(&ctx.device, &ctx.queue, background.as_ref());
            let display = gpu::render_display(&ctx, &mut renderer, &scene)?;
            let hdr = gpu::read_hdr(&ctx, &renderer)?;
            eprintln!("rendered on {} ({:?})", ctx.adapter.name, ctx.adapter.backend);
            (display, hdr)
        }
        (None, other) => bail!("--device {other}: use gpu or cpu"),
    };
    match kind {
        output::ImageKind::Png => output::write_png(&args.output, &display)?,
        output::ImageKind::Exr => {
            // Linear float: background plus flare, times the exposure (what the PNG shows before tonemapping),
            // at the image size whatever the accumulation's.
            let mut linear = cpu::composite(&scene, &hdr, background.as_ref());
            for p in &mut linear.pixels {
                for c in p.iter_mut().take(3) {
                    *c *= args.exposure;
                }
            }
            output::write_exr(&args.output, &linear)?
        }
    }
    let st = frame.stats;
    eprintln!(
        "wrote {} ({width}x{height}): {} ghosts x {} wavelengths, {} sprites drawn, culled {} dim / {} off sensor / {} empty entrance",
        args.output.display(),
        flare.system.ghosts.len(),
        config.spectrum.len(),
        st.drawn,
        st.below_threshold,
        st.off_sensor,
        st.empty_entrance_region
    );
    Ok(())
}
