//! A tracker's 2D track of the light, as CSV: `frame,x_px,y_px[,intensity_ev]`, turned into light keys.
//!
//! # How it works
//! Pixel coordinates are those of the frame (the plate's, when there is one): origin at the top-left corner
//! of the top-left pixel, x right, y down, so the centre of pixel (i, j) is (i + 0.5, j + 0.5). The optional
//! fourth column is the light's intensity in stops relative to the document's (0: as set). A first row whose
//! frame field is not a number is a header and skipped; blank lines and lines starting with `#` are skipped.
//! Every other row must have three or four fields; a bad number, a repeated frame or a pixel outside the
//! lens's traced field is refused with its line number. [`to_keys`] turns each row into one key per frame:
//! the pixel becomes a sensor point (the frame spans the sensor, [`crate::optics::sensor`]) and the sensor
//! point the light angle whose chief ray lands there ([`crate::optics::mapping::ImageMapping`]).

use crate::optics::mapping::ImageMapping;
use crate::optics::sensor::Sensor;
use crate::timeline::Track;

/// One row of a track.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackRow {
    /// The row's line in the file (from 1).
    pub line: usize,
    pub frame: i64,
    pub x_px: f64,
    pub y_px: f64,
    pub intensity_ev: Option<f64>,
}

/// Why a track cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum TrackError {
    #[error("{0}")]
    Read(String),
    #[error("line {line}: {reason}")]
    Line { line: usize, reason: String },
    #[error("the track has no rows (expected `frame,x_px,y_px[,intensity_ev]`)")]
    Empty,
}

/// Reads and parses a track file.
pub fn read_track(path: &std::path::Path) -> Result<Vec<TrackRow>, TrackError> {
    let text = crate::files::read_text_bounded(path, crate::files::MAX_TEXT_BYTES).map_err(TrackError::Read)?;
    parse_track(&text)
}

/// Parses a track's text (see the module documentation); rows come back sorted by frame.
pub fn parse_track(text: &str) -> Result<Vec<TrackRow>, TrackError> {
    let mut rows: Vec<TrackRow> = Vec::new();
    // The line each frame was given on (a repeated frame is refused naming both): linear in the rows.
    let mut given: std::collections::HashMap<i64, usize> = std::collections::HashMap::new();
    let mut seen_data = false;
    for (n, raw) in text.lines().enumerate() {
        let line = n + 1;
        let content = raw.trim();
        if content.is_empty() || content.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = content.split(',').map(str::trim).collect();
        if !seen_data && fields[0].parse::<f64>().is_err() {
            // The header row.
            seen_data = true;
            continue;
        }
        seen_data = true;
        let bad = |reason: String| TrackError::Line { line, reason: crate::files::clean(&reason) };
        if !(3..=4).contains(&fields.len()) {
            return Err(bad(format!("{} fields; expected frame,x_px,y_px[,intensity_ev] (`{content}`)", fields.len())));
        }
        let frame: i64 = fields[0].parse().map_err(|_| bad(format!("frame `{}` is not a whole number", fields[0])))?;
        let number = |k: usize, name: &str| -> Result<f64, TrackError> {
            match fields[k].parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                _ => Err(bad(format!("{name} `{}` is not a finite number", fields[k]))),
            }
        };
        let (x_px, y_px) = (number(1, "x_px")?, number(2, "y_px")?);
        let intensity_ev = if fields.len() == 4 { Some(number(3, "intensity_ev")?) } else { None };
        if let Some(ev) = intensity_ev
            && ev.abs() > 64.0
        {
            return Err(bad(format!("intensity_ev {ev} is outside -64 to 64 stops")));
        }
        if let Some(previous) = given.insert(frame, line) {
            return Err(bad(format!("frame {frame} was already given on line {previous}")));
        }
        rows.push(TrackRow { line, frame, x_px, y_px, intensity_ev });
    }
    if rows.is_empty() {
        return Err(TrackError::Empty);
    }
    rows.sort_by_key(|r| r.frame);
    // The frames it spans become the timeline's: no more than a timeline may hold.
    let (first, last) = (&rows[0], &rows[rows.len() - 1]);
    if let Err(reason) = crate::timeline::check_frame_count(first.frame, last.frame) {
        return Err(TrackError::Line { line: last.line, reason });
    }
    Ok(rows)
}

/// The light keys of `rows` (pixels of the delivered `width` x `height` frame) for a frame spanning
/// `sensor_width_mm` desqueezed by `desqueeze` ([`crate::frame::FrameRequest::desqueeze`]: a row's pixel is
/// taken to the sensor's pixels, [`crate::frame::sensor_pixels`]) through the lens's `mapping`: a position key per row and an
/// intensity key per row that has one.
pub fn to_keys(
    rows: &[TrackRow],
    mapping: &ImageMapping,
    sensor_width_mm: f64,
    (width, height): (u32, u32),
    desqueeze: f64,
) -> Result<(Track<[f64; 2]>, Track<f64>), TrackError> {
    let (columns, sensor_rows) = crate::frame::sensor_pixels(width, height, desqueeze);
    let sensor = &Sensor::for_frame(sensor_width_mm, columns, sensor_rows);
    let to_sensor = [f64::from(columns) / f64::from(width.max(1)), f64::from(sensor_rows) / f64::from(height.max(1))];
    let mut position = Track::default();
    let mut intensity = Track::default();
    for row in rows {
        let px = [row.x_px * to_sensor[0], row.y_px * to_sensor[1]];
        let deg = mapping.light_deg_for_pixel(px, sensor, columns, sensor_rows).ok_or_else(|| TrackError::Line {
            line: row.line,
            reason: format!(
                "pixel ({}, {}) lies outside the lens's traced field (chief rays reach {:.1} deg) on a {:.1} mm \
                     sensor of {width}x{height} pixels",
                row.x_px,
                row.y_px,
                mapping.traced_max_deg(),
                sensor.width_mm
            ),
        })?;
        position.set(row.frame, deg);
        if let Some(ev) = row.intensity_ev {
            intensity.set(row.frame, ev);
        }
    }
    Ok((position, intensity))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_track_with_a_header_parses_and_sorts() {
        let rows = parse_track("frame,x_px,y_px\n2, 10.5, 20\n\n# a comment\n1,11,21,-1.5\n").unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!((rows[0].frame, rows[0].line, rows[0].intensity_ev), (1, 5, Some(-1.5)));
        assert_eq!((rows[1].frame, rows[1].x_px, rows[1].y_px), (2, 10.5, 20.0));
        // No header.
        assert_eq!(parse_track("1,2,3").unwrap().len(), 1);
    }

    #[test]
    fn a_bad_row_names_its_line() {
        let cases = [
            ("frame,x,y\n1,2,3\n2,abc,4\n", 3, "x_px `abc`"),
            ("1,2,3\n2,3\n", 2, "2 fields"),
            ("1,2,3\n1.5,3,4\n", 2, "frame `1.5`"),
            ("1,2,3\n1,3,4\n", 2, "already given on line 1"),
            ("1,2,3,nan\n", 1, "intensity_ev"),
            ("1,2,inf\n", 1, "y_px"),
        ];
        for (text, line, words) in cases {
            let e = parse_track(text).unwrap_err();
            let message = e.to_string();
            assert!(matches!(e, TrackError::Line { line: l, .. } if l == line), "{text:?}: {message}");
            assert!(message.contains(words), "{text:?}: {message}");
        }
        assert!(matches!(parse_track("frame,x,y\n"), Err(TrackError::Empty)));
    }
}
