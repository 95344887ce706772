//! `flarelab trace`: one ray traced exactly through the lens (or along a ghost path) to the sensor: the
//! reference convention's ray (a field angle through a point of the entrance pupil), or any ray given by a
//! point and a direction (`--start X,Y,Z --dir L,M,N`), so a landing can be checked against another tracer
//! without agreeing on a pupil.

use anyhow::{Context, Result, bail};
use flare_core::optics::glass::D_LINE_NM;
use flare_core::optics::{FirstOrder, LightPath, PathKind, Ray, TraceOptions, TraceStatus, Tracer, pupil_ray};
use glam::DVec3;
use serde_json::json;

use super::common::{check_wavelength, open_lens, parse_pair_f64, parse_pair_usize};

#[derive(clap::Args, Debug)]
pub struct TraceArgs {
    /// Lens file or built-in lens name.
    file: String,
    /// Field angle of the light in the y-z plane, degrees (|T| < 90); with --pupil.
    #[arg(long, allow_negative_numbers = true, required_unless_present = "start", conflicts_with_all = ["start", "dir"])]
    field_deg: Option<f64>,
    /// Point of the entrance pupil in units of its radius, e.g. 0,0.5; with --field-deg (an anamorphic lens's pupil is
    /// taken as its y-z section's, a circle: --start and --dir aim anywhere).
    #[arg(long, allow_hyphen_values = true, value_parser = parse_pair_f64, requires = "field_deg")]
    pupil: Option<(f64, f64)>,
    /// A point of the incoming ray in lens coordinates (mm; z along the axis, 0 at the first vertex, the
    /// light travelling towards +z): the ray is the line through it along --dir, in object space (the point
    /// may lie anywhere on that line, in front of the lens or inside it, as the pupil form's point does).
    #[arg(long, allow_hyphen_values = true, value_parser = parse_triple_f64, requires = "dir")]
    start: Option<[f64; 3]>,
    /// The incoming ray's direction (any length; normalised), with --start; its z must be positive.
    #[arg(long, allow_hyphen_values = true, value_parser = parse_triple_f64, requires = "start")]
    dir: Option<[f64; 3]>,
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

/// Parses `X,Y,Z` (three finite numbers).
fn parse_triple_f64(s: &str) -> Result<[f64; 3], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let values: Vec<f64> = parts.iter().filter_map(|p| p.parse::<f64>().ok()).filter(|v| v.is_finite()).collect();
    match values.as_slice() {
        [x, y, z] if parts.len() == 3 => Ok([*x, *y, *z]),
        _ => Err(format!("`{s}` is not X,Y,Z (three finite numbers)")),
    }
}

/// The ray the arguments give: the pupil form, or a start point and a direction (normalised; refused when it
/// has no length or does not travel towards +z).
fn ray_of(args: &TraceArgs, fo: &FirstOrder) -> Result<Ray> {
    match (args.field_deg, args.pupil, args.start, args.dir) {
        (Some(field_deg), Some((px, py)), None, None) => {
            if !(field_deg.is_finite() && field_deg.abs() < 90.0) {
                bail!("--field-deg {field_deg}: must be finite and strictly between -90 and 90");
            }
            Ok(pupil_ray(&fo.entrance_pupil(), field_deg.to_radians(), px, py))
        }
        (None, None, Some(start), Some(dir)) => {
            let d = DVec3::from_array(dir);
            let length = d.length();
            if !(length.is_finite() && length > 0.0) {
                bail!("--dir {},{},{}: a direction needs a length", dir[0], dir[1], dir[2]);
            }
            if d.z <= 0.0 {
                bail!(
                    "--dir {},{},{}: the light must travel towards the lens (+z, from the object side)",
                    dir[0],
                    dir[1],
                    dir[2]
                );
            }
            Ok(Ray { origin_mm: DVec3::from_array(start), direction: d / length })
        }
        _ => bail!("give --field-deg T --pupil PX,PY, or --start X,Y,Z --dir L,M,N"),
    }
}

pub fn run(args: &TraceArgs) -> Result<()> {
    check_wavelength(args.wavelength_nm)?;
    let lens = open_lens(&args.file)?;
    let fo = FirstOrder::d_line(&lens).with_context(|| args.file.clone())?;
    let kind = match args.ghost {
        Some((i, j)) => PathKind::Ghost { i, j },
        None => PathKind::Image,
    };
    let path = LightPath::new(&lens, kind)?;
    let tracer = Tracer::new(&lens, &path, args.wavelength_nm, fo.sensor_z_mm());
    let ray = ray_of(args, &fo)?;
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
            "section_focus_z_mm": fo.sections.as_ref().map(|b| json!({"x": b[0].sensor_z_mm(), "y": b[1].sensor_z_mm()})),
            "sensor_z_mm": fo.sensor_z_mm(),
            "direction": out.sensor_direction.map(|d| [d.x, d.y, d.z]),
            "clipped_at": out.clipped_at,
            "path": path_name,
            "field_deg": args.field_deg,
            "pupil": args.pupil.map(|(px, py)| [px, py]),
            "start": [ray.origin_mm.x, ray.origin_mm.y, ray.origin_mm.z],
            "dir": [ray.direction.x, ray.direction.y, ray.direction.z],
            "wavelength_nm": args.wavelength_nm,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    if let Some(both) = &fo.sections {
        println!(
            "anamorphic lens: the sensor sits at z = {:.6} mm, half way between the x-z focus ({:.6} mm) and the y-z \
             focus ({:.6} mm){}",
            fo.sensor_z_mm(),
            both[0].sensor_z_mm(),
            both[1].sensor_z_mm(),
            if args.pupil.is_some() { "; the pupil is the y-z section's" } else { "" }
        );
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
