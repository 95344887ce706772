//! The command line: `flarelab lens info|list|convert`, `flarelab trace`.
//!
//! Every command reads a lens from a file (`.json`, `.zmx`, `.dat`, by extension or content) or from the
//! built-in library by name, and prints human-readable text or, with `--json`, one JSON document.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand, ValueEnum};
use flare_core::optics::formats::{load_lens_file, pbrt, to_json, write_atomic, zmx};
use flare_core::optics::glass::D_LINE_NM;
use flare_core::optics::library::{DEFAULT_LENS_ID, builtin_lens, ids};
use flare_core::optics::{FirstOrder, Lens, LightPath, PathKind, TraceOptions, TraceStatus, Tracer, pupil_ray};
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
