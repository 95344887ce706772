//! `flarelab trace`: one ray traced exactly through the lens (or along a ghost path) to the sensor.

use anyhow::{Context, Result, bail};
use flare_core::optics::glass::D_LINE_NM;
use flare_core::optics::{FirstOrder, LightPath, PathKind, TraceOptions, TraceStatus, Tracer, pupil_ray};
use serde_json::json;

use super::common::{check_wavelength, open_lens, parse_pair_f64, parse_pair_usize};

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

pub fn run(args: &TraceArgs) -> Result<()> {
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
