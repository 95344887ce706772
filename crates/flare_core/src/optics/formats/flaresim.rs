//! FlareSim's lens prescriptions (`.lens`), so users of that flare simulator bring their lenses.
//!
//! # How it works
//! The format (FlareSim's README, "Lens Prescriptions"): `key: value` header lines (`name`, `focal_length`),
//! then `surfaces:` and one row per surface, object side first:
//! `radius thickness ior abbe semi_ap coating`, `#` starting a comment. `radius` is signed in mm, 0 flat,
//! the word `stop` the aperture stop (flat, in air); `ior` is n_d of the medium after the surface (1 air);
//! `abbe` is V_d (0: FlareSim treats the glass as non-dispersive; FlareLab has no such glass and assumes its
//! usual V_d, and says so); `semi_ap` the clear semi-diameter; `coating` the number of AR layers: 0 bare,
//! 1 a quarter-wave MgF2 layer at 550 nm, 2 or more FlareLab's broadband 3-layer stack (said once as a
//! warning). `focal_length` is checked against the lens's paraxial focal length (a warning beyond 2 %).
//! A row with the wrong number of columns or a word where a number belongs is refused with its line.

use super::text::{FormatError, LoadedLens, finish_text_lens};
use crate::optics::lens::{Coating, Lens, Medium, Surface, round};
use crate::optics::paraxial::FirstOrder;

const FORMAT: &str = "FlareSim .lens";

fn line_error(line: usize, message: impl Into<String>) -> FormatError {
    FormatError::Line { format: FORMAT, line, message: crate::files::clean(&message.into()) }
}

/// True when `text` looks like a FlareSim lens: a `surfaces:` line.
pub(crate) fn looks_like(text: &str) -> bool {
    text.lines().any(|l| l.trim().eq_ignore_ascii_case("surfaces:"))
}

/// Parses and validates a FlareSim `.lens` text.
pub fn parse(text: &str, id_hint: &str) -> Result<LoadedLens, FormatError> {
    let (mut name, mut focal_length) = (String::new(), None);
    let mut in_surfaces = false;
    let (mut surfaces, mut lines) = (Vec::new(), Vec::new());
    let mut warnings = Vec::new();
    let (mut non_dispersive, mut coated_1, mut coated_many) = (Vec::new(), false, false);
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let content = raw.split('#').next().unwrap_or("").trim();
        if content.is_empty() {
            continue;
        }
        if !in_surfaces {
            let Some((key, value)) = content.split_once(':') else {
                return Err(line_error(line, format!("`{content}` is neither a `key: value` header nor `surfaces:`")));
            };
            let value = value.trim();
            match key.trim().to_ascii_lowercase().as_str() {
                "surfaces" => in_surfaces = true,
                "name" => name = value.to_owned(),
                "focal_length" => {
                    let f: f64 = value
                        .parse()
                        .map_err(|_| line_error(line, format!("focal_length `{value}` is not a number")))?;
                    focal_length = Some((line, f));
                }
                other => {
                    warnings.push(format!("line {line}: header `{other}` is not one FlareLab knows; it was not used"))
                }
            }
            continue;
        }
        let cells: Vec<&str> = content.split_whitespace().collect();
        if !(5..=6).contains(&cells.len()) {
            return Err(line_error(
                line,
                format!("expected 6 columns (radius thickness ior abbe semi_ap coating), found {}", cells.len()),
            ));
        }
        let number = |k: usize, what: &str| -> Result<f64, FormatError> {
            cells[k]
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| line_error(line, format!("{what} `{}` is not a number", cells[k])))
        };
        let stop = cells[0].eq_ignore_ascii_case("stop");
        let radius_mm = if stop { 0.0 } else { number(0, "radius")? };
        let (thickness_mm, n_d, abbe, semi) =
            (number(1, "thickness")?, number(2, "ior")?, number(3, "abbe")?, number(4, "semi_ap")?);
        let layers = if cells.len() == 6 { number(5, "coating")? } else { 0.0 };
        if layers < 0.0 || layers.fract() != 0.0 {
            return Err(line_error(line, format!("coating `{}` is not a number of layers", cells[5])));
        }
        let k = surfaces.len();
        let v_d = if n_d == 1.0 {
            None
        } else if abbe == 0.0 {
            non_dispersive.push(k);
            None
        } else {
            Some(abbe)
        };
        let glass = (n_d == 1.0).then(|| "air".to_owned());
        let mut surface = Surface::new(radius_mm, Some(thickness_mm), Medium { n_d, v_d, glass }, semi);
        surface.stop = stop;
        surface.coating = match layers as u32 {
            0 => Coating::Uncoated,
            1 => {
                coated_1 = true;
                Coating::QuarterWave { design_wavelength_nm: 550.0, layer_index: Some(1.38) }
            }
            _ => {
                coated_many = true;
                Coating::broadband()
            }
        };
        surfaces.push(surface);
        lines.push(line);
    }
    if surfaces.is_empty() {
        return Err(FormatError::Structure { format: FORMAT, message: "no surface rows after `surfaces:`".to_owned() });
    }
    if !non_dispersive.is_empty() {
        warnings.push(format!(
            "surfaces {non_dispersive:?} give abbe 0 (no dispersion in FlareSim); FlareLab assumes V_d 50 for them"
        ));
    }
    if coated_1 || coated_many {
        warnings.push(
            "coating column: 1 layer is read as a quarter-wave MgF2 layer at 550 nm, 2 or more as FlareLab's \
             broadband 3-layer stack"
                .to_owned(),
        );
    }
    let loaded = finish_text_lens(surfaces, name, id_hint, &lines, warnings)?;
    Ok(check_focal_length(loaded, focal_length))
}

/// Adds a warning when the file's focal length and the lens's paraxial one differ by more than 2 %.
fn check_focal_length(mut loaded: LoadedLens, focal_length: Option<(usize, f64)>) -> LoadedLens {
    if let Some((line, f)) = focal_length
        && let Ok(fo) = FirstOrder::d_line(&loaded.lens)
        && (fo.efl_mm - f).abs() > 0.02 * f.abs()
    {
        loaded.warnings.push(format!(
            "line {line}: focal_length {} mm, but the prescription's paraxial focal length is {} mm",
            round(f),
            round(fo.efl_mm)
        ));
    }
    loaded
}

/// The lens as a FlareSim `.lens` text. Coatings are written as their layer count (a quarter-wave as 1, a
/// multilayer as its layers); aspheric surfaces and a stop on a lens surface cannot be written.
pub fn write(lens: &Lens) -> Result<String, FormatError> {
    if let Some((k, kind)) = lens.surfaces.iter().enumerate().find_map(|(k, s)| Some((k, s.non_spherical_kind()?))) {
        return Err(FormatError::Structure {
            format: FORMAT,
            message: format!("surface {k} is {kind}, and the .lens format holds spheres only"),
        });
    }
    if lens.stop_on_lens_surface() {
        return Err(FormatError::Structure {
            format: FORMAT,
            message: "the stop is on a lens surface, and the .lens format needs it as its own `stop` row".to_owned(),
        });
    }
    let mut out = format!("name: {}\n", lens.name.replace(['\n', '\r'], " "));
    if let Ok(fo) = FirstOrder::d_line(lens) {
        out.push_str(&format!("focal_length: {}\n", fo.efl_mm));
    }
    out.push_str("\nsurfaces:\n# radius thickness ior abbe semi_ap coating\n");
    for s in &lens.surfaces {
        let radius = if s.stop { "stop".to_owned() } else { format!("{}", s.radius_mm) };
        let layers = match &s.coating {
            Coating::Uncoated => 0,
            Coating::QuarterWave { .. } => 1,
            Coating::Multilayer { layers } => layers.len(),
        };
        out.push_str(&format!(
            "{radius} {} {} {} {} {layers}\n",
            s.thickness_mm.unwrap_or(0.0),
            s.medium.n_d,
            s.medium.v_d.unwrap_or(0.0),
            s.semi_aperture_mm
        ));
    }
    Ok(out)
}
