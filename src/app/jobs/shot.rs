//! The app's shot jobs, each on a thread with progress and Cancel, polled by the UI each frame (the window
//! never blocks): finding the light in every plate of the shot, and exporting a sequence. Both go through
//! `flare_core::shot` exactly as `flarelab render --frames` does.

use std::sync::Arc;

use super::job::Job;

use flare_core::flare::PreparedFlare;
use flare_core::footage::pattern::FramePattern;
use flare_core::frame::Device;
use flare_core::lut::blend::LiveLut;
use flare_core::preset::Document;
use flare_core::shot::plan::{ShotPlan, plan};
use flare_core::shot::sequence::{FrameOutcome, SequenceOptions, SequenceReport, ShotSources, render_sequence};

/// The export size without a plate or a size the user set.
pub const DEFAULT_EXPORT_PX: (u32, u32) = (1920, 1080);

/// What a job hands back.
pub enum ShotOutcome {
    /// The light found in the plates: the plan of the timeline's range, for the document whose
    /// [`light_key`] it was made from.
    Light { plan: ShotPlan, key: u64 },
    /// A sequence written (or stopped): every frame's record.
    Exported { report: SequenceReport, pattern: String, device: String },
}

/// What a shot job hands back, or why it stopped.
pub type ShotResult = Result<ShotOutcome, String>;

/// What the board's one shot job is for (see [`super::job::Slot`]): finding the light for the document of this
/// [`light_key`], or exporting a sequence.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShotKind {
    Light(u64),
    Export,
}

/// What the light found in the plates depends on: the plates, the detection settings, the range, the sensor,
/// the lens (its mapping) and the light keys (they continue a covered light).
pub fn light_key(doc: &Document) -> u64 {
    flare_core::fingerprint::of(&(
        &doc.background,
        &doc.auto_light,
        doc.timeline.first_frame,
        doc.timeline.last_frame,
        doc.sensor_width_mm,
        &doc.timeline.light_deg,
        doc.optics_fingerprint(),
    ))
}

/// Finds the light in every plate of `doc`'s timeline range.
pub fn find_light(doc: Document, flare: Arc<PreparedFlare>) -> Job<ShotResult> {
    Job::spawn("finding the light…", move |cancel, report| {
        let key = light_key(&doc);
        let range = doc.timeline.frames();
        let progress = |done: usize, total: usize| {
            report(done as f32 / total.max(1) as f32, format!("finding the light: {done}/{total} plates"));
        };
        let plan = plan(&doc, &flare.system, range, None, &progress, cancel).map_err(|e| e.to_string())?;
        Ok(ShotOutcome::Light { plan, key })
    })
}

/// Renders `doc`'s timeline range to `pattern` (at the plate's size, else `size`) on a headless GPU when
/// there is one (`gpu`), else on the CPU twin. `found`: the light already found in the plates for this
/// document (its [`light_key`] unchanged), which spares reading every plate again.
pub fn export(
    doc: Document,
    flare: Arc<PreparedFlare>,
    lut: Option<Arc<LiveLut>>,
    found: Option<Arc<ShotPlan>>,
    pattern: FramePattern,
    size: Option<(u32, u32)>,
    gpu: bool,
) -> Job<ShotResult> {
    Job::spawn("planning the frames…", move |cancel, report| {
        let range = doc.timeline.frames();
        // The user's size, else the plates' (the plan's own), else the default.
        let size = size.or_else(|| doc.background.is_none().then_some(DEFAULT_EXPORT_PX));
        let scanning = |done: usize, total: usize| {
            report(0.0, format!("finding the light: {done}/{total} plates"));
        };
        let plan = match found {
            // Planned for the plates' size over the same range: the export's own plan would be the same.
            Some(found) if size.is_none() => found,
            _ => Arc::new(plan(&doc, &flare.system, range, size, &scanning, cancel).map_err(|e| e.to_string())?),
        };
        let mut device = if gpu { Device::gpu(false).unwrap_or(Device::Cpu) } else { Device::Cpu };
        if let Some(dir) = std::path::Path::new(&pattern.text).parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        }
        let options = SequenceOptions {
            out: pattern.clone(),
            layers: doc.layer_choice(false),
            skip_existing: false,
            divisor: 1,
            parallel_frames: true,
            traced: None,
        };
        let sources = ShotSources { doc: &doc, flare: &flare, lut: lut.as_deref(), plan: &plan };
        let report = render_sequence(
            &mut device,
            &sources,
            &options,
            &|record, done, total| {
                let failed = matches!(record.outcome, FrameOutcome::Failed(_));
                report(
                    done as f32 / total.max(1) as f32,
                    format!("frame {} ({done}/{total}){}", record.frame, if failed { ", failed" } else { "" }),
                );
            },
            cancel,
        );
        Ok(ShotOutcome::Exported { report, pattern: pattern.text, device: device.name() })
    })
}
