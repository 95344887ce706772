//! `flarelab lens info|list|convert`: a lens's first-order data and surfaces, the built-in lenses, and a lens
//! written in another format.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::{Subcommand, ValueEnum};
use flare_core::files::write_atomic;
use flare_core::optics::FirstOrder;
use flare_core::optics::formats::{flaresim, pbrt, to_json, zmx};
use flare_core::optics::glass::D_LINE_NM;
use flare_core::optics::library::{DEFAULT_LENS_ID, builtin_lens, ids};
use serde_json::json;

use super::common::{check_wavelength, open_lens, open_lens_checked};

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
        #[arg(short = 'o', long = "out", alias = "output")]
        output: PathBuf,
    },
}

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum OutputFormat {
    Json,
    Zmx,
    Dat,
    /// FlareSim's .lens.
    Lens,
}

pub fn run(command: LensCommand) -> Result<()> {
    match command {
        LensCommand::Info { file, json, wavelength_nm } => lens_info(&file, json, wavelength_nm),
        LensCommand::List { json } => lens_list(json),
        LensCommand::Convert { file, to, output } => lens_convert(&file, to, &output),
    }
}

fn lens_info(file: &str, as_json: bool, wavelength_nm: f64) -> Result<()> {
    check_wavelength(wavelength_nm)?;
    let loaded = open_lens_checked(file)?;
    let (lens, warnings) = (&loaded.lens, &loaded.warnings);
    let fo = FirstOrder::compute(lens, wavelength_nm).with_context(|| file.to_string())?;
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
                    "conic": s.conic, "aspheric_r2": s.aspheric_r2, "aspheric": s.aspheric,
                    "radius_x_mm": s.radius_x_mm,
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
            "warnings": warnings,
            "sections": fo.sections.as_ref().map(|both| json!({
                "x": section_json(&both[0]), "y": section_json(&both[1]),
            })),
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
    if let Some(both) = &fo.sections {
        println!(
            "  anamorphic: each section focuses on its own (the sensor sits half way, the plane of least confusion)"
        );
        for (word, s) in [("x", &both[0]), ("y", &both[1])] {
            println!(
                "    {word} section: EFL {:>11.6} mm, focus {:.6} mm behind the first vertex ({:+.6} mm from the \
                 sensor), entrance pupil {:.6} mm at {:.6} mm, f/{:.4}",
                s.efl_mm,
                s.total_track_mm,
                s.total_track_mm - fo.total_track_mm,
                s.entrance_pupil_diameter_mm,
                s.entrance_pupil_z_mm,
                s.f_number
            );
        }
        println!("    squeeze (EFL y / EFL x): {:.6}", both[1].efl_mm / both[0].efl_mm);
    }
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
            "  {k:>3} {radius:>12} {thickness:>10} {:>8.4} {vd:>6} {glass:>8} {:>9.3}  {}{}{}",
            s.medium.n_d,
            s.semi_aperture_mm,
            s.medium.dispersion().describe(),
            if s.stop { "  (stop)" } else { "" },
            if let Some(r_x) = s.radius_x_mm {
                let r_x = if r_x == 0.0 { "flat".to_owned() } else { format!("{r_x:.4}") };
                format!("  (toroid: x-z radius {r_x}; y-z profile k {}, r^4.. {:?})", s.conic, s.aspheric)
            } else if s.is_spherical() {
                String::new()
            } else {
                format!("  (asphere: k {}, r^2 {:e}, r^4.. {:?})", s.conic, s.aspheric_r2, s.aspheric)
            }
        );
    }
    if !assumed.is_empty() {
        println!();
        println!("  note: surfaces {assumed:?} give no Abbe number or known glass; their dispersion is assumed.");
    }
    for warning in warnings {
        println!("  warning: {warning}");
    }
    Ok(())
}

/// One section's first-order data in `lens info --json`.
fn section_json(fo: &FirstOrder) -> serde_json::Value {
    json!({
        "efl_mm": fo.efl_mm, "focus_z_mm": fo.total_track_mm, "bfd_mm": fo.bfd_mm,
        "entrance_pupil_z_mm": fo.entrance_pupil_z_mm, "entrance_pupil_diameter_mm": fo.entrance_pupil_diameter_mm,
        "f_number": fo.f_number,
    })
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
        OutputFormat::Zmx => zmx::write(&lens)?,
        OutputFormat::Dat => pbrt::write(&lens)?,
        OutputFormat::Lens => flaresim::write(&lens)?,
    };
    write_atomic(output, text.as_bytes()).with_context(|| format!("writing {}", output.display()))?;
    eprintln!("wrote {}", output.display());
    Ok(())
}
