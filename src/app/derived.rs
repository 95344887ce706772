//! What the app derives from the document, kept apart from the UI ([`Derived`]): the prepared flare (rebuilt
//! only when the document's optics fingerprint changes; an impossible lens keeps the last valid one and says
//! why), the plate of the playhead's frame (a sequence's files kept decoded for scrubbing and read ahead on
//! threads while it plays), the LUT, and the frame (built again only when its request, the LUT or the plate changed),
//! with their GPU uploads through [`crate::viewport`]; how often each was rebuilt ([`RebuildCounts`]); and the
//! ghost list of a frame.
//!
//! # How it works
//! This is the app's frame source: [`Derived::sync`] takes the document by shared reference (it never writes
//! it: the automatic exposure is [`Derived::flare_ev`], an unreadable plate is shown as none with the reason)
//! and rebuilds what changed in order: the optics, the automatic exposure, the plate, the frame. Its fields are
//! private; the shell tells it only the view's inputs ([`Derived::set_playhead`], [`Derived::set_view_px`],
//! [`Derived::set_draft`], [`Derived::painted`]) and what jobs made ([`Derived::set_lut`],
//! [`Derived::set_shot_plan`], [`Derived::show_plate`] from the depth of field); everything else reads it
//! through its getters.

use std::sync::Arc;
use std::time::Instant;

use eframe::egui_wgpu::RenderState;
use flare_core::flare::PreparedFlare;
use flare_core::footage::pattern::FramePattern;
use flare_core::frame::{Draft, DraftOutcome, Frame, FrameRequest};
use flare_core::ghost::{FrameStats, GhostFrame, GhostSystem, Sprite};
use flare_core::image::HdrImage;
use flare_core::lut::blend::LiveLut;
use flare_core::lut::{GhostLut, LutKind};
use flare_core::optics::FirstOrder;
use flare_core::preset::{Document, LutSource};
use flare_core::render::gpu::LutAtlas;
use flare_core::shot::ShotPlan;

use super::plates::{PREFETCH, PlateCache};

use crate::panels::{GhostRow, LensProblem};
use crate::viewport::{ViewFrame, ViewportResources};

/// How often the app rebuilt what the document implies, for the tests and the status bar: display settings
/// (exposures, tonemap, starburst, plate exposure) must change only `frames`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RebuildCounts {
    /// Prepared flares built (ghost system, aperture mask, starburst FFT).
    pub optics: u64,
    /// GPU texture uploads (aperture, starburst, plate, LUT atlas).
    pub textures: u64,
    /// Frames built.
    pub frames: u64,
}

/// What the latest frame was built from: a new frame is built only when this changes.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameKey {
    pub optics: u64,
    pub request: FrameRequest,
    pub lut_generation: u64,
    pub plate_generation: u64,
}

/// The ghost list of a frame: each ghost's light summed over its wavelengths, and why it is culled.
pub fn ghost_rows(system: &GhostSystem, frame: &GhostFrame) -> Vec<GhostRow> {
    let mut rows: Vec<GhostRow> = system
        .ghosts
        .iter()
        .enumerate()
        .map(|(ghost, m)| GhostRow { ghost, i: m.i, j: m.j, rgb: [0.0; 3], culled: Some("no sprite") })
        .collect();
    for s in &frame.sprites {
        let row = &mut rows[s.ghost];
        for c in 0..3 {
            row.rgb[c] += s.rgb[c];
        }
        row.culled = match (row.culled, s.culled) {
            (_, None) => None,
            (None, Some(_)) => None,
            (Some("no sprite"), Some(r)) => Some(r.word()),
            (other, Some(_)) => other,
        };
    }
    rows
}

/// What a sync tells the app.
pub enum SyncEvent {
    /// Something the user should read (a bad aperture image, an unreadable plate).
    Message(String),
    /// The ray-traced LUT in use was dropped: it was baked for another lens or other settings.
    LutDropped,
}

/// The state derived from the document (see the module documentation).
pub struct Derived {
    /// The software adapter draws the viewport at half resolution.
    software: bool,
    optics_key: Option<u64>,
    /// The auto exposure and what it was computed for (the flare's id, the sensor width's bits).
    auto_exposure: Option<((u64, u64), f64)>,
    /// The prepared flare in use (the last valid one).
    flare: Option<Arc<PreparedFlare>>,
    /// What was rebuilt so far.
    rebuilds: RebuildCounts,
    first_order: Option<FirstOrder>,
    lens_problem: Option<LensProblem>,
    frame_key: Option<FrameKey>,
    /// The viewport's size in pixels.
    view_px: (u32, u32),
    /// The latest frame for the viewport, with its generation (see [`crate::viewport`]).
    view_frame: Option<ViewFrame>,
    /// The frame was rebuilt after the viewport was painted this UI frame.
    frame_pending: bool,
    ghosts: Vec<GhostRow>,
    sprites: Vec<Sprite>,
    stats: FrameStats,
    scene_ms: f64,
    /// The plate file shown (the background, or its sequence's file of the playhead's frame).
    background_key: Option<String>,
    /// The background plate the view and exports use (defocused when the depth of field is on and done).
    plate: Option<Arc<HdrImage>>,
    /// The plate as read, and a count of its changes (what the depth of field defocuses, `crate::app::jobs::dof`).
    sharp_plate: Option<Arc<HdrImage>>,
    sharp_generation: u64,
    /// Plates read lately or ahead of the playhead ([`PlateCache`]).
    plate_cache: PlateCache,
    /// The timeline frame shown.
    playhead: i64,
    /// The light found in the plates, when the document asks for it and it has been found.
    shot_plan: Option<Arc<ShotPlan>>,
    plate_generation: u64,
    lut: Option<Arc<LiveLut>>,
    lut_generation: u64,
    /// The LUT shown is the automatic bake's ([`Self::show_auto_lut`]).
    lut_auto: bool,
    /// The viewport draws this draft instead of the full frame (see [`crate::app::draft`]).
    draft: Option<Draft>,
    /// What the frame shown left out, when it is a draft.
    draft_shown: Option<DraftOutcome>,
}

impl Derived {
    pub fn new(software: bool) -> Self {
        Self {
            software,
            optics_key: None,
            auto_exposure: None,
            flare: None,
            rebuilds: RebuildCounts::default(),
            first_order: None,
            lens_problem: None,
            frame_key: None,
            view_px: (960, 540),
            view_frame: None,
            frame_pending: false,
            ghosts: Vec::new(),
            sprites: Vec::new(),
            stats: FrameStats::default(),
            scene_ms: 0.0,
            background_key: None,
            plate: None,
            sharp_plate: None,
            sharp_generation: 0,
            plate_cache: PlateCache::default(),
            playhead: 1,
            shot_plan: None,
            plate_generation: 0,
            lut: None,
            lut_generation: 0,
            lut_auto: false,
            draft: None,
            draft_shown: None,
        }
    }

    /// Re-derives what changed in `doc`, uploading to `gpu`. It only reads the document: an unreadable plate
    /// shows as none (the reason in a [`SyncEvent::Message`], said once per file) and stays in the document
    /// for the user to replace or remove.
    pub fn sync(&mut self, doc: &Document, gpu: Option<&RenderState>) -> Vec<SyncEvent> {
        let mut events = Vec::new();
        self.sync_optics(doc, gpu, &mut events);
        self.sync_exposure(doc);
        self.sync_background(doc, gpu, &mut events);
        self.sync_frame(doc);
        events
    }

    /// Auto exposure: the flare's exposure that follows the optics and the sensor (computed once per change
    /// of either). A derived value: it is never written into the document (an undo step must be the user's),
    /// and [`Self::flare_ev`] gives it to what draws.
    fn sync_exposure(&mut self, doc: &Document) {
        let Some(flare) = self.flare.as_deref() else { return };
        let key = (flare.id, doc.sensor_width_mm.to_bits());
        if !matches!(self.auto_exposure, Some((k, _)) if k == key) {
            let ev = flare_core::exposure::auto_flare_ev(&flare.system, doc.sensor_width_mm);
            self.auto_exposure = Some((key, ev));
        }
    }

    /// The flare's exposure the frame uses: the automatic one while `doc.exposure_auto` (once the optics are
    /// known), else the user's `doc.flare_ev`.
    pub fn flare_ev(&self, doc: &Document) -> f64 {
        match self.auto_exposure {
            Some((_, ev)) if doc.exposure_auto => ev,
            _ => doc.flare_ev,
        }
    }

    /// A copy of `doc` for a job or a file, its exposure the one the view uses ([`Self::flare_ev`]): what the
    /// command line draws from it (it resolves an automatic exposure the same way).
    pub fn resolved(&self, doc: &Document) -> Document {
        let mut resolved = Document { flare_ev: self.flare_ev(doc), ..doc.clone() };
        if self.lut_is_auto(doc) {
            // The LUT ghosts on screen are the automatic bake's: a file says "simulated", which the command
            // line fetches from the same cache (or bakes).
            resolved.blend.lut = LutSource::Simulated { path: None };
        }
        resolved
    }

    /// Whether the LUT on screen is the automatic bake's, drawn for a document that named none (a derived
    /// use, never written into the document: undo gives back exactly what was there).
    fn lut_is_auto(&self, doc: &Document) -> bool {
        self.lut_auto && self.lut.is_some() && doc.blend.lut == LutSource::None
    }

    /// The light found in the plates for the live document (or none): the frame shows it from now on.
    pub fn set_shot_plan(&mut self, plan: Option<ShotPlan>) {
        self.shot_plan = plan.map(Arc::new);
        self.frame_key = None;
    }

    // What the frame source derived, to read (its only writer is itself).

    /// The prepared flare in use (the last valid one).
    pub fn flare(&self) -> &Option<Arc<PreparedFlare>> {
        &self.flare
    }

    /// Why the document's lens is refused (the viewport keeps the last valid flare).
    pub fn lens_problem(&self) -> &Option<LensProblem> {
        &self.lens_problem
    }

    /// The valid lens's first-order properties (d line).
    pub fn first_order(&self) -> &Option<FirstOrder> {
        &self.first_order
    }

    /// The optics fingerprint the flare was last derived for.
    pub fn optics_key(&self) -> Option<u64> {
        self.optics_key
    }

    /// The plate as read (what the depth of field defocuses).
    pub fn sharp_plate(&self) -> &Option<Arc<HdrImage>> {
        &self.sharp_plate
    }

    /// A count of the sharp plate's changes.
    pub fn sharp_generation(&self) -> u64 {
        self.sharp_generation
    }

    /// The plate the view and exports use (defocused when the depth of field is on and done).
    pub fn plate(&self) -> &Option<Arc<HdrImage>> {
        &self.plate
    }

    /// The LUT in use.
    pub fn lut(&self) -> &Option<Arc<LiveLut>> {
        &self.lut
    }

    /// A count of the LUT's changes.
    pub fn lut_generation(&self) -> u64 {
        self.lut_generation
    }

    /// The viewport's drawing size in pixels.
    pub fn view_px(&self) -> (u32, u32) {
        self.view_px
    }

    /// The latest frame for the viewport, with its generation.
    pub fn view_frame(&self) -> &Option<ViewFrame> {
        &self.view_frame
    }

    /// What the latest frame was built from.
    pub fn frame_key(&self) -> &Option<FrameKey> {
        &self.frame_key
    }

    /// The frame was rebuilt after the viewport was painted this UI frame.
    pub fn frame_pending(&self) -> bool {
        self.frame_pending
    }

    /// The light found in the plates, when the document asks for it and it has been found.
    pub fn shot_plan(&self) -> &Option<Arc<ShotPlan>> {
        &self.shot_plan
    }

    /// What was rebuilt so far.
    pub fn rebuilds(&self) -> RebuildCounts {
        self.rebuilds
    }

    /// What the latest frame drew and culled.
    pub fn stats(&self) -> FrameStats {
        self.stats
    }

    /// The latest frame's ghost list.
    pub fn ghosts(&self) -> &Vec<GhostRow> {
        &self.ghosts
    }

    /// The latest frame's sprites.
    pub fn sprites(&self) -> &Vec<Sprite> {
        &self.sprites
    }

    /// How long the latest frame took to build (ms).
    pub fn scene_ms(&self) -> f64 {
        self.scene_ms
    }

    /// The timeline frame the frame shows.
    pub fn playhead(&self) -> i64 {
        self.playhead
    }

    /// The draft the viewport draws instead of the full frame, while the user drags.
    pub fn draft(&self) -> Option<Draft> {
        self.draft
    }

    /// What the frame shown left out, when it is a draft.
    pub fn draft_shown(&self) -> Option<DraftOutcome> {
        self.draft_shown
    }

    /// The frame the view shows from now on (the view's playhead).
    pub fn set_playhead(&mut self, frame: i64) {
        self.playhead = frame;
    }

    /// The viewport's drawing size changed: the frame is built again at it.
    pub fn set_view_px(&mut self, px: (u32, u32)) {
        self.view_px = px;
    }

    /// Draw `draft` (or the full frame) from the next build on.
    pub fn set_draft(&mut self, draft: Option<Draft>) {
        self.draft = draft;
    }

    /// The viewport painted the latest frame.
    pub fn painted(&mut self) {
        self.frame_pending = false;
    }

    /// Forgets the optics' key, so the next sync rebuilds the flare (after something outside the document
    /// changed its optics: a glass catalogue added).
    pub fn invalidate_optics(&mut self) {
        self.optics_key = None;
    }

    fn sync_optics(&mut self, doc: &Document, gpu: Option<&RenderState>, events: &mut Vec<SyncEvent>) {
        let key = doc.optics_fingerprint();
        if self.optics_key == Some(key) {
            return;
        }
        self.optics_key = Some(key);
        if let Err(e) = doc.lens.validate() {
            let (surface, field) = match &e {
                flare_core::optics::LensError::Field { surface, field, .. } => (Some(*surface), Some(*field)),
                _ => (None, None),
            };
            self.set_lens_problem(Some(LensProblem { surface, field, reason: e.to_string() }), events);
            return;
        }
        let config = match doc.flare_config() {
            Ok(config) => config,
            Err(e) => {
                // A bad aperture image or spectrum: the last valid flare stays, and the user is told.
                events.push(SyncEvent::Message(e.to_string()));
                return;
            }
        };
        self.rebuilds.optics += 1;
        match PreparedFlare::new(&doc.lens, &config) {
            Ok(flare) => {
                self.first_order = FirstOrder::d_line(&doc.lens).ok();
                if let Some(rs) = gpu {
                    ViewportResources::with(rs, |res, device, queue| {
                        res.renderer.set_aperture(device, queue, &flare.ghost_masks);
                        res.renderer.set_starburst(device, queue, &flare.starburst);
                        res.renderer.set_dirt(device, queue, flare.dirt.as_ref());
                    });
                    self.rebuilds.textures += 3;
                }
                // A ray-traced LUT is for one lens and its settings: refuse it for any other.
                if let Some(lut) = &self.lut
                    && lut.lut.kind == LutKind::RayTraced
                    && lut.lut.check_for(&doc.lens, &flare.config).is_err()
                {
                    self.set_lut(None, gpu);
                    events.push(SyncEvent::LutDropped);
                }
                self.flare = Some(Arc::new(flare));
                self.set_lens_problem(None, events);
            }
            Err(e) => {
                self.set_lens_problem(Some(LensProblem { surface: None, field: None, reason: e.to_string() }), events)
            }
        }
    }

    /// Records why the lens is refused (or that it is not), and says so in the status bar when that changes: the
    /// refusal with its reason, and once the lens is valid again, that the view follows it, so the refusal's words
    /// never outlive it.
    fn set_lens_problem(&mut self, problem: Option<LensProblem>, events: &mut Vec<SyncEvent>) {
        let said = match (&self.lens_problem, &problem) {
            (old, Some(new)) if old.as_ref().map(|o| &o.reason) != Some(&new.reason) => {
                Some(format!("lens edit refused: {}; the view keeps the last valid lens", new.reason))
            }
            (Some(_), None) => Some("the lens is valid again: the view follows it".to_owned()),
            _ => None,
        };
        events.extend(said.map(SyncEvent::Message));
        self.lens_problem = problem;
    }

    fn sync_background(&mut self, doc: &Document, gpu: Option<&RenderState>, events: &mut Vec<SyncEvent>) {
        let file = doc.plate_at(self.playhead).map(|p| p.display().to_string());
        let reread = self.plate_cache.read_as(doc.color.input_space.is_some().then(|| doc.color.clone()));
        if self.background_key == file && !reread {
            return;
        }
        self.background_key = file.clone();
        let sequence = doc.background.as_deref().is_some_and(FramePattern::is_pattern);
        let plate = match &file {
            Some(path) => match self.plate_cache.get(path) {
                Some(plate) => Some(plate),
                None => match flare_core::shot::plate::read_plate_in(&doc.color, std::path::Path::new(path)) {
                    Ok((p, warning)) => {
                        if let Some(warning) = warning {
                            // Said once: the plate is cached, not read again.
                            events.push(SyncEvent::Message(warning));
                        }
                        let p = Arc::new(p);
                        self.plate_cache.put(path.clone(), p.clone());
                        Some(p)
                    }
                    Err(e) if sequence => {
                        // One bad frame of a sequence: that frame shows no plate, the sequence stays.
                        events.push(SyncEvent::Message(format!("frame {}: {e}", self.playhead)));
                        None
                    }
                    Err(e) => {
                        // Said once (the key stays: the file is not read again every frame until it changes).
                        events.push(SyncEvent::Message(format!("{e}; the plate is not shown")));
                        None
                    }
                },
            },
            None => None,
        };
        if let Some(rs) = gpu {
            ViewportResources::with(rs, |res, device, queue| {
                res.renderer.set_background(device, queue, plate.as_deref())
            });
            self.rebuilds.textures += 1;
        }
        self.sharp_plate = plate.clone();
        self.sharp_generation += 1;
        self.plate = plate;
        self.plate_generation += 1;
        if sequence {
            // The next frames are read on threads meanwhile: playing forward rarely waits for a file.
            let ahead: Vec<String> = (1..=PREFETCH)
                .filter_map(|k| doc.plate_at(self.playhead + k))
                .map(|p| p.display().to_string())
                .collect();
            self.plate_cache.prefetch(&ahead);
        }
    }

    /// Uploads `plate` as the background the view draws and exports use (the depth of field's result, or the
    /// sharp plate back).
    pub fn show_plate(&mut self, plate: Option<Arc<HdrImage>>, gpu: Option<&RenderState>) {
        if let Some(rs) = gpu {
            ViewportResources::with(rs, |res, device, queue| {
                res.renderer.set_background(device, queue, plate.as_deref())
            });
            self.rebuilds.textures += 1;
        }
        self.plate = plate;
        self.plate_generation += 1;
    }

    /// Replaces the LUT in use (uploading its atlas): one the user opened or asked for.
    pub fn set_lut(&mut self, lut: Option<GhostLut>, gpu: Option<&RenderState>) {
        self.replace_lut(lut.map(|l| Arc::new(LiveLut::new(l))), false, gpu);
    }

    /// Shows the automatic bake's LUT (from memory, the cache or a bake): blended even while the document names
    /// no LUT (see [`Self::resolved`]). It comes prepared ([`LiveLut::new`] on the job's thread): what is left
    /// here is the upload.
    pub fn show_auto_lut(&mut self, live: Arc<LiveLut>, atlas: Option<LutAtlas>, gpu: Option<&RenderState>) {
        match (gpu, atlas) {
            (Some(rs), Some(atlas)) => {
                ViewportResources::with(rs, |res, _, _| res.renderer.set_lut_atlas(&live, atlas));
                self.rebuilds.textures += 1;
                self.lut_auto = true;
                self.lut = Some(live);
                self.lut_generation += 1;
            }
            (gpu, _) => self.replace_lut(Some(live), true, gpu),
        }
    }

    /// Takes the automatic bake's LUT off the screen (automatic baking was turned off); a LUT the user opened
    /// stays.
    pub fn drop_auto_lut(&mut self, gpu: Option<&RenderState>) {
        if self.lut_auto && self.lut.is_some() {
            self.replace_lut(None, false, gpu);
        }
    }

    fn replace_lut(&mut self, live: Option<Arc<LiveLut>>, auto: bool, gpu: Option<&RenderState>) {
        self.lut_auto = auto;
        if let Some(rs) = gpu {
            ViewportResources::with(rs, |res, device, queue| res.renderer.set_lut(device, queue, live.as_deref()));
            self.rebuilds.textures += 1;
        }
        self.lut = live;
        self.lut_generation += 1;
    }

    /// Whether the viewport's adapter is a software one (lavapipe, llvmpipe).
    pub fn software(&self) -> bool {
        self.software
    }

    /// The accumulation divisor of the viewport: half resolution on software adapters.
    pub fn view_divisor(&self) -> u32 {
        if self.software { 2 } else { 1 }
    }

    /// The request of the playhead's frame at `width` x `height`: the timeline's sample there, with the light
    /// found in the plate when there is one for that frame.
    pub fn request_at(
        &self,
        doc: &Document,
        flare: &PreparedFlare,
        width: u32,
        height: u32,
        divisor: u32,
    ) -> FrameRequest {
        let mut request = doc.frame_request_at(&flare.system, self.playhead as f64, width, height, divisor);
        request.display.flare_ev = self.flare_ev(doc);
        if self.lut_is_auto(doc) {
            request.lut_use = flare_core::frame::LutUse::Blend;
        }
        if let Some(planned) = self.shot_plan.as_ref().and_then(|p| p.frames.iter().find(|f| f.frame == self.playhead))
        {
            planned.apply_to(&mut request);
        }
        request
    }

    /// Where the light is in the frame shown (degrees).
    pub fn light_deg(&self, doc: &Document) -> [f64; 2] {
        self.frame_key.as_ref().map_or_else(|| doc.light_at(self.playhead as f64), |k| k.request.light_deg)
    }

    /// `draft` of the frame on screen, built aside (the viewport warms its draft passes with it); `None`
    /// before there is a flare.
    pub fn draft_of_view(&self, doc: &Document, draft: Draft) -> Option<Frame> {
        let flare = self.flare.as_ref()?;
        Some(Frame::build(flare, self.lut.as_deref(), &self.view_request(doc, flare, Some(draft))))
    }

    /// The request of the view's frame (at the viewport's size and divisor) as a draft `draft` or sharp.
    fn view_request(&self, doc: &Document, flare: &PreparedFlare, draft: Option<Draft>) -> FrameRequest {
        let (w, h) = self.view_px;
        FrameRequest { draft, ..self.request_at(doc, flare, w, h, self.view_divisor()) }
    }

    /// Builds the frame when what it shows changed.
    pub fn sync_frame(&mut self, doc: &Document) {
        let (Some(flare), Some(optics)) = (self.flare.clone(), self.optics_key) else { return };
        let key = FrameKey {
            optics,
            request: self.view_request(doc, &flare, self.draft),
            lut_generation: self.lut_generation,
            plate_generation: self.plate_generation,
        };
        if self.frame_key.as_ref() == Some(&key) {
            return;
        }
        let started = Instant::now();
        let frame = Frame::build(&flare, self.lut.as_deref(), &key.request);
        self.draft_shown = frame.draft;
        self.frame_key = Some(key);
        self.rebuilds.frames += 1;
        let rows = ghost_rows(&flare.system, &frame.sprites);
        self.ghosts = rows;
        self.sprites = frame.sprites.sprites.clone();
        self.stats = frame.sprites.stats;
        self.scene_ms = started.elapsed().as_secs_f64() * 1e3;
        let generation = self.view_frame.as_ref().map_or(1, |f| f.0 + 1);
        self.view_frame = Some((generation, Arc::new(frame)));
        self.frame_pending = true;
    }
}
