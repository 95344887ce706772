//! Rendering a planned shot to an image sequence, every frame through the one frame pipeline and the one
//! writer; the command line's `render --frames` and the app's File > Export sequence both call
//! [`render_sequence`].
//!
//! # How it works
//! Each planned frame ([`super::plan`]) becomes a [`FrameRequest`](crate::frame::FrameRequest), a
//! [`Frame`] and a file, exactly as a still is made ([`crate::frame::render_to_file`]). A frame whose file
//! exists and reads back whole (every pixel decoded: [`reads_back_whole`]) is skipped when asked (`skip_existing`,
//! to resume a stopped render; a truncated or damaged file is drawn again); a frame that fails (its plate is
//! missing or unreadable, the file cannot be written) is recorded with the reason and the others still render.
//! On a GPU the frames are drawn one after another on the one device, while the previous frame's layers are
//! encoded and written on a second thread (unless ghost layers are asked for: those are drawn on the same
//! device, so they are written in turn). On the CPU twin the frames are drawn in parallel on rayon's pool (each
//! frame's passes are parallel too; frames in parallel also overlap reading and writing). On the GPU a plate
//! shared by consecutive frames (a still background) is read once. With `traced` set, each frame's ghosts are
//! ray-traced ([`crate::traced`]) on the device (a GPU for a fixed grid, else the CPU) instead of drawn. Every frame reports a [`FrameRecord`]
//! (frame, light pixel and angle, visibility, milliseconds, outcome), the same record [`write_log`] writes.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

use super::plan::{FramePlan, ShotPlan};
use crate::flare::PreparedFlare;
use crate::footage::pattern::FramePattern;
use crate::frame::{self, Device, Frame, LayerChoice, Made, Sources};
use crate::image::HdrImage;
use crate::lut::blend::LiveLut;
use crate::preset::Document;
use crate::traced::TracedGhosts;

/// How a sequence is written.
#[derive(Clone, Debug)]
pub struct SequenceOptions {
    /// The output files (`out/flare.####.exr`).
    pub out: FramePattern,
    pub layers: LayerChoice,
    /// Leave a frame whose file exists as it is.
    pub skip_existing: bool,
    /// Accumulation divisor (1, 2 or 4).
    pub divisor: u32,
    /// On the CPU twin, draw frames in parallel (false: one after another, each frame's passes still
    /// parallel; for measuring which is faster).
    pub parallel_frames: bool,
    /// Ghosts ray-traced instead of drawn (`--method raygrid | reference`); their layers traced too.
    pub traced: Option<Arc<TracedGhosts>>,
}

/// What happened to a frame.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(rename_all = "snake_case", tag = "status", content = "error")]
pub enum FrameOutcome {
    Rendered,
    Skipped,
    Failed(String),
}

/// One frame of the log.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FrameRecord {
    pub frame: i64,
    /// Where the light images on the frame (pixels, y down); `null` when it is off the frame.
    pub light_px: Option<[f64; 2]>,
    pub light_deg: [f64; 2],
    pub visibility: f64,
    /// Wall time of the frame: reading its plate, building, drawing and writing.
    pub ms: f64,
    #[serde(flatten)]
    pub outcome: FrameOutcome,
    #[serde(skip)]
    pub path: PathBuf,
}

/// Every frame's record, in frame order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SequenceReport {
    pub records: Vec<FrameRecord>,
    /// What clamping a plate's values said (the first plate that needed it), to be said once for the sequence.
    pub plate_warning: Option<String>,
}

impl SequenceReport {
    pub fn count(&self, what: fn(&FrameOutcome) -> bool) -> usize {
        self.records.iter().filter(|r| what(&r.outcome)).count()
    }
    pub fn failed(&self) -> usize {
        self.count(|o| matches!(o, FrameOutcome::Failed(_)))
    }
    pub fn rendered(&self) -> usize {
        self.count(|o| *o == FrameOutcome::Rendered)
    }
    pub fn skipped(&self) -> usize {
        self.count(|o| *o == FrameOutcome::Skipped)
    }

    /// The median wall time of the rendered frames (0 when none was).
    pub fn median_ms(&self) -> f64 {
        let mut ms: Vec<f64> =
            self.records.iter().filter(|r| r.outcome == FrameOutcome::Rendered).map(|r| r.ms).collect();
        ms.sort_by(f64::total_cmp);
        ms.get(ms.len() / 2).copied().unwrap_or(0.0)
    }

    /// Every failed frame with its reason, in frame order.
    pub fn failures(&self) -> Vec<(i64, &str)> {
        self.records
            .iter()
            .filter_map(|r| match &r.outcome {
                FrameOutcome::Failed(e) => Some((r.frame, e.as_str())),
                _ => None,
            })
            .collect()
    }
}

/// What one frame is drawn from.
pub struct ShotSources<'a> {
    pub doc: &'a Document,
    pub flare: &'a PreparedFlare,
    pub lut: Option<&'a LiveLut>,
    pub plan: &'a ShotPlan,
}

/// The last plate read (defocused, with the depth of field on), kept for the next frame that uses the same
/// plate and depth files.
type PlateCache = Option<((PathBuf, Option<PathBuf>), Arc<HdrImage>)>;

fn plate_for(
    plan: &FramePlan,
    sources: &ShotSources,
    cache: &mut PlateCache,
    warned: &std::sync::Mutex<Option<String>>,
) -> Result<Option<Arc<HdrImage>>, String> {
    let Some(path) = &plan.plate else { return Ok(None) };
    let key = (path.clone(), sources.doc.dof.enabled.then(|| sources.doc.depth_at(plan.frame)).flatten());
    if let Some((k, img)) = cache
        && *k == key
    {
        return Ok(Some(img.clone()));
    }
    if !path.exists() {
        return Err(format!("frame {}: plate {} is missing", plan.frame, path.display()));
    }
    let (plate, warning) =
        super::plate::frame_plate(sources.doc, sources.flare, plan.frame, path).map_err(|e| match e {
            super::plate::FramePlateError::Plate(e) => format!("frame {}: plate {}: {e}", plan.frame, path.display()),
            super::plate::FramePlateError::DepthOfField(e) => format!("frame {}: {e}", plan.frame),
        })?;
    if let (Some(warning), Ok(mut first)) = (warning, warned.lock())
        && first.is_none()
    {
        *first = Some(warning);
    }
    let img = Arc::new(plate);
    *cache = Some((key, img.clone()));
    Ok(Some(img))
}

fn record(plan: &FramePlan, path: PathBuf, started: Instant, outcome: FrameOutcome) -> FrameRecord {
    FrameRecord {
        frame: plan.frame,
        light_px: plan.light_px,
        light_deg: plan.light_deg,
        visibility: plan.visibility,
        ms: started.elapsed().as_secs_f64() * 1e3,
        outcome,
        path,
    }
}

/// A frame's outcome from the result of drawing or writing it to `path`.
fn outcome_of<T>(frame: i64, path: &Path, result: Result<T, frame::FrameError>) -> FrameOutcome {
    match result {
        Ok(_) => FrameOutcome::Rendered,
        Err(e) => FrameOutcome::Failed(format!("frame {frame}: {}: {e}", path.display())),
    }
}

/// A drawn frame waiting to be written by the writer thread.
struct Pending {
    frame: Frame,
    made: Made,
    plate: Option<Arc<HdrImage>>,
    path: PathBuf,
    plan: FramePlan,
    started: Instant,
}

/// Frame `plan` of the shot, as the document and its timeline make it.
fn frame_of(plan: &FramePlan, sources: &ShotSources, options: &SequenceOptions) -> Frame {
    let request = sources.plan.request(sources.doc, &sources.flare.system, plan, options.divisor);
    Frame::build(sources.flare, sources.lut, &request)
}

/// Draws frame `plan` on the CPU twin and writes it to `path`.
fn write_on_cpu(
    plan: &FramePlan,
    sources: &ShotSources,
    options: &SequenceOptions,
    path: &Path,
    warned: &std::sync::Mutex<Option<String>>,
) -> FrameOutcome {
    let plate = match plate_for(plan, sources, &mut None, warned) {
        Ok(plate) => plate,
        Err(e) => return FrameOutcome::Failed(e),
    };
    let frame = frame_of(plan, sources, options);
    let s = Sources { flare: sources.flare, lut: sources.lut, plate: plate.as_deref() };
    let written = match &options.traced {
        Some(t) => t.render_to_file(&Device::Cpu, &frame, &s, options.layers, path).map(|_| ()),
        None => frame::render_to_file(&mut Device::Cpu, &frame, &s, options.layers, path),
    };
    outcome_of(plan.frame, path, written)
}

/// Writes a frame the GPU drew (on the writer thread, while the GPU draws the next).
fn write_pending(p: &Pending, sources: &ShotSources, options: &SequenceOptions) -> FrameOutcome {
    let s = Sources { flare: sources.flare, lut: sources.lut, plate: p.plate.as_deref() };
    // No ghost layers here: the CPU device is never asked to draw.
    let written = frame::write_made(&mut Device::Cpu, &p.frame, &s, &p.made, options.layers, &p.path);
    outcome_of(p.plan.frame, &p.path, written)
}

/// Renders every planned frame (see the module documentation). `on_frame(record, done, total)` is called as
/// each frame finishes (from worker threads on the CPU twin); `cancel` stops before the next frame.
pub fn render_sequence(
    device: &mut Device,
    sources: &ShotSources,
    options: &SequenceOptions,
    on_frame: &(dyn Fn(&FrameRecord, usize, usize) + Sync),
    cancel: &AtomicBool,
) -> SequenceReport {
    let total = sources.plan.frames.len();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let finish = |r: FrameRecord| {
        on_frame(&r, done.fetch_add(1, Ordering::Relaxed) + 1, total);
        r
    };
    // A frame is skipped only when its file reads back whole: a truncated or damaged one is drawn again.
    let skip = |path: &Path| options.skip_existing && path.exists() && reads_back_whole(path);
    let warned = std::sync::Mutex::new(None);
    let mut records: Vec<FrameRecord> = match device {
        Device::Cpu | Device::LostGpu(_) => {
            let one = |plan: &FramePlan| {
                let started = Instant::now();
                let path = options.out.path(plan.frame);
                if cancel.load(Ordering::Relaxed) {
                    return None;
                }
                if skip(&path) {
                    return Some(finish(record(plan, path, started, FrameOutcome::Skipped)));
                }
                let outcome = write_on_cpu(plan, sources, options, &path, &warned);
                Some(finish(record(plan, path, started, outcome)))
            };
            if options.parallel_frames {
                sources.plan.frames.par_iter().filter_map(one).collect()
            } else {
                sources.plan.frames.iter().filter_map(one).collect()
            }
        }
        Device::Gpu(_) => {
            let write_apart = !options.layers.ghosts;
            let (tx, rx) = std::sync::mpsc::sync_channel::<Pending>(1);
            let finish = &finish;
            std::thread::scope(|scope| {
                let writer = scope.spawn(move || {
                    rx.into_iter()
                        .map(|p| {
                            let outcome = write_pending(&p, sources, options);
                            finish(record(&p.plan, p.path, p.started, outcome))
                        })
                        .collect::<Vec<_>>()
                });
                let mut inline = Vec::new();
                let mut cache: PlateCache = None;
                for plan in &sources.plan.frames {
                    if cancel.load(Ordering::Relaxed) {
                        break;
                    }
                    let started = Instant::now();
                    let path = options.out.path(plan.frame);
                    if skip(&path) {
                        inline.push(finish(record(plan, path, started, FrameOutcome::Skipped)));
                        continue;
                    }
                    let plate = match plate_for(plan, sources, &mut cache, &warned) {
                        Ok(p) => p,
                        Err(e) => {
                            inline.push(finish(record(plan, path, started, FrameOutcome::Failed(e))));
                            continue;
                        }
                    };
                    let frame = frame_of(plan, sources, options);
                    let s = Sources { flare: sources.flare, lut: sources.lut, plate: plate.as_deref() };
                    let made = match &options.traced {
                        Some(t) => t.draw_for_file(device, &frame, &s, options.layers, &path).map(|(made, _)| made),
                        None => frame::draw_for_file(device, &frame, &s, options.layers, &path),
                    };
                    let made = match made {
                        Ok(d) => d,
                        Err(e) => {
                            let failed = FrameOutcome::Failed(format!("frame {}: {e}", plan.frame));
                            inline.push(finish(record(plan, path, started, failed)));
                            continue;
                        }
                    };
                    if write_apart {
                        let pending = Pending { frame, made, plate, path, plan: plan.clone(), started };
                        if tx.send(pending).is_err() {
                            break;
                        }
                    } else {
                        let written = match &options.traced {
                            Some(t) => t.write_made(device, &frame, &s, &made, options.layers, &path),
                            None => frame::write_made(device, &frame, &s, &made, options.layers, &path),
                        };
                        let outcome = outcome_of(plan.frame, &path, written);
                        inline.push(finish(record(plan, path, started, outcome)));
                    }
                }
                drop(tx);
                let mut all = writer.join().unwrap_or_default();
                all.extend(inline);
                all
            })
        }
    };
    records.sort_by_key(|r| r.frame);
    SequenceReport { records, plate_warning: warned.into_inner().ok().flatten() }
}

/// Writes the log: a JSON array with one record per frame, through a temporary file and a rename.
pub fn write_log(path: &Path, report: &SequenceReport) -> std::io::Result<()> {
    let text = serde_json::to_string_pretty(&report.records).map_err(std::io::Error::other)?;
    crate::files::write_atomic(path, text.as_bytes())
}

/// Whether the image at `path` decodes completely (a PNG through `image`, an EXR every channel of every layer
/// through `exr`): what `skip_existing` asks of a frame before it trusts it.
pub fn reads_back_whole(path: &Path) -> bool {
    match crate::output::ImageKind::from_path(path) {
        Ok(crate::output::ImageKind::Png) => crate::output::open_image(path, "frame").is_ok(),
        Ok(crate::output::ImageKind::Exr) => {
            crate::output::exr_size(path, "frame").is_ok() && exr::prelude::read_all_data_from_file(path).is_ok()
        }
        Err(_) => false,
    }
}
