//! pbrt realistic-camera lens tables (`.dat`).
//!
//! # How it works
//! One interface per row, from the object side: `radius thickness index aperture`, whitespace separated,
//! `#` starting a comment. The aperture is the clear *diameter* (halved here), the index is that of the
//! medium after the surface, and index 0 marks the aperture stop (air on both sides). pbrt puts the film
//! apart, so the last row's thickness is usually 0: read as "not given". The format carries no Abbe
//! numbers or glass names, so a lens read from `.dat` disperses by the assumed V_d of
//! [`crate::optics::glass`]; at the d-line it is identical to its JSON twin. The first comment line, if
//! any, names the lens.

use super::text::{FormatError, LoadedLens, exact, finish_text_lens};
use crate::optics::lens::{Lens, Medium, Surface};

const FORMAT: &str = "pbrt .dat";

/// Parses and validates a pbrt `.dat` text.
pub fn parse(text: &str, id_hint: &str) -> Result<LoadedLens, FormatError> {
    let mut name = String::new();
    let mut surfaces: Vec<Surface> = Vec::new();
    let mut lines = Vec::new();
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let content = raw.trim();
        if let Some(comment) = content.strip_prefix('#') {
            if name.is_empty() && surfaces.is_empty() {
                name = comment.trim().to_owned();
            }
            continue;
        }
        let content = content.split('#').next().unwrap_or("").trim();
        if content.is_empty() {
            continue;
        }
        let tokens: Vec<&str> = content.split_whitespace().collect();
        if tokens.len() != 4 {
            return Err(FormatError::Line {
                format: FORMAT,
                line,
                message: format!("expected 4 numbers (radius thickness index aperture), found {} fields", tokens.len()),
            });
        }
        const FIELDS: [&str; 4] = ["radius", "thickness", "index", "aperture"];
        let mut v = [0.0; 4];
        for (i, t) in tokens.iter().enumerate() {
            v[i] = t.parse().ok().filter(|x: &f64| x.is_finite()).ok_or_else(|| FormatError::Line {
                format: FORMAT,
                line,
                message: crate::files::clean(&format!("field {} ({}) `{t}` is not a finite number", i + 1, FIELDS[i])),
            })?;
        }
        let [radius_mm, thickness_mm, index, aperture_mm] = v;
        let stop = index == 0.0;
        let medium = if stop || index == 1.0 { Medium::air() } else { Medium { n_d: index, v_d: None, glass: None } };
        surfaces.push(Surface { stop, ..Surface::new(radius_mm, Some(thickness_mm), medium, 0.5 * aperture_mm) });
        lines.push(line);
    }
    if let Some(last) = surfaces.last_mut()
        && last.thickness_mm == Some(0.0)
    {
        last.thickness_mm = None;
    }
    finish_text_lens(surfaces, name, id_hint, &lines, Vec::new())
}

/// The lens as a pbrt `.dat` table (aperture as diameter, index 0 on the stop, air as 1). pbrt's table has
/// spheres only: an aspheric or conic surface is refused, naming it.
pub fn write(lens: &Lens) -> Result<String, FormatError> {
    if lens.stop_on_lens_surface() || !lens.surfaces[lens.stop_index()].medium.is_air() {
        return Err(FormatError::Structure {
            format: "pbrt .dat",
            message: format!(
                "the stop is surface {} (a lens surface, or in glass), and pbrt's table needs it as a flat row in air",
                lens.stop_index()
            ),
        });
    }
    if let Some((k, kind)) = lens.surfaces.iter().enumerate().find_map(|(k, s)| Some((k, s.non_spherical_kind()?))) {
        return Err(FormatError::Structure {
            format: "pbrt .dat",
            message: format!("surface {k} is {kind}, and pbrt's lens table holds spheres only"),
        });
    }
    let mut out =
        format!("# {}\n# radius\tthickness\tindex\taperture (diameter)\n", lens.name.replace(['\n', '\r'], " "));
    for s in &lens.surfaces {
        let index = if s.stop { 0.0 } else { s.medium.n_d };
        out.push_str(&format!(
            "{}\t{}\t{}\t{}\n",
            exact(s.radius_mm),
            exact(s.thickness_mm.unwrap_or(0.0)),
            exact(index),
            exact(2.0 * s.semi_aperture_mm)
        ));
    }
    Ok(out)
}
