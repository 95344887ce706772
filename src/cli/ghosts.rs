//! `flarelab ghosts`: every two-reflection ghost for a light direction, with its sprite, brightness, colour
//! and whether it is culled.

use anyhow::{Context, Result, bail};
use flare_core::flare::{FlareConfig, PreparedFlare};
use flare_core::ghost::{FrameSettings, GhostSettings, GhostSystem};
use flare_core::optics::{D_LINE_NM, LightPath, PathMatrices, Section};
use flare_core::report::{ghost_report, to_csv};
use flare_core::spectrum::Spectrum;
use serde_json::json;

use super::common::{open_lens, parse_coating};

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
    /// The ghost report: each ghost's focus, size, f-number, peak and mean irradiance against the source's
    /// image, energy share and stop crossings, worst first, and which surface's coating helps most.
    #[arg(long)]
    report: bool,
    /// With --report: the ghost table as CSV.
    #[arg(long, requires = "report", conflicts_with = "json")]
    csv: bool,
    /// With --report: the f-number (default: wide open).
    #[arg(long, requires = "report")]
    f_number: Option<f64>,
}

pub fn run(args: &GhostsArgs) -> Result<()> {
    if !(args.field_deg.is_finite() && args.field_deg.abs() < 90.0) {
        bail!("--field-deg {}: must be finite and strictly between -90 and 90", args.field_deg);
    }
    let spectrum = match args.wavelength_nm {
        Some(w) => Spectrum::single(w).map_err(|e| anyhow::anyhow!("--wavelength-nm: {e}"))?,
        None => Spectrum::rgb(),
    };
    let lens = open_lens(&args.file)?;
    let coating_override = args.coating.as_deref().map(parse_coating).transpose()?;
    if args.report {
        return report(args, &lens, spectrum, coating_override);
    }
    let settings = GhostSettings { spectrum: spectrum.clone(), stop_scale: 1.0, coating_override };
    let system = GhostSystem::build(&lens, &settings).with_context(|| args.file.clone())?;
    let u = [0.0, args.field_deg.to_radians().tan()];
    let frame_settings = FrameSettings::default();
    let frame = system.frame(u, &frame_settings);
    let reported = spectrum.len() / 2; // the single wavelength, or G of RGB
    let mut rows = Vec::with_capacity(system.ghosts.len());
    let sections = (lens.section(Section::Y), lens.section(Section::X));
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
        // Where this ghost's rays from the light focus at the d-line, from the image plane (None: afocal), in
        // the y-z section and in the x-z section (the same for a lens of revolution).
        let focus = |lens: &flare_core::optics::Lens| {
            LightPath::ghost(lens, ghost.i, ghost.j).ok().and_then(|p| {
                PathMatrices::compute(lens, &p, D_LINE_NM, system.first_order.sensor_z_mm()).focus_after_sensor_mm()
            })
        };
        let (focus_mm, focus_x_mm) = (focus(&sections.0), focus(&sections.1));
        let ellipse = system.stop_image_ellipse(g, reported, u);
        rows.push(json!({
            "i": ghost.i, "j": ghost.j,
            "focus_mm": focus_mm,
            "focus_x_mm": focus_x_mm,
            "semi_axes_mm": ellipse.map(|e| e.1),
            "center_mm": sprite.map(|s| s.0.map(|v| v + 0.0)), "radius_mm": sprite.map(|s| s.1),
            "intensity": intensity, "rgb": rgb,
            "straddles_stop": ghost.straddles_stop,
            "stop_crossings": ghost.per_wavelength[reported].matrices.stop_from_entrance.len(),
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
    print_rows(&rows, system.is_anamorphic());
    Ok(())
}

/// The ghosts' rows as a table, brightest first; an anamorphic lens's with both semi-axes.
fn print_rows(rows: &[serde_json::Value], anamorphic: bool) {
    if anamorphic {
        println!("  anamorphic: each ghost is an ellipse, its semi-axes along x and y (radius x, radius y)");
        println!(
            "  {:>3} {:>3}  {:>10} {:>9} {:>9}  {:>10}  {:<8} culled",
            "i", "j", "centre y", "radius x", "radius y", "intensity", "stop"
        );
    } else {
        println!(
            "  {:>3} {:>3}  {:>10} {:>9}  {:>10}  {:<8} culled",
            "i", "j", "centre y", "radius", "intensity", "stop"
        );
    }
    let mut order: Vec<usize> = (0..rows.len()).collect();
    order.sort_by(|&a, &b| {
        rows[b]["intensity"].as_f64().partial_cmp(&rows[a]["intensity"].as_f64()).unwrap_or(std::cmp::Ordering::Equal)
    });
    for k in order {
        let r = &rows[k];
        let centre = r["center_mm"][1].as_f64().map(|v| format!("{v:.3}")).unwrap_or_else(|| "-".into());
        let mut radius = r["radius_mm"].as_f64().map(|v| format!("{v:.3}")).unwrap_or_else(|| "-".into());
        if anamorphic {
            let axis =
                |k: usize| r["semi_axes_mm"][k].as_f64().map(|v| format!("{v:.3}")).unwrap_or_else(|| "-".into());
            radius = format!("{:>9} {:>9}", axis(0), axis(1));
        }
        println!(
            "  {:>3} {:>3}  {centre:>10} {radius:>9}  {:>10.3e}  {:<8} {}",
            r["i"],
            r["j"],
            r["intensity"].as_f64().unwrap_or(0.0),
            match r["stop_crossings"].as_u64() {
                Some(1) => "once".to_owned(),
                Some(n) => format!("{n} times"),
                None => "-".to_owned(),
            },
            r["culled"].as_str().unwrap_or("")
        );
    }
}

/// `flarelab ghosts --report`: [`flare_core::report::ghost_report`] as text, JSON or CSV.
fn report(
    args: &GhostsArgs,
    lens: &flare_core::optics::Lens,
    spectrum: Spectrum,
    coating_override: Option<flare_core::optics::Coating>,
) -> Result<()> {
    let aperture = flare_core::aperture::Aperture { f_number: args.f_number, ..Default::default() };
    let config = FlareConfig { aperture, spectrum, coating_override, ..FlareConfig::default() };
    let flare = PreparedFlare::new(lens, &config).with_context(|| args.file.clone())?;
    let u = [0.0, args.field_deg.to_radians().tan()];
    let r = ghost_report(lens, &flare.system, flare.mask(), u).with_context(|| args.file.clone())?;
    if args.csv {
        print!("{}", to_csv(&r));
        return Ok(());
    }
    if args.json {
        let out = json!({"lens": lens.id, "field_deg": args.field_deg, "report": r});
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    println!(
        "{} at {} deg, f/{:.2}: {} ghosts carry {:.3e} of the light entering the pupil; worst first",
        lens.id,
        args.field_deg,
        flare.system.first_order.f_number / flare.system.settings.stop_scale,
        r.ghosts.len(),
        r.total_energy_fraction
    );
    let anamorphic = flare.system.is_anamorphic();
    if anamorphic {
        println!("  anamorphic: focus and size in the y-z section, then in the x-z section (focus x, width)");
    }
    println!(
        "  {:>4} {:>3} {:>3} {:>10} {:>9} {:>8} {:>10} {:>10} {:>7}  {:<8}{}  cut by (light taken)",
        "rank",
        "i",
        "j",
        "focus mm",
        "size mm",
        "f/#",
        "peak/src",
        "mean/src",
        "share",
        "stop",
        if anamorphic { "       focus x   width mm" } else { "" }
    );

    let opt = |v: Option<f64>, p: usize| v.map(|v| format!("{v:.p$}")).unwrap_or_else(|| "afocal".into());
    for (rank, g) in r.ghosts.iter().enumerate() {
        println!(
            "  {:>4} {:>3} {:>3} {:>10} {:>9.3} {:>8} {:>10.2e} {:>10.2e} {:>6.2}%  {:<8}{}  {}",
            rank + 1,
            g.i,
            g.j,
            opt(g.focus_mm, 2),
            g.image_diameter_mm,
            opt(g.f_number, 1),
            g.peak_vs_source,
            g.mean_vs_source,
            100.0 * g.energy_share,
            if g.stop_crossings == 1 { "once".to_owned() } else { format!("{} times", g.stop_crossings) },
            if anamorphic {
                format!("  {:>12} {:>10.3}", opt(g.focus_x_mm, 2), g.image_width_mm)
            } else {
                String::new()
            },
            g.vignetting_words()
        );
    }
    println!();
    println!("  coating sensitivity: the share of the bare lens's ghost energy removed when one surface alone");
    println!("  wears the {} (every other surface bare), most helpful first:", r.sensitivity_coating);
    for s in &r.sensitivity {
        println!("    surface {:>3}  {:>+7.2}%", s.surface, 100.0 * s.energy_drop);
    }
    Ok(())
}
