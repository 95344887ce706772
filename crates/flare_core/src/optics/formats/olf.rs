//! OpenLensFlare's optical systems (`.xml`), so users of that flare renderer bring their lenses.
//!
//! # How it works
//! The format (OpenLensFlare's `examples/systems/*.xml`): an `<opticalSystem>` with `<name>`, `<fnumber>`,
//! `<effectiveFocalLength>`, `<fieldOfView>`, `<filmWidth>`, `<filmHeight>` and `<elements>`, each
//! `<element>` holding `<type>` (`lensSpherical`, `apertureStop`, `sensor`), `<height>` (the clear
//! semi-aperture: read so, the example systems' paraxial f-numbers come out near their stated `<fnumber>`,
//! read as diameters twice it), `<thickness>` (to the next element), `<radius>` (0 flat), `<refractiveIndex>` (n_d after the
//! surface), `<abbeNumber>`, `<coatingLambda>` (nm, 0 bare) and `<coatingIor>` (0: the ideal
//! `max(sqrt(n0 n2), 1.38)`), as a quarter-wave coating. The `sensor` element ends the lens (the element
//! before it gives the distance to the image). `<fnumber>` sets the stop's semi-diameter as a `.zmx` FNUM
//! does, and a warning says so; `<effectiveFocalLength>` is checked (a warning beyond 2 %); film size and
//! field of view are the document's sensor, not the lens's, and are not used. `lensAspherical` (which the
//! format gives no coefficients for) and aperture textures (`<mask>`) are refused or said, by line. XML is read
//! with quick-xml; every error names the line.

use quick_xml::Reader;
use quick_xml::events::Event;

use super::text::{FormatError, LoadedLens, StopScaling, StopScalingError, finish_text_lens, scale_stop_to_pupil};
use crate::optics::lens::{Coating, Medium, Surface, round};
use crate::optics::paraxial::FirstOrder;

const FORMAT: &str = "OpenLensFlare .xml";

fn line_error(line: usize, message: impl Into<String>) -> FormatError {
    FormatError::Line { format: FORMAT, line, message: crate::files::clean(&message.into()) }
}

/// True when `text` looks like an OpenLensFlare optical system.
pub(crate) fn looks_like(text: &str) -> bool {
    text.trim_start().starts_with('<') && text.contains("<opticalSystem")
}

/// One `<element>` as read, with the line it starts on.
#[derive(Default)]
struct Element {
    line: usize,
    fields: Vec<(String, String, usize)>,
}

impl Element {
    fn text(&self, key: &str) -> Option<(&str, usize)> {
        self.fields.iter().rev().find(|(k, _, _)| k == key).map(|(_, v, l)| (v.as_str(), *l))
    }

    fn number(&self, key: &str, default: Option<f64>) -> Result<f64, FormatError> {
        match self.text(key) {
            Some((v, line)) => v
                .trim()
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| line_error(line, format!("<{key}> `{}` is not a number", v.trim()))),
            None => default.ok_or_else(|| line_error(self.line, format!("the element has no <{key}>"))),
        }
    }
}

/// The line of a byte offset, counting only the newlines since the last offset asked for (the reader's
/// offsets only grow): linear in the file, where counting from the start for every element was quadratic.
struct Lines<'a> {
    text: &'a str,
    offset: usize,
    line: usize,
}

impl Lines<'_> {
    fn at(&mut self, offset: u64) -> usize {
        let offset = (offset as usize).min(self.text.len());
        if offset < self.offset {
            (self.offset, self.line) = (0, 1);
        }
        self.line += self.text.as_bytes()[self.offset..offset].iter().filter(|&&b| b == b'\n').count();
        self.offset = offset;
        self.line
    }
}

/// The `<opticalSystem>`'s own fields as (tag, text, line).
type SystemFields = Vec<(String, String, usize)>;

/// Reads `text`'s XML: the `<opticalSystem>`'s own fields and its `<elements>`, every value with its line.
fn read_xml(text: &str) -> Result<(SystemFields, Vec<Element>), FormatError> {
    let mut lines = Lines { text, offset: 0, line: 1 };
    let mut line_of = |offset: u64| lines.at(offset);
    let mut reader = Reader::from_str(text);
    let mut path: Vec<String> = Vec::new();
    let mut system: Vec<(String, String, usize)> = Vec::new();
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let at = line_of(reader.buffer_position());
        let event = reader
            .read_event()
            .map_err(|e| line_error(line_of(reader.error_position()), format!("not well-formed XML: {e}")))?;
        match event {
            Event::Start(e) => {
                let tag = String::from_utf8_lossy(e.name().as_ref()).into_owned();
                if tag == "element" && path.last().is_some_and(|p| p == "elements") {
                    elements.push(Element { line: at, ..Element::default() });
                }
                path.push(tag);
            }
            Event::End(_) => {
                path.pop();
            }
            Event::Text(t) => {
                let value = t.decode().map_err(|e| line_error(at, format!("text is not UTF-8: {e}")))?.into_owned();
                if value.trim().is_empty() {
                    continue;
                }
                let Some(tag) = path.last().cloned() else { continue };
                match path.len() {
                    2 if path[0] == "opticalSystem" => system.push((tag, value, at)),
                    4 if path[1] == "elements" && path[2] == "element" => {
                        if let Some(e) = elements.last_mut() {
                            e.fields.push((tag, value, at));
                        }
                    }
                    _ => {}
                }
            }
            Event::Eof => break,
            _ => {}
        }
    }
    if !path.is_empty() {
        return Err(line_error(line_of(text.len() as u64), format!("<{}> is never closed", path.last().unwrap())));
    }
    Ok((system, elements))
}

/// The surface of element `e` (the aperture stop where `stop`); an aperture texture it names is not used,
/// and `warnings` says so.
fn element_surface(e: &Element, stop: bool, warnings: &mut Vec<String>) -> Result<Surface, FormatError> {
    let height = e.number("height", None)?;
    let n_d = e.number("refractiveIndex", Some(1.0))?;
    let abbe = e.number("abbeNumber", Some(0.0))?;
    let radius_mm = if stop { 0.0 } else { e.number("radius", Some(0.0))? };
    let v_d = (n_d != 1.0 && abbe > 0.0).then_some(abbe);
    let glass = (n_d == 1.0).then(|| "air".to_owned());
    let mut s = Surface::new(radius_mm, Some(e.number("thickness", None)?), Medium { n_d, v_d, glass }, height);
    s.stop = stop;
    let lambda = e.number("coatingLambda", Some(0.0))?;
    let coating_ior = e.number("coatingIor", Some(0.0))?;
    if lambda > 0.0 {
        s.coating = Coating::QuarterWave {
            design_wavelength_nm: lambda,
            layer_index: (coating_ior > 0.0).then_some(coating_ior),
        };
    }
    for key in ["mask", "maskFT"] {
        if let Some((v, line)) = e.text(key) {
            warnings.push(format!(
                "line {line}: the aperture texture <{key}> {} is not used (set the stop's shape in the Aperture panel)",
                v.trim()
            ));
        }
    }
    Ok(s)
}

/// Parses and validates an OpenLensFlare optical system.
pub fn parse(text: &str, id_hint: &str) -> Result<LoadedLens, FormatError> {
    let (system, elements) = read_xml(text)?;
    let field = |key: &str| system.iter().find(|(k, _, _)| k == key).map(|(_, v, l)| (v.trim().to_owned(), *l));
    let mut warnings = Vec::new();
    let (mut surfaces, mut lines) = (Vec::new(), Vec::new());
    let mut ended = false;
    for e in &elements {
        let (kind, kind_line) = e.text("type").ok_or_else(|| line_error(e.line, "the element has no <type>"))?;
        if ended {
            return Err(line_error(e.line, "an element after the sensor"));
        }
        match kind.trim() {
            "sensor" => {
                ended = true;
                continue;
            }
            "lensSpherical" | "apertureStop" => {}
            "lensAspherical" => {
                return Err(FormatError::Unsupported {
                    format: FORMAT,
                    line: kind_line,
                    what: "lensAspherical (the format gives no aspheric coefficients)".to_owned(),
                });
            }
            other => {
                return Err(line_error(
                    kind_line,
                    format!("element type `{other}` is not one of lensSpherical, apertureStop, sensor"),
                ));
            }
        }
        surfaces.push(element_surface(e, kind.trim() == "apertureStop", &mut warnings)?);
        lines.push(e.line);
    }
    if surfaces.is_empty() {
        return Err(FormatError::Structure { format: FORMAT, message: "no <element> in <elements>".to_owned() });
    }
    let name = field("name").map(|(v, _)| v).unwrap_or_default();
    let number = |key: &str| -> Result<Option<(f64, usize)>, FormatError> {
        match field(key) {
            None => Ok(None),
            Some((v, line)) => v
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite() && *x > 0.0)
                .map(|x| Some((x, line)))
                .ok_or_else(|| line_error(line, format!("<{key}> `{v}` is not a positive number"))),
        }
    };
    let f_number = number("fnumber")?;
    let efl = number("effectiveFocalLength")?;
    if let Some((f, line)) = f_number {
        size_stop_to_f_number(&mut surfaces, f, line, &mut warnings)?;
    }
    let mut loaded = finish_text_lens(surfaces, name, id_hint, &lines, warnings)?;
    if let Some((f, line)) = efl
        && let Ok(fo) = FirstOrder::d_line(&loaded.lens)
        && (fo.efl_mm - f).abs() > 0.02 * f
    {
        loaded.warnings.push(format!(
            "line {line}: <effectiveFocalLength> {} mm, but the prescription's paraxial focal length is {} mm",
            round(f),
            round(fo.efl_mm)
        ));
    }
    Ok(loaded)
}

/// Scales the stop so that the lens works at `f_number` (EFL / entrance pupil diameter), and says so.
fn size_stop_to_f_number(
    surfaces: &mut [Surface],
    f_number: f64,
    line: usize,
    warnings: &mut Vec<String>,
) -> Result<(), FormatError> {
    let scaled = scale_stop_to_pupil(surfaces, |fo| fo.efl_mm / f_number).map_err(|e| match e {
        StopScalingError::NoFirstOrder(e) => {
            line_error(line, format!("<fnumber> needs the lens's first-order data, and there are none: {e}"))
        }
        StopScalingError::NoUsableSize => {
            line_error(line, format!("<fnumber> {} gives no usable stop size", round(f_number)))
        }
    })?;
    if let Some(StopScaling { stop, given_mm, semi_mm }) = scaled {
        warnings.push(format!(
            "line {line}: <fnumber> {} sets the stop's (surface {stop}) semi-diameter to {} mm (its height said {} mm)",
            round(f_number),
            round(semi_mm),
            round(given_mm)
        ));
    }
    Ok(())
}
