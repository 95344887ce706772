//! Zemax OpticStudio sequential lens files (`.zmx`).
//!
//! # How it works
//! A `.zmx` file is a list of keyword lines. `SURF n` opens surface n; surface 0 is the object and the last
//! is the image, the ones between are the lens. Inside a surface FlareLab reads `TYPE` (only `STANDARD`),
//! `CURV` (curvature, 1/length; 0 = flat), `DISZ` (thickness to the next surface), `GLAS` (name, then two
//! flags, then n_d and V_d of the model or catalogue glass), `DIAM` (the *semi*-diameter), `STOP`, and
//! `CONI` (which must be 0). `UNIT` scales lengths to millimetres and `NAME` names the lens. Anything that
//! would change the optics and that FlareLab does not model (other surface types, conics, mirrors,
//! non-circular apertures, non-sequential mode) is refused by name with its line; purely cosmetic keywords
//! (comments, colours, solves' flags) are skipped.

use super::text::{FormatError, exact, finish_text_lens};
use crate::optics::glass::find_glass;
use crate::optics::lens::{Lens, Medium, Surface};

const FORMAT: &str = "Zemax .zmx";

fn line_error(line: usize, message: impl Into<String>) -> FormatError {
    FormatError::Line { format: FORMAT, line, message: message.into() }
}

fn unsupported(line: usize, what: impl Into<String>) -> FormatError {
    FormatError::Unsupported { format: FORMAT, line, what: what.into() }
}

fn number(line: usize, field: &str, token: Option<&str>) -> Result<f64, FormatError> {
    let token = token.ok_or_else(|| line_error(line, format!("{field} has no value")))?;
    let v: f64 = token.parse().map_err(|_| line_error(line, format!("{field} value `{token}` is not a number")))?;
    if v.is_finite() { Ok(v) } else { Err(line_error(line, format!("{field} value `{token}` is not finite"))) }
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
}

/// Parses and validates a `.zmx` text.
pub fn parse(text: &str, id_hint: &str) -> Result<Lens, FormatError> {
    let mut blocks: Vec<Block> = Vec::new();
    let mut name = String::new();
    let mut scale_to_mm = 1.0;
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let mut tokens = raw.split_whitespace();
        let Some(keyword) = tokens.next() else { continue };
        let top_level = !raw.starts_with([' ', '\t']);
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
            _ if blocks.is_empty() => {}
            "TYPE" => match tokens.next() {
                Some("STANDARD") => {}
                other => return Err(unsupported(line, format!("surface TYPE {}", other.unwrap_or("(none)")))),
            },
            "CURV" => blocks.last_mut().unwrap().curvature = number(line, "CURV", tokens.next())? / scale_to_mm,
            "CONI" => {
                let k = number(line, "CONI", tokens.next())?;
                if k != 0.0 {
                    return Err(unsupported(line, format!("conic constant CONI {k} (aspheric surface)")));
                }
            }
            "DISZ" => {
                let b = blocks.last_mut().unwrap();
                match tokens.next() {
                    Some("INFINITY") => b.thickness_infinite = true,
                    t => b.thickness = Some(number(line, "DISZ", t)? * scale_to_mm),
                }
            }
            "DIAM" => {
                blocks.last_mut().unwrap().semi_diameter = Some(number(line, "DIAM", tokens.next())? * scale_to_mm)
            }
            "STOP" => blocks.last_mut().unwrap().stop = true,
            "GLAS" => {
                let medium = glass_line(line, &raw.split_whitespace().collect::<Vec<_>>())?;
                blocks.last_mut().unwrap().glass = Some((line, medium));
            }
            "SQAP" | "ELAP" | "OBSC" | "OBDC" | "SPID" => {
                return Err(unsupported(line, format!("aperture {keyword} (only circular clear apertures)")));
            }
            "XDAT" => return Err(unsupported(line, "extra data XDAT (aspheric or special surface)")),
            _ => {}
        }
    }
    build(blocks, name, id_hint)
}

/// Reads a `GLAS name flag flag n_d V_d ...` line.
fn glass_line(line: usize, tokens: &[&str]) -> Result<Medium, FormatError> {
    let name = *tokens.get(1).ok_or_else(|| line_error(line, "GLAS has no glass name"))?;
    if name.eq_ignore_ascii_case("MIRROR") {
        return Err(unsupported(line, "GLAS MIRROR (mirror surface; FlareLab models refractive lenses)"));
    }
    let given = |i: usize| tokens.get(i).and_then(|t| t.parse::<f64>().ok()).filter(|v| v.is_finite() && *v != 0.0);
    let model = name == "___BLANK";
    let catalogue = find_glass(name);
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
    Ok(Medium { n_d, v_d, glass: (!model).then(|| name.to_owned()) })
}

fn build(blocks: Vec<Block>, name: String, id_hint: &str) -> Result<Lens, FormatError> {
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
    let mut surfaces = Vec::with_capacity(image - 1);
    let mut lines = Vec::with_capacity(image - 1);
    for (k, b) in blocks[1..image].iter().enumerate() {
        if b.thickness_infinite {
            return Err(line_error(b.line, format!("surface {k} has DISZ INFINITY (only the object may)")));
        }
        let semi_aperture_mm = b
            .semi_diameter
            .ok_or_else(|| line_error(b.line, format!("surface {k} has no DIAM (clear semi-diameter)")))?;
        let medium = b.glass.as_ref().map(|(_, m)| m.clone()).unwrap_or_else(Medium::air);
        let radius_mm = if b.curvature == 0.0 { 0.0 } else { 1.0 / b.curvature };
        let surface = Surface::new(radius_mm, Some(b.thickness.unwrap_or(0.0)), medium, semi_aperture_mm);
        surfaces.push(Surface { stop: b.stop, ..surface });
        lines.push(b.line);
    }
    finish_text_lens(surfaces, name, id_hint, &lines)
}

/// The lens as a sequential `.zmx` text (UTF-8, millimetres, STANDARD surfaces), which [`parse`] reads back
/// to the same prescription (curvature is stored as 1/R, so radii round-trip to the last bit or one ulp).
pub fn write(lens: &Lens) -> String {
    let mut out = String::new();
    let mut push = |s: String| {
        out.push_str(&s);
        out.push('\n');
    };
    push("VERS 190000 0 0".to_owned());
    push("MODE SEQ".to_owned());
    push(format!("NAME {}", lens.name.replace(['\n', '\r'], " ")));
    push("UNIT MM X W X CM MR CPMM".to_owned());
    push("SURF 0".to_owned());
    push("  TYPE STANDARD".to_owned());
    push("  CURV 0.0".to_owned());
    push("  DISZ INFINITY".to_owned());
    for (k, s) in lens.surfaces.iter().enumerate() {
        push(format!("SURF {}", k + 1));
        if s.stop {
            push("  STOP".to_owned());
        }
        push("  TYPE STANDARD".to_owned());
        push(format!("  CURV {}", exact(s.curvature_per_mm())));
        push(format!("  DISZ {}", exact(s.thickness_mm.unwrap_or(0.0))));
        if !s.medium.is_air() {
            let name = s.medium.glass.as_deref().filter(|g| !g.is_empty() && !g.contains(char::is_whitespace));
            push(format!(
                "  GLAS {} 1 0 {} {} 0 0 0 0 0 0",
                name.unwrap_or("___BLANK"),
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
    out
}
