//! Zemax OpticStudio sequential lens files (`.zmx`).
//!
//! # How it works
//! A `.zmx` file is a list of keyword lines. `SURF n` opens surface n; surface 0 is the object and the last
//! is the image, the ones between are the lens. Inside a surface FlareLab reads `TYPE` (`STANDARD`,
//! `EVENASPH` or `TOROIDAL`), `CURV` (curvature, 1/length; 0 = flat), `CONI` (conic constant), `PARM n` of an
//! even asphere (`PARM 1` the r^2 term, `PARM 2..8` the r^4..r^16 terms, scaled by the unit) or of a toroid
//! (`PARM 1` the radius of rotation, 0 for flat in x, `PARM 2` the y^2 term, `PARM 3..8` the y^4..y^14 terms:
//! `CURV`, `CONI` and these make the y-z profile), `XDAT` of a toroid only where it is 0 (its Zernike terms
//! are not modelled and are refused by line), `DISZ` (thickness to the
//! next surface), `GLAS` (name, then two flags, then n_d and V_d of the model or catalogue glass; the name is
//! looked up in the file's `GCAT` catalogues first, in their order, so `GCAT CDGM` makes `F5` CDGM's), `DIAM` (the
//! *semi*-diameter) and `STOP`. `UNIT` scales lengths to millimetres and `NAME` names the lens. The system
//! aperture sets the stop's semi-diameter: `ENPD d` (entrance pupil diameter) or `FNUM F` (image-space F/#,
//! so `d = EFL / F`) scale it so that the paraxial entrance pupil has that diameter, and a warning says
//! which one won; `FLOA` (float by stop size) keeps the stop's `DIAM`. Anything that would change the optics
//! and that FlareLab does not model (other surface types, mirrors, non-circular apertures, non-sequential
//! mode, other aperture types) is refused by name with its line; purely cosmetic keywords (comments,
//! colours, solves' flags) are skipped.

use super::text::{
    FormatError, LoadedLens, StopScaling, StopScalingError, exact, finish_text_lens, scale_stop_to_pupil,
};
use crate::optics::glass::find_glass;
use crate::optics::lens::{Lens, MAX_ASPHERIC_TERMS, Medium, Surface, round};
use crate::optics::paraxial::FirstOrder;

const FORMAT: &str = "Zemax .zmx";

fn line_error(line: usize, message: impl Into<String>) -> FormatError {
    FormatError::Line { format: FORMAT, line, message: crate::files::clean(&message.into()) }
}

fn unsupported(line: usize, what: impl Into<String>) -> FormatError {
    FormatError::Unsupported { format: FORMAT, line, what: what.into() }
}

fn number(line: usize, field: &str, token: Option<&str>) -> Result<f64, FormatError> {
    let token = token.ok_or_else(|| line_error(line, format!("{field} has no value")))?;
    let shown = crate::files::shorten(token);
    let v: f64 = token.parse().map_err(|_| line_error(line, format!("{field} value `{shown}` is not a number")))?;
    if v.is_finite() { Ok(v) } else { Err(line_error(line, format!("{field} value `{shown}` is not finite"))) }
}

/// One `SURF` block as read, before it becomes a [`Surface`].
#[derive(Default)]
struct Block {
    line: usize,
    curvature: f64,
    thickness: Option<f64>,
    thickness_infinite: bool,
    glass: Option<(usize, Medium)>,
    semi_diameter: Option<f64>,
    stop: bool,
    even_asphere: bool,
    toroidal: bool,
    conic: f64,
    /// PARM 1..8 as read (unscaled), with their lines.
    parms: [(usize, f64); 8],
}

/// The system aperture a file declares, with its line.
#[derive(Clone, Copy, Debug, PartialEq)]
enum SystemAperture {
    EntrancePupilDiameter { line: usize, diameter_mm: f64 },
    ImageFNumber { line: usize, f_number: f64 },
    FloatByStop { line: usize },
}

/// Parses and validates a `.zmx` text.
pub fn parse(text: &str, id_hint: &str) -> Result<LoadedLens, FormatError> {
    let mut blocks: Vec<Block> = Vec::new();
    let mut name = String::new();
    let mut scale_to_mm = 1.0;
    let mut apertures: Vec<SystemAperture> = Vec::new();
    // The catalogues the file's glasses come from, in the order OpticStudio searches them.
    let gcat: Vec<String> = text
        .lines()
        .filter_map(|l| l.trim().strip_prefix("GCAT "))
        .flat_map(|rest| rest.split_whitespace().map(str::to_ascii_uppercase))
        .collect();
    // The surface keywords given so far in the current SURF block, with their lines: a keyword that changes
    // the optics given twice is refused (which one was meant cannot be known; the last silently won).
    let mut given: Vec<(String, usize)> = Vec::new();
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let mut tokens = raw.split_whitespace();
        let Some(keyword) = tokens.next() else { continue };
        let top_level = !raw.starts_with([' ', '\t']);
        if keyword == "SURF" {
            given.clear();
        } else if !blocks.is_empty() {
            once_per_surface(&mut given, raw, line, blocks.len() - 1)?;
        }
        match keyword {
            "MODE" => {
                if let Some(mode) = tokens.next().filter(|m| *m != "SEQ") {
                    return Err(unsupported(line, format!("MODE {mode} (only sequential MODE SEQ)")));
                }
            }
            "NAME" if top_level || blocks.is_empty() => name = raw.trim()[4..].trim().to_owned(),
            "UNIT" => {
                scale_to_mm = match tokens.next() {
                    Some("MM") => 1.0,
                    Some("CM") => 10.0,
                    Some("IN") => 25.4,
                    Some("METER" | "M") => 1000.0,
                    other => return Err(unsupported(line, format!("UNIT {}", other.unwrap_or("(none)")))),
                };
            }
            "SURF" => {
                let n = number(line, "SURF", tokens.next())?;
                if n != blocks.len() as f64 {
                    return Err(line_error(line, format!("SURF {n} out of order (expected SURF {})", blocks.len())));
                }
                blocks.push(Block { line, ..Block::default() });
            }
            "ENPD" if blocks.is_empty() => {
                let d = number(line, "ENPD", tokens.next())?;
                if d <= 0.0 {
                    return Err(line_error(line, format!("ENPD {d}: an entrance pupil diameter must be positive")));
                }
                apertures.push(SystemAperture::EntrancePupilDiameter { line, diameter_mm: d * scale_to_mm });
            }
            "FNUM" if blocks.is_empty() => {
                let f = number(line, "FNUM", tokens.next())?;
                if f <= 0.0 {
                    return Err(line_error(line, format!("FNUM {f}: an f-number must be positive")));
                }
                apertures.push(SystemAperture::ImageFNumber { line, f_number: f });
            }
            "FLOA" if blocks.is_empty() => apertures.push(SystemAperture::FloatByStop { line }),
            _ => {
                if let Some(block) = blocks.last_mut() {
                    surface_keyword(block, (line, keyword, raw), tokens, scale_to_mm, &gcat)?;
                }
            }
        }
    }
    build(blocks, name, id_hint, &apertures, scale_to_mm)
}

/// Refuses a keyword that changes the optics given twice in one SURF block (which one was meant cannot be
/// known; the last used to win silently). `given` holds the block's keywords so far with their lines.
fn once_per_surface(
    given: &mut Vec<(String, usize)>,
    raw: &str,
    line: usize,
    surface: usize,
) -> Result<(), FormatError> {
    let mut tokens = raw.split_whitespace();
    let key = match tokens.next() {
        Some("PARM") => format!("PARM {}", tokens.next().unwrap_or("")),
        Some(k @ ("TYPE" | "CURV" | "CONI" | "DISZ" | "DIAM" | "STOP" | "GLAS")) => k.to_owned(),
        _ => return Ok(()),
    };
    if let Some((_, first)) = given.iter().find(|(k, _)| *k == key) {
        return Err(line_error(
            line,
            format!(
                "{} repeated in SURF {surface} (first on line {first}): which value is meant is unclear",
                crate::files::shorten(&key)
            ),
        ));
    }
    given.push((key, line));
    Ok(())
}

/// Reads one keyword of a SURF block into `block`: `raw` is line `line`, `keyword` its first word, `tokens` what
/// follows it; lengths in the file's unit (`scale_to_mm` mm each), glasses looked up in `gcat` first.
fn surface_keyword(
    block: &mut Block,
    (line, keyword, raw): (usize, &str, &str),
    mut tokens: std::str::SplitWhitespace,
    scale_to_mm: f64,
    gcat: &[String],
) -> Result<(), FormatError> {
    match keyword {
        "TYPE" => match tokens.next() {
            Some("STANDARD") => {}
            Some("EVENASPH") => block.even_asphere = true,
            Some("TOROIDAL") => block.toroidal = true,
            other => return Err(unsupported(line, format!("surface TYPE {}", other.unwrap_or("(none)")))),
        },
        "CURV" => block.curvature = number(line, "CURV", tokens.next())? / scale_to_mm,
        "CONI" => block.conic = number(line, "CONI", tokens.next())?,
        "PARM" => {
            let n = number(line, "PARM", tokens.next())?;
            let v = number(line, &format!("PARM {n}"), tokens.next())?;
            if n.fract() != 0.0 || !(0.0..=8.0).contains(&n) {
                if v != 0.0 {
                    return Err(unsupported(line, format!("PARM {n} = {v} (an even asphere has PARM 1 to 8)")));
                }
            } else if n >= 1.0 {
                block.parms[n as usize - 1] = (line, v);
            }
        }
        "DISZ" => match tokens.next() {
            Some("INFINITY") => block.thickness_infinite = true,
            t => block.thickness = Some(number(line, "DISZ", t)? * scale_to_mm),
        },
        "DIAM" => block.semi_diameter = Some(number(line, "DIAM", tokens.next())? * scale_to_mm),
        "STOP" => block.stop = true,
        "GLAS" => {
            let medium = glass_line(line, &raw.split_whitespace().collect::<Vec<_>>(), gcat)?;
            block.glass = Some((line, medium));
        }
        "SQAP" | "ELAP" | "OBSC" | "OBDC" | "SPID" => {
            return Err(unsupported(line, format!("aperture {keyword} (only circular clear apertures)")));
        }
        "XDAT" => {
            // A toroid's extra data are its Zernike terms (their count, the normalisation radius, the
            // coefficients): all 0 is a plain toroid; anything else changes the surface and is refused.
            let _index = tokens.next();
            let value = tokens.next().and_then(|t| t.parse::<f64>().ok());
            let plain_toroid = block.toroidal && value == Some(0.0);
            if !plain_toroid {
                return Err(unsupported(
                    line,
                    "extra data XDAT (Zernike terms of a TOROIDAL surface, or a special surface's data)",
                ));
            }
        }
        _ => {}
    }
    Ok(())
}

/// Reads a `GLAS name flag flag n_d V_d ...` line. The name is looked up in the file's `GCAT` catalogues
/// first; where that finds another glass than the plain name would, the medium keeps `CATALOGUE:NAME`.
fn glass_line(line: usize, tokens: &[&str], gcat: &[String]) -> Result<Medium, FormatError> {
    let name = *tokens.get(1).ok_or_else(|| line_error(line, "GLAS has no glass name"))?;
    if name.eq_ignore_ascii_case("MIRROR") {
        return Err(unsupported(line, "GLAS MIRROR (mirror surface; FlareLab models refractive lenses)"));
    }
    let given = |i: usize| tokens.get(i).and_then(|t| t.parse::<f64>().ok()).filter(|v| v.is_finite() && *v != 0.0);
    let model = name == "___BLANK";
    let plain = find_glass(name);
    let from_gcat = gcat.iter().find_map(|c| find_glass(&format!("{c}:{name}")));
    let catalogue = from_gcat.or(plain);
    let glass_name = match from_gcat {
        Some(g) if plain.is_none_or(|p| !std::ptr::eq(g, p)) => format!("{}:{name}", g.catalogue),
        _ => name.to_owned(),
    };
    let (n_d, v_d) = match (given(4), catalogue) {
        (Some(n_d), _) => (n_d, given(5)),
        (None, Some(g)) => (g.n_d, Some(g.v_d)),
        (None, None) => {
            return Err(line_error(
                line,
                format!("glass `{name}` is not in the built-in catalogue and the line gives no n_d (5th field)"),
            ));
        }
    };
    Ok(Medium { n_d, v_d, glass: (!model).then_some(glass_name) })
}

fn build(
    blocks: Vec<Block>,
    name: String,
    id_hint: &str,
    apertures: &[SystemAperture],
    scale_to_mm: f64,
) -> Result<LoadedLens, FormatError> {
    if blocks.len() < 3 {
        return Err(FormatError::Structure {
            format: FORMAT,
            message: format!(
                "found {} SURF blocks; a lens needs the object, at least one surface, and the image",
                blocks.len()
            ),
        });
    }
    let object = &blocks[0];
    if let Some((line, m)) = &object.glass
        && !m.is_air()
    {
        return Err(unsupported(*line, "an object surface in glass (object space must be air)"));
    }
    let image = blocks.len() - 1;
    let aperture = system_aperture(apertures);
    let stop_sized_by_file =
        matches!(aperture.0, Some(SystemAperture::EntrancePupilDiameter { .. } | SystemAperture::ImageFNumber { .. }));
    let mut surfaces = Vec::with_capacity(image - 1);
    let mut lines = Vec::with_capacity(image - 1);
    for (k, b) in blocks[1..image].iter().enumerate() {
        if b.thickness_infinite {
            return Err(line_error(b.line, format!("surface {k} has DISZ INFINITY (only the object may)")));
        }
        let semi_aperture_mm = match b.semi_diameter {
            Some(d) => d,
            // The system aperture sizes the stop: any positive placeholder will be scaled.
            None if b.stop && stop_sized_by_file => 1.0,
            None => return Err(line_error(b.line, format!("surface {k} has no DIAM (clear semi-diameter)"))),
        };
        let medium = b.glass.as_ref().map(|(_, m)| m.clone()).unwrap_or_else(Medium::air);
        let radius_mm = if b.curvature == 0.0 { 0.0 } else { 1.0 / b.curvature };
        let mut surface = Surface::new(radius_mm, Some(b.thickness.unwrap_or(0.0)), medium, semi_aperture_mm);
        surface.stop = b.stop;
        surface.conic = b.conic;
        if b.toroidal {
            // PARM 1 is the radius of rotation (a length); PARM n >= 2 multiplies y^(2n - 2), length^(3-2n).
            let scale = |n: usize| scale_to_mm.powi(3 - 2 * n as i32);
            surface.radius_x_mm = Some(b.parms[0].1 * scale_to_mm);
            surface.aspheric_r2 = b.parms[1].1 * scale(2);
            let mut terms: Vec<f64> = (3..=8).map(|n| b.parms[n - 1].1 * scale(n)).collect();
            while terms.last() == Some(&0.0) {
                terms.pop();
            }
            surface.aspheric = terms;
        } else if b.even_asphere {
            // PARM n multiplies r^(2n): in file units it is length^(1-2n).
            let scale = |n: usize| scale_to_mm.powi(1 - 2 * n as i32);
            surface.aspheric_r2 = b.parms[0].1 * scale(1);
            let mut terms: Vec<f64> = (2..=8).map(|n| b.parms[n - 1].1 * scale(n)).collect();
            while terms.last() == Some(&0.0) {
                terms.pop();
            }
            debug_assert!(terms.len() <= MAX_ASPHERIC_TERMS);
            surface.aspheric = terms;
        } else if let Some((n, (line, v))) = b.parms.iter().enumerate().find(|(_, (_, v))| *v != 0.0) {
            return Err(unsupported(
                *line,
                format!("PARM {} = {v} on a STANDARD surface (only TYPE EVENASPH and TOROIDAL have them)", n + 1),
            ));
        }
        surfaces.push(surface);
        lines.push(b.line);
    }
    let mut warnings = aperture.1;
    if let Some(a) = aperture.0 {
        size_stop(&mut surfaces, a, &lines, &mut warnings)?;
    }
    finish_text_lens(surfaces, name, id_hint, &lines, warnings)
}

/// The system aperture that wins (ENPD over FNUM; FLOA, float by stop size, over both, as OpticStudio
/// keeps the other values in the file when the type is changed) and the warnings for the ones it beat.
fn system_aperture(apertures: &[SystemAperture]) -> (Option<SystemAperture>, Vec<String>) {
    let rank = |a: &SystemAperture| match a {
        SystemAperture::FloatByStop { .. } => 0,
        SystemAperture::EntrancePupilDiameter { .. } => 1,
        SystemAperture::ImageFNumber { .. } => 2,
    };
    let Some(winner) = apertures.iter().min_by_key(|a| rank(a)).copied() else { return (None, Vec::new()) };
    let describe = |a: &SystemAperture| match *a {
        SystemAperture::FloatByStop { line } => format!("FLOA (line {line})"),
        SystemAperture::EntrancePupilDiameter { line, diameter_mm } => {
            format!("ENPD {} mm (line {line})", round(diameter_mm))
        }
        SystemAperture::ImageFNumber { line, f_number } => format!("FNUM {} (line {line})", round(f_number)),
    };
    let warnings = apertures
        .iter()
        .filter(|a| **a != winner)
        .map(|a| format!("the system aperture {} is ignored: {} wins", describe(a), describe(&winner)))
        .collect();
    (Some(winner), warnings)
}

/// Scales the stop's semi-diameter so that the paraxial entrance pupil has the diameter the file's ENPD
/// or FNUM asks for, and says so.
fn size_stop(
    surfaces: &mut [Surface],
    aperture: SystemAperture,
    lines: &[usize],
    warnings: &mut Vec<String>,
) -> Result<(), FormatError> {
    let (line, said) = match aperture {
        SystemAperture::FloatByStop { .. } => return Ok(()),
        SystemAperture::EntrancePupilDiameter { line, diameter_mm } => {
            (line, format!("ENPD {} mm", round(diameter_mm)))
        }
        SystemAperture::ImageFNumber { line, f_number } => (line, format!("FNUM {}", round(f_number))),
    };
    let wanted_epd_mm = |first_order: &FirstOrder| match aperture {
        SystemAperture::EntrancePupilDiameter { diameter_mm, .. } => diameter_mm,
        SystemAperture::ImageFNumber { f_number, .. } => first_order.efl_mm.abs() / f_number,
        SystemAperture::FloatByStop { .. } => unreachable!("returned above"),
    };
    let scaled = scale_stop_to_pupil(surfaces, wanted_epd_mm).map_err(|e| match e {
        StopScalingError::NoFirstOrder(e) => {
            line_error(line, format!("the system aperture needs the lens's first-order data, and there are none: {e}"))
        }
        StopScalingError::NoUsableSize => line_error(line, format!("{said} gives no usable stop size")),
    })?;
    let Some(StopScaling { stop, given_mm, semi_mm }) = scaled else { return Ok(()) };
    let had = if (semi_mm - given_mm).abs() <= 1e-6 * semi_mm {
        "as its DIAM says".to_owned()
    } else {
        format!("its DIAM said {} mm", round(given_mm))
    };
    warnings.push(format!(
        "the system aperture {said} (line {line}) sets the stop's (surface {stop}, line {}) semi-diameter to {} mm ({had})",
        lines[stop],
        round(semi_mm)
    ));
    Ok(())
}

/// The lens as a sequential `.zmx` text (UTF-8, millimetres, STANDARD, EVENASPH or TOROIDAL surfaces), which [`parse`]
/// reads back to the same prescription (curvature is stored as 1/R, so radii round-trip to the last bit or one
/// ulp). A toroid with an r^16 term is refused: Zemax's TOROIDAL stops at y^14.
pub fn write(lens: &Lens) -> Result<String, FormatError> {
    if let Some(k) = lens.surfaces.iter().position(|s| s.is_toroidal() && s.aspheric.len() > MAX_ASPHERIC_TERMS - 1) {
        return Err(FormatError::Structure {
            format: FORMAT,
            message: format!(
                "surface {k} is a toroid with a y^16 term, which Zemax's TOROIDAL (y^2 to y^14) cannot hold"
            ),
        });
    }
    let mut out = String::new();
    let mut push = |s: String| {
        out.push_str(&s);
        out.push('\n');
    };
    push("VERS 190000 0 0".to_owned());
    push("MODE SEQ".to_owned());
    push(format!("NAME {}", lens.name.replace(['\n', '\r'], " ")));
    push("UNIT MM X W X CM MR CPMM".to_owned());
    // A glass kept as `CATALOGUE:NAME` (one that a GCAT picked on reading) is written by its plain name, with
    // a GCAT line naming the catalogues of the lens's glasses in the order they first appear.
    let named = |s: &crate::optics::lens::Surface| {
        s.medium.glass.clone().filter(|g| !s.medium.is_air() && !g.is_empty() && !g.contains(char::is_whitespace))
    };
    if lens.surfaces.iter().filter_map(named).any(|g| g.contains(':')) {
        let mut catalogues: Vec<String> = Vec::new();
        for g in lens.surfaces.iter().filter_map(named).filter_map(|g| find_glass(&g)) {
            if !catalogues.contains(&g.catalogue) {
                catalogues.push(g.catalogue.clone());
            }
        }
        push(format!("GCAT {}", catalogues.join(" ")));
    }
    push("SURF 0".to_owned());
    push("  TYPE STANDARD".to_owned());
    push("  CURV 0.0".to_owned());
    push("  DISZ INFINITY".to_owned());
    for (k, s) in lens.surfaces.iter().enumerate() {
        push(format!("SURF {}", k + 1));
        if s.stop {
            push("  STOP".to_owned());
        }
        if s.is_toroidal() {
            push("  TYPE TOROIDAL".to_owned());
        } else if s.is_spherical() {
            push("  TYPE STANDARD".to_owned());
        } else {
            push("  TYPE EVENASPH".to_owned());
        }
        push(format!("  CURV {}", exact(s.curvature_per_mm())));
        if s.conic != 0.0 {
            push(format!("  CONI {}", exact(s.conic)));
        }
        if let Some(r_x) = s.radius_x_mm {
            push(format!("  PARM 1 {}", exact(r_x)));
            push(format!("  PARM 2 {}", exact(s.aspheric_r2)));
            for n in 3..=8 {
                push(format!("  PARM {n} {}", exact(s.aspheric.get(n - 3).copied().unwrap_or(0.0))));
            }
        } else if !s.is_spherical() {
            push(format!("  PARM 1 {}", exact(s.aspheric_r2)));
            for n in 2..=8 {
                push(format!("  PARM {n} {}", exact(s.aspheric.get(n - 2).copied().unwrap_or(0.0))));
            }
        }
        push(format!("  DISZ {}", exact(s.thickness_mm.unwrap_or(0.0))));
        if !s.medium.is_air() {
            let name = named(s).map(|g| g.rsplit(':').next().unwrap_or_default().to_owned());
            push(format!(
                "  GLAS {} 1 0 {} {} 0 0 0 0 0 0",
                name.as_deref().unwrap_or("___BLANK"),
                exact(s.medium.n_d),
                exact(s.medium.v_d.unwrap_or(0.0))
            ));
        }
        push(format!("  DIAM {} 1 0 0 1 \"\"", exact(s.semi_aperture_mm)));
    }
    push(format!("SURF {}", lens.surfaces.len() + 1));
    push("  TYPE STANDARD".to_owned());
    push("  CURV 0.0".to_owned());
    push("  DISZ 0".to_owned());
    Ok(out)
}
