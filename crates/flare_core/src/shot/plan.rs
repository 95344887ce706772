//! The plan of a shot: for every frame of a range, where the light is, how bright, and which plate.
//!
//! # How it works
//! [`check_range`] refuses, before any work, a range that a plate sequence does not cover (the frames on
//! disk are listed; a frame missing *inside* the sequence is not refused here: that frame fails when it is
//! drawn and the others still render). [`plan`] then fixes the frame size (the given size, else the plate's,
//! else 1280x720) and the sensor it spans (the document's width, the image's aspect), and per frame takes the
//! timeline's keyed or static light. When the document finds the light in the plate ([`crate::footage::detect`]),
//! every plate of the range is read (in parallel) and scanned first; the solved position replaces the light
//! and the filtered visibility is kept. A planned frame's request is the document's request of that frame
//! ([`crate::preset::Document::frame_request_at`], whose light gain is `2^light_ev` there) with the planned
//! light put in ([`FramePlan::apply_to`]: the position, and the gain times the visibility), so an intensity key
//! edited after the light was found takes effect at once. The light's pixel is always the light angle through the lens's mapping
//! ([`crate::optics::mapping::ImageMapping`]), `None` when it lands outside the frame. The light found in the
//! plate needs a plate: a document asking for it without one is refused.

use std::ops::RangeInclusive;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use crate::footage::detect::{self, DetectError, Scan};
use crate::footage::pattern::FramePattern;
use crate::frame::FrameRequest;
use crate::ghost::GhostSystem;
use crate::optics::sensor::Sensor;
use crate::preset::Document;
use crate::shutter::LightPath;

/// The size of a frame with no plate and no size given.
pub(crate) const DEFAULT_SIZE: (u32, u32) = (1280, 720);

/// One planned frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FramePlan {
    pub frame: i64,
    /// Frame position of the light (degrees, X right, Y up).
    pub light_deg: [f64; 2],
    /// Where the light images (pixels from the top-left corner, y down); `None` outside the frame.
    pub light_px: Option<[f64; 2]>,
    /// The light's visibility in the plate (1 when it is not found in the plate): it multiplies the timeline's
    /// `2^light_ev` into the frame's light gain ([`Self::apply_to`]).
    pub visibility: f64,
    /// The plate file of the frame.
    pub plate: Option<PathBuf>,
    /// With the light found in the plate and the shutter open: the light while it is open, its positions read
    /// between the neighbouring frames' solved ones ([`track_path`]). `None`: the timeline's path stands.
    pub motion: Option<LightPath>,
}

/// Every frame of a range, planned (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct ShotPlan {
    pub frames: Vec<FramePlan>,
    pub width: u32,
    pub height: u32,
    pub sensor: Sensor,
}

impl FramePlan {
    /// Puts this frame's light into `request` (the document's request of the same frame): its position, and
    /// the visibility times the timeline's intensity there.
    pub fn apply_to(&self, request: &mut FrameRequest) {
        request.light_deg = self.light_deg;
        request.light_gain *= self.visibility;
        if self.motion.is_some() {
            request.motion = self.motion.clone();
        }
    }
}

impl ShotPlan {
    /// The frame request of planned frame `plan` (`divisor`: the accumulation divisor).
    pub fn request(&self, doc: &Document, system: &GhostSystem, plan: &FramePlan, divisor: u32) -> FrameRequest {
        let mut request = doc.frame_request_at(system, plan.frame as f64, self.width, self.height, divisor);
        plan.apply_to(&mut request);
        request
    }
}

/// The light while the shutter is open on `frame`, the `i`th frame of a range whose solved positions are
/// `positions` (one per frame, in order): read linearly between neighbouring frames, and past either end of
/// the range at the speed of its last step; the intensity is the timeline's, relative to the frame's. `None`
/// when the shutter is closed or the light stands still.
pub fn track_path(doc: &Document, positions: &[[f64; 2]], i: usize, frame: i64) -> Option<LightPath> {
    let n = positions.len();
    if i >= n {
        return None;
    }
    let position = |dt: f64| -> [f64; 2] {
        if n == 1 {
            return positions[0];
        }
        let x = i as f64 + dt;
        let k = (x.floor().max(0.0) as usize).min(n - 2);
        let t = x - k as f64;
        let (a, b) = (positions[k], positions[k + 1]);
        [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t]
    };
    let timeline = &doc.timeline;
    let ev = |t: f64| timeline.light_ev.value_at(t, timeline.interpolation).unwrap_or(0.0);
    let here = frame as f64;
    let (open, close) = crate::shutter::open_interval(here, timeline.shutter_deg);
    let path = LightPath::over(open, close, |t| {
        (position(t - here), f64::from(crate::color::gain_from_ev(ev(t) - ev(here))))
    })?;
    path.moves().then_some(path)
}

/// Why a shot cannot be planned.
#[derive(Debug, thiserror::Error)]
pub enum ShotError {
    #[error("{0}")]
    Range(String),
    #[error("frame {frame}: plate {path}: {reason}")]
    Plate { frame: i64, path: String, reason: String },
    #[error(transparent)]
    Detect(#[from] DetectError),
    #[error("cancelled")]
    Cancelled,
}

/// Refuses a range the document's plate sequence does not cover, or an empty range (see the module
/// documentation); returns the frames of the sequence on disk (empty without a sequence).
pub fn check_range(doc: &Document, frames: &RangeInclusive<i64>) -> Result<Vec<i64>, ShotError> {
    if frames.is_empty() {
        return Err(ShotError::Range(format!("frames {}-{}: the range is empty", frames.start(), frames.end())));
    }
    let Some(background) = doc.background.as_deref() else { return Ok(Vec::new()) };
    let Some(pattern) = FramePattern::parse(background).map_err(ShotError::Range)? else { return Ok(Vec::new()) };
    let on_disk = pattern.existing_frames();
    let (Some(&first), Some(&last)) = (on_disk.first(), on_disk.last()) else {
        return Err(ShotError::Range(format!("no file of the plate sequence {background} exists")));
    };
    if *frames.start() < first || *frames.end() > last {
        return Err(ShotError::Range(format!(
            "frames {}-{} are outside the plate sequence {background}, which has frames {first}-{last} ({} files)",
            frames.start(),
            frames.end(),
            on_disk.len()
        )));
    }
    Ok(on_disk)
}

/// The size of the frames of `range`: `size` when given, else the size of the first plate of the range on
/// disk, else `DEFAULT_SIZE`. Refuses a range the plate sequence does not cover ([`check_range`]) and a frame
/// that would need more memory than it may take ([`crate::frame::check_frame_memory`]).
pub fn frame_size(
    doc: &Document,
    range: &RangeInclusive<i64>,
    size: Option<(u32, u32)>,
) -> Result<(u32, u32), ShotError> {
    let on_disk = check_range(doc, range)?;
    let first = range.clone().find(|f| on_disk.is_empty() || on_disk.contains(f));
    let plate = first.and_then(|f| Some((f, doc.plate_at(f)?)));
    let (width, height) = match (size, &plate) {
        (Some(size), _) => size,
        (None, None) => DEFAULT_SIZE,
        // The header alone, the EXR's display window included (its decoder pads the data window out to it).
        (None, Some((frame, path))) => crate::output::image_size(path, "plate")
            .map_err(|reason| ShotError::Range(format!("frame {frame}: {reason}")))?,
    };
    crate::frame::check_frame_memory(width, height, doc.desqueeze, plate.is_some())
        .map_err(|e| ShotError::Range(e.to_string()))?;
    Ok((width, height))
}

/// Plans `frames` of `doc` (see the module documentation). `size`: the frame size (`None`: the plate's);
/// `progress(done, total)` is called while plates are scanned; `cancel` stops the scan.
pub fn plan(
    doc: &Document,
    system: &GhostSystem,
    frames: RangeInclusive<i64>,
    size: Option<(u32, u32)>,
    progress: &(dyn Fn(usize, usize) + Sync),
    cancel: &AtomicBool,
) -> Result<ShotPlan, ShotError> {
    let list: Vec<i64> = frames.clone().collect();
    let plates: Vec<Option<PathBuf>> = list.iter().map(|&f| doc.plate_at(f)).collect();
    let (width, height) = frame_size(doc, &frames, size)?;
    // The light is found and placed on the sensor's pixels: a desqueezed frame has more of them than the
    // delivered frame (and its plates).
    let (columns, rows) = crate::frame::sensor_pixels(width, height, doc.desqueeze);
    let sensor = Sensor::for_frame(doc.sensor_width_mm, columns, rows);
    let mapping = &system.mapping;
    let to_delivered = [f64::from(width) / f64::from(columns), f64::from(height) / f64::from(rows)];
    // Where a light images (delivered pixels), when that lands at least `margin` pixels inside the frame.
    let inside = |deg: [f64; 2], margin: f64| {
        let p = mapping.pixel_for_light_deg(deg, &sensor, columns, rows);
        let p = [p[0] * to_delivered[0], p[1] * to_delivered[1]];
        let within = |v: f64, size: u32| v.is_finite() && v >= margin && v <= f64::from(size) - margin;
        (within(p[0], width) && within(p[1], height)).then_some(p)
    };
    let solved = match &doc.auto_light {
        None => None,
        Some(_) if doc.background.is_none() => {
            return Err(ShotError::Range("the light is found in the plate, and the document has no plate".into()));
        }
        Some(auto) => {
            let done = std::sync::atomic::AtomicUsize::new(0);
            let scans: Vec<Option<Scan>> = plates
                .par_iter()
                .map(|path| {
                    if cancel.load(Ordering::Relaxed) {
                        return None;
                    }
                    // A plate that cannot be read is a frame with no light here; drawing it reports why.
                    let scan = path.as_deref().and_then(|p| super::plate::read_plate_in(&doc.color, p).ok()).map(
                        |(plate, _)| {
                            let scan = detect::detect(&plate, auto.threshold);
                            // The scan's pixels are the plate's; the frame may be drawn at another size.
                            let (sx, sy) = (
                                f64::from(columns) / f64::from(plate.width),
                                f64::from(rows) / f64::from(plate.height),
                            );
                            Scan {
                                detection: scan.detection.map(|d| detect::Detection {
                                    centroid_px: [d.centroid_px[0] * sx, d.centroid_px[1] * sy],
                                    ..d
                                }),
                                ..scan
                            }
                        },
                    );
                    progress(done.fetch_add(1, Ordering::Relaxed) + 1, plates.len());
                    scan
                })
                .collect();
            if cancel.load(Ordering::Relaxed) {
                return Err(ShotError::Cancelled);
            }
            let keyed = |f: i64| (!doc.timeline.light_deg.is_empty()).then(|| doc.light_at(f as f64));
            let to_deg = |px: [f64; 2]| mapping.light_deg_for_pixel(px, &sensor, columns, rows);
            let on_plate = |deg: [f64; 2], margin: f64| inside(deg, margin).is_some();
            Some(detect::solve(&list, &scans, auto, to_deg, keyed, on_plate)?)
        }
    };
    let positions: Option<Vec<[f64; 2]>> = solved.as_ref().map(|s| s.iter().map(|l| l.light_deg).collect());
    let frames = list
        .iter()
        .enumerate()
        .map(|(i, &frame)| {
            let (light_deg, visibility) = match &solved {
                Some(s) => (s[i].light_deg, s[i].visibility),
                None => (doc.light_at(frame as f64), 1.0),
            };
            let motion = positions.as_deref().and_then(|p| track_path(doc, p, i, frame));
            FramePlan {
                frame,
                light_deg,
                light_px: inside(light_deg, 0.0),
                visibility,
                plate: plates[i].clone(),
                motion,
            }
        })
        .collect();
    Ok(ShotPlan { frames, width, height, sensor })
}
