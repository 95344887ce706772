//! One frame, drawn the same everywhere: the app's viewport and export, `flarelab render`, the benchmark and the
//! tests all turn a [`FrameRequest`] into a [`Frame`], draw it with one GPU entry point or its CPU twin
//! ([`Device`]), and write it with one writer (`crate::output::write_frame`).
//!
//! # How it works
//! A [`FrameRequest`] is everything that decides a frame besides the prepared optics: the light's position
//! and gain (a timeline's intensity times its visibility in the plate: it scales every ghost and the
//! starburst, and 0 draws no flare), the size and the sensor width it spans, the display settings (exposures in stops, tonemap, starburst), each lens ghost's gain (toggles
//! and solo already folded in, see [`crate::preset::Document::ghost_gains`]) and how LUT ghosts are used.
//! [`Frame::build`] makes the drawable frame in one pass: the LUT instances first (they say how much of each
//! non-linear ghost its paraxial sprite keeps), then the paraxial instances with the user's gain times that
//! weight applied as they are built, and the starburst's placement. With a moving light while the shutter is
//! open ([`FrameRequest::motion`], [`crate::shutter`]) it does so at each time sample and keeps each ghost's
//! own samples, weighted, in the one frame. Nothing edits a built frame afterwards: a
//! ghost's own layer is a frame built again with the other ghosts at gain 0 ([`Frame::ghost_alone`]).
//!
//! A desqueezed request ([`FrameRequest::desqueeze`], an anamorphic lens's squeeze undone) is built on the
//! sensor's square pixels ([`sensor_pixels`]: more rows, or more columns) and delivered at the request's size:
//! the tonemap and the layers sample the accumulation at the delivered pixels ([`crate::render::FlareScene::output_size`]).
//!
//! [`Device::draw`] draws a frame into an HDR accumulation (linear relative irradiance, before any gain) and
//! an 8-bit display image: on the GPU through [`FlareRenderer::render_with_lut`] (the same call the app's
//! viewport makes), or on the CPU through the twin passes of [`crate::render::cpu`] and
//! [`crate::lut::blend::lut_pass`]. [`Drawn::layers`] turns that into what a compositor gets, every layer at
//! the frame's size and linear: `flare` (accumulation x `2^flare_ev`), `starburst` (its share of the flare),
//! `dirt` (the front dirt's glow, its share of the flare, only for a dirty lens: [`crate::dirt`]),
//! `plate` (the plate x `2^plate_ev`) and the composite `flare + plate`, which is what the display image
//! shows through the request's display transform ([`FrameRequest::view`], the OCIO view, or a tonemap curve); [`ghost_layers`] adds one layer per drawn ghost, each drawn alone on the same device.
//! A file of linear layers only (an EXR) is written from the accumulation alone ([`draw_for_file`] makes a
//! [`Made::Linear`] through [`Device::draw_linear`], [`write_made`] writes it): the CPU twin then makes no
//! display image, whose OCIO view was most of an EXR's time (the layers are the same bytes either way).

use crate::flare::PreparedFlare;
use crate::ghost::{GhostFrame, Sensor, light_slopes_for_frame_position};
use crate::image::{DisplayImage, HdrImage};
use crate::lut::LutKind;
use crate::lut::blend::{BlendSettings, LiveLut, LutScene, lut_pass};
use crate::output::ExrPixel;
pub use crate::output::FrameLayers;
use crate::raytrace::Window;
use crate::render::GhostInstance;
use crate::render::cpu;
use crate::render::gpu::{FlareRenderer, GpuContext, GpuError};
use crate::render::{DisplaySettings, FlareScene};
use crate::shutter::{LightPath, ShutterSamples};

/// How the LUT ghosts of a frame are used.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LutUse {
    /// Paraxial ghosts only (a LUT, if given, is not drawn).
    #[default]
    Off,
    /// LUT ghosts blended with the paraxial flare ([`BlendSettings`]).
    Blend,
    /// The LUT alone, no paraxial sprite (a photo LUT played back).
    Alone,
}

/// Everything that decides a frame besides the prepared optics (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct FrameRequest {
    /// Where the light appears in the frame (degrees, X right, Y up).
    pub light_deg: [f64; 2],
    /// The light's linear intensity relative to the document's (`2^light_ev` of the timeline times the
    /// light's visibility in the plate): it multiplies every ghost's gain and the starburst; 0 draws no flare.
    pub light_gain: f64,
    pub width: u32,
    pub height: u32,
    /// The width of the sensor the frame spans (mm; 36 is full frame).
    pub sensor_width_mm: f64,
    pub display: DisplaySettings,
    /// Per lens ghost index, its gain (missing entries are 1, 0 leaves the ghost out).
    pub ghost_gains: Vec<f32>,
    /// The gains the dim threshold sees when they are not `ghost_gains`: a ghost's own layer
    /// ([`Frame::ghost_alone`]) is culled as the whole frame is, so that the layers add up to the flare.
    pub cull_gains: Option<Vec<f32>>,
    pub blend: BlendSettings,
    pub lut_use: LutUse,
    /// Draw a draft instead (the app while the user drags; never an export or a command's frame).
    pub draft: Option<Draft>,
    /// The light while the shutter is open ([`crate::shutter`]); `None` (a closed shutter or a still light):
    /// the sharp frame at `light_deg`.
    pub motion: Option<LightPath>,
    /// The OCIO display transform of [`crate::color::Tonemap::View`] (`None`: the built-in default).
    pub view: Option<std::sync::Arc<crate::view_transform::ViewTransform>>,
    /// The desqueeze: the delivered `width` x `height` image shows the sensor stretched along x by this factor
    /// (an anamorphic lens's squeeze `EFL_y / EFL_x` undone; 1: none; below 1 the sensor is compressed along
    /// x). The frame is drawn on the sensor at [`sensor_pixels`] (square pixels, never fewer than delivered)
    /// and averaged down to `width` x `height` as it is tonemapped and written.
    pub desqueeze: f64,
}

/// What drawing a frame keeps per sensor pixel (the accumulation and its passes), and per delivered pixel (the
/// display image, the linear layers, the file's channels), at most (bytes). Measured as peak RSS (issue 61,
/// the default still as EXR), less the process's own (0.12 GB on the CPU twin, 0.32 GB on lavapipe): the
/// delivered frame without desqueeze took 102 (CPU twin) and 124 (lavapipe) bytes a pixel from 1024x1024 to
/// 8192x4320 (3.70 and 4.32 GB there); desqueezed by 4 at 4096x2160 (a 4096x8640 sensor) 1.27 and 1.95 GB,
/// which puts the sensor's share at 9 and 22 bytes a pixel and the delivered share at 93 and 102.
pub(crate) const SENSOR_BYTES_PER_PX: u64 = 32;
/// See [`SENSOR_BYTES_PER_PX`].
pub(crate) const DELIVERED_BYTES_PER_PX: u64 = 100;
/// What a plate keeps per pixel of the frame: its decoded RGBA floats and the copy the frame reads.
pub(crate) const PLATE_BYTES_PER_PX: u64 = 32;
/// The most memory one frame may need (bytes): 6 GiB, an 8192x4320 frame with room (about 4.7 GB), and less
/// where the machine has less available ([`available_memory_bytes`]).
pub(crate) const MAX_FRAME_BYTES: u64 = 6 << 30;

/// The memory a frame delivered at `width` x `height`, desqueezed by `desqueeze`, needs at most while it is
/// drawn and written, with a plate when `plate` (bytes; see [`SENSOR_BYTES_PER_PX`]).
pub(crate) fn frame_memory_bytes(width: u32, height: u32, desqueeze: f64, plate: bool) -> u64 {
    let (w, h) = sensor_pixels(width, height, desqueeze);
    let sensor = u64::from(w) * u64::from(h);
    let delivered = u64::from(width) * u64::from(height);
    let per_delivered = DELIVERED_BYTES_PER_PX + if plate { PLATE_BYTES_PER_PX } else { 0 };
    sensor * SENSOR_BYTES_PER_PX + delivered * per_delivered
}

/// The memory this machine has available now (bytes): Linux's `MemAvailable`, or a control group's limit when
/// lower; `None` where neither can be read.
pub fn available_memory_bytes() -> Option<u64> {
    let meminfo = std::fs::read_to_string("/proc/meminfo").ok();
    let available = meminfo.as_deref().and_then(|text| {
        let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
        line.split_whitespace().nth(1)?.parse::<u64>().ok().map(|kb| kb.saturating_mul(1024))
    });
    let cgroup = std::fs::read_to_string("/sys/fs/cgroup/memory.max").ok().and_then(|t| t.trim().parse::<u64>().ok());
    match (available, cgroup) {
        (Some(a), Some(c)) => Some(a.min(c)),
        (a, c) => a.or(c),
    }
}

/// What a command may plan on of `available` bytes free (nine tenths: the rest is the system's and the
/// estimates' margin). The one share every memory check uses (frames, bakes, `dof`, `synth-dof`).
pub fn usable_memory_bytes(available: u64) -> u64 {
    available / 10 * 9
}

/// Refuses a frame (see `frame_memory_bytes`) that would need more than `MAX_FRAME_BYTES` or than nine
/// tenths of the memory available now, naming both figures, before any work. Issue 61: `--size 8192x8192`, a
/// black 8192x8192 PNG plate or `--desqueeze 4` aborted at 5.1-5.4 GB when memory ran out.
pub fn check_frame_memory(width: u32, height: u32, desqueeze: f64, plate: bool) -> Result<(), FrameError> {
    let need = frame_memory_bytes(width, height, desqueeze, plate);
    let available = available_memory_bytes().map(usable_memory_bytes);
    let limit = available.map_or(MAX_FRAME_BYTES, |a| a.min(MAX_FRAME_BYTES));
    if need <= limit {
        return Ok(());
    }
    let (sw, sh) = sensor_pixels(width, height, desqueeze);
    let drawn = if (sw, sh) == (width, height) { String::new() } else { format!(" (drawn at {sw}x{sh}, desqueezed)") };
    let why = match available {
        Some(a) if a < MAX_FRAME_BYTES => {
            format!("nine tenths of the {:.1} GB this machine has free", a as f64 / 0.9e9)
        }
        _ => format!("the {:.1} GB a frame may take", MAX_FRAME_BYTES as f64 / 1e9),
    };
    Err(FrameError::Request(format!(
        "a {width}x{height} frame{drawn} needs about {:.1} GB, more than {why}: draw a smaller frame (--size)",
        need as f64 / 1e9
    )))
}

/// The most a frame is desqueezed (and `1 / MAX_DESQUEEZE` the least).
pub const MAX_DESQUEEZE: f64 = 4.0;

/// The square sensor pixels a frame delivered at `width` x `height` and desqueezed by `desqueeze` is drawn at:
/// `height x desqueeze` rows for a desqueeze above 1, `width / desqueeze` columns below 1, rounded (the
/// delivered size itself for 1, or a desqueeze that is not finite; clamped to [1/4, 4]).
pub fn sensor_pixels(width: u32, height: u32, desqueeze: f64) -> (u32, u32) {
    if !desqueeze.is_finite() || desqueeze == 1.0 {
        return (width, height);
    }
    let d = desqueeze.clamp(1.0 / MAX_DESQUEEZE, MAX_DESQUEEZE);
    let scale = |n: u32, by: f64| (f64::from(n) * by).round().max(1.0) as u32;
    if d > 1.0 { (width, scale(height, d)) } else { (scale(width, 1.0 / d), height) }
}

impl FrameRequest {
    /// The width of the sensor the frame spans (mm): `sensor_width_mm`, or full frame where that is not finite
    /// and positive.
    pub fn sensor_width(&self) -> f64 {
        if self.sensor_width_mm.is_finite() && self.sensor_width_mm > 0.0 {
            self.sensor_width_mm
        } else {
            crate::optics::sensor::FULL_FRAME_WIDTH_MM
        }
    }

    /// The size the frame is drawn at on the sensor (square pixels): [`sensor_pixels`].
    pub fn sensor_size(&self) -> (u32, u32) {
        sensor_pixels(self.width, self.height, self.desqueeze)
    }
}

/// A draft of a frame: what the app draws while the light is dragged or a value scrubbed, chosen to hold a
/// frame time ([`Frame::build`]). Its accumulation is at 1/`divisor` of the request's size (2 or 4; at least
/// the request's own divisor): with a divisor of 2 or more the whole frame, tonemap included, is drawn at half
/// the size (a viewport stretches it) and accumulated at the rest of the divisor. Of the paraxial sprites only
/// the brightest are drawn, as many as fit in `fragment_budget` accumulation fragments (a sprite's quad
/// clipped to the accumulation): the faint ones, which cost as much to fill as the bright ones, are skipped
/// first. LUT instances and the starburst are kept.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Draft {
    pub divisor: u32,
    pub fragment_budget: u64,
}

/// What a draft left out of its frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DraftOutcome {
    /// The accumulation drawn, as a divisor of the request's size.
    pub divisor: u32,
    /// Sprites drawn and skipped for the budget.
    pub drawn: usize,
    pub skipped: usize,
    /// Accumulation fragments of the sprites drawn.
    pub fragments: u64,
}

impl Default for FrameRequest {
    fn default() -> Self {
        Self {
            light_deg: [6.0, 4.0],
            light_gain: 1.0,
            width: 1280,
            height: 720,
            sensor_width_mm: crate::optics::sensor::FULL_FRAME_WIDTH_MM,
            display: DisplaySettings::default(),
            ghost_gains: Vec::new(),
            cull_gains: None,
            blend: BlendSettings::default(),
            lut_use: LutUse::Off,
            draft: None,
            motion: None,
            view: None,
            desqueeze: 1.0,
        }
    }
}

/// A frame ready to draw.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// The paraxial instances (gains applied), the starburst's placement and the uniforms.
    pub scene: FlareScene,
    /// The LUT instances, when a LUT is drawn.
    pub lut: Option<LutScene>,
    /// Every sprite of the frame with why it is culled, and the counts (for ghost lists and status lines).
    pub sprites: GhostFrame,
    /// What the frame was built from.
    pub request: FrameRequest,
    /// When the request asked for a draft: what it left out.
    pub draft: Option<DraftOutcome>,
    /// When the light moves while the shutter is open: how the shutter was sampled ([`crate::shutter`]).
    pub shutter: Option<ShutterSamples>,
    /// The share of the light the front dirt takes at the frame's own time (`dirt_share`; 0: a clean lens):
    /// what a ray-traced method's ghosts are dimmed by, as the sprites are.
    pub dirt_taken: f64,
}

impl Frame {
    /// Builds the frame `request` asks for from `flare` and, when LUT ghosts are used, `lut`. With a moving
    /// light while the shutter is open, the frame is built at each time sample ([`crate::shutter`]) and their
    /// instances, each weighted by 1 / samples, drawn together.
    pub fn build(flare: &PreparedFlare, lut: Option<&LiveLut>, request: &FrameRequest) -> Self {
        let (sensor_w, sensor_h) = request.sensor_size();
        let (mut w, mut h) = (sensor_w.max(1), sensor_h.max(1));
        let mut output = (request.width.max(1), request.height.max(1));
        // A draft of divisor 2 or more is drawn at half the size (see [`Draft`]).
        let draft_divisor = request.draft.map(|d| d.divisor.max(request.display.accumulation_divisor).clamp(1, 4));
        if draft_divisor.is_some_and(|d| d >= 2) {
            (w, h) = (w.div_ceil(2), h.div_ceil(2));
            output = (output.0.div_ceil(2), output.1.div_ceil(2));
        }
        let lut = lut.filter(|_| request.lut_use != LutUse::Off);
        // The light's gain scales every ghost and the starburst; a NaN or negative gain draws no flare.
        let light_gain = if request.light_gain.is_finite() { request.light_gain.max(0.0) as f32 } else { 0.0 };
        let sensor = Sensor::for_frame(request.sensor_width(), w, h);
        let mut display = request.display;
        if let Some(d) = draft_divisor {
            display.accumulation_divisor = if d >= 2 { d / 2 } else { 1 };
        }
        let path = request.motion.as_ref().filter(|p| p.moves());
        let shutter = path.map(|p| crate::shutter::plan_samples(flare, p, sensor, w, display.flare_gain()));
        let (mut scene, lut_scene, sprites) = match (path, &shutter) {
            (Some(path), Some(samples)) if samples.count > 1 => {
                // The frame's own time (the middle) gives the starburst, the uniforms and the sprite list.
                let (mut scene, mut lut_scene, sprites) =
                    sharp(flare, lut, request, (sensor, w, h), &display, request.light_deg, light_gain);
                scene.instances.clear();
                scene.instance_ghosts.clear();
                scene.dropped_non_finite = 0;
                if let Some(l) = &mut lut_scene {
                    l.instances.clear();
                    l.sources.clear();
                    l.dropped_non_finite = 0;
                }
                for (k, point) in path.samples(samples.count).into_iter().enumerate() {
                    let gain = light_gain * point.gain as f32;
                    let (s, l, _) = sharp(flare, lut, request, (sensor, w, h), &display, point.light_deg, gain);
                    for (instance, &ghost) in s.instances.iter().zip(&s.instance_ghosts) {
                        if let Some(weight) = samples.weight(ghost as usize, k) {
                            scene.instances.push(weighted(*instance, weight));
                            scene.instance_ghosts.push(ghost);
                        }
                    }
                    scene.dropped_non_finite += s.dropped_non_finite;
                    if let (Some(all), Some(l), Some(live)) = (&mut lut_scene, l, lut) {
                        for (instance, &(lg, entry, mip)) in l.instances.iter().zip(&l.sources) {
                            let ghost = live.lut.ghosts.get(lg as usize).map_or(usize::MAX, |g| g.ghost as usize);
                            if let Some(weight) = samples.weight(ghost, k) {
                                let mut i = *instance;
                                i.colour = i.colour.map(|c| c * weight);
                                all.instances.push(i);
                                all.sources.push((lg, entry, mip));
                            }
                        }
                        all.dropped_non_finite += l.dropped_non_finite;
                    }
                }
                if let Some(l) = lut_scene.as_mut().filter(|l| l.alpha_over) {
                    // Each ghost's samples one run, laid over the flare at once with their summed coverage.
                    l.group_by_ghost();
                }
                (scene, lut_scene, sprites)
            }
            _ => sharp(flare, lut, request, (sensor, w, h), &display, request.light_deg, light_gain),
        };
        scene.view = request.view.clone();
        if output != (scene.width, scene.height) {
            // Desqueezed: the tonemap and the layers average the sensor's pixels down to the delivered ones.
            scene.set_output_size(output);
        }
        let draft = request.draft.map(|d| {
            let skipped = scene.keep_brightest(d.fragment_budget);
            let fragments = scene.instances.iter().map(|i| scene.fragments(i)).sum();
            let divisor = request.width.max(1).div_ceil(scene.hdr_width.max(1));
            DraftOutcome { divisor, drawn: scene.instances.len(), skipped, fragments }
        });
        let dirt_taken =
            dirt_share(flare, light_slopes_for_frame_position(request.light_deg[0], request.light_deg[1]), &display);
        Self { scene, lut: lut_scene, sprites, request: request.clone(), draft, shutter, dirt_taken }
    }

    /// The frame's size in pixels as delivered (desqueezed; the sensor's are `scene.width` x `scene.height`).
    pub fn size(&self) -> (u32, u32) {
        self.scene.output_size
    }

    /// The lens ghosts this frame draws (paraxial or LUT instances), in index order.
    pub fn drawn_ghosts(&self, lut: Option<&LiveLut>) -> Vec<u32> {
        let mut ghosts: Vec<u32> = self.scene.instance_ghosts.clone();
        if let (Some(l), Some(live)) = (&self.lut, lut) {
            ghosts.extend(l.sources.iter().map(|&(lg, _, _)| live.lut.ghosts[lg as usize].ghost));
        }
        ghosts.sort_unstable();
        ghosts.dedup();
        ghosts.retain(|&g| g != crate::lut::PHOTO_GHOST);
        ghosts
    }

    /// The frame of the same request with only lens ghost `g` (its sprites and LUT images, at its gain) and no
    /// starburst: built again, as any frame is, with every other ghost at gain 0.
    pub fn ghost_alone(&self, g: u32, flare: &PreparedFlare, lut: Option<&LiveLut>) -> Self {
        let gain = self.request.ghost_gains.get(g as usize).copied().unwrap_or(1.0);
        let ghost_gains = (0..flare.system.ghosts.len() as u32).map(|h| if h == g { gain } else { 0.0 }).collect();
        let display = DisplaySettings { starburst: false, ..self.request.display };
        let cull_gains = Some(self.request.cull_gains.clone().unwrap_or_else(|| self.request.ghost_gains.clone()));
        Frame::build(
            flare,
            lut,
            &FrameRequest { ghost_gains, cull_gains, display, draft: None, ..self.request.clone() },
        )
    }
}

/// The frame of `request` with the light at `light_deg` and gain `light_gain` at one instant: the LUT
/// instances first (they say how much of each non-linear ghost its paraxial sprite keeps), then the paraxial
/// instances with the user's gain times that weight, and the starburst.
fn sharp(
    flare: &PreparedFlare,
    lut: Option<&LiveLut>,
    request: &FrameRequest,
    (sensor, w, h): (Sensor, u32, u32),
    display: &DisplaySettings,
    light_deg: [f64; 2],
    light_gain: f32,
) -> (FlareScene, Option<LutScene>, GhostFrame) {
    let ghosts = flare.system.ghosts.len();
    let u = light_slopes_for_frame_position(light_deg[0], light_deg[1]);
    // The front dirt takes its share of the light before any ghost forms; the glow is where it goes. A clean
    // lens multiplies nothing (the frame it always drew, bit for bit).
    let taken = dirt_share(flare, u, display);
    let direct_gain = if taken > 0.0 { light_gain * (1.0 - taken) as f32 } else { light_gain };
    let scaled = |list: &[f32]| -> Vec<f32> {
        (0..ghosts).map(|g| list.get(g).copied().unwrap_or(1.0).max(0.0) * direct_gain).collect()
    };
    let mut gains = scaled(&request.ghost_gains);
    // The dim threshold sees the user's gains and the light's (what the ghost adds to the picture, whether its
    // sprite or its LUT image draws it), not the share a LUT takes from the paraxial sprite: a baked ghost is not
    // "too dim" because its LUT draws it.
    let cull = scaled(request.cull_gains.as_deref().unwrap_or(&request.ghost_gains));
    let lut_scene = lut.map(|live| {
        let out = Window::for_sensor(sensor.width_mm, w, h);
        let mut scene = LutScene::build(live, &flare.system, u, out, &request.blend, &gains);
        scene.choose_mips(live, display.accumulation_divisor);
        // The LUT images too are culled where they cannot be seen at the frame's exposure.
        scene.cull_faint(flare.config.threshold(request.display.flare_gain()), &live.footprints);
        scene
    });
    if let Some(l) = &lut_scene {
        // A photo LUT is the whole flare photographed: it is never drawn over paraxial sprites.
        let alone = request.lut_use == LutUse::Alone || lut.is_some_and(|live| live.lut.kind == LutKind::Photo);
        for (g, gain) in gains.iter_mut().enumerate() {
            *gain = if alone { 0.0 } else { *gain * l.paraxial_weight(g as u32) };
        }
    }
    let display = DisplaySettings {
        starburst_intensity: display.starburst_intensity * direct_gain,
        dirt_amount: display.dirt_amount * f64::from(light_gain),
        ..*display
    };
    let (scene, sprites) = flare.scene_culled_with(light_deg, sensor, w, h, &display, &gains, Some(&cull));
    (scene, lut_scene, sprites)
}

/// The share of the light of slopes `u` that the front dirt takes from the image and every ghost (0 for a clean
/// lens or an amount of 0).
pub(crate) fn dirt_share(flare: &PreparedFlare, u: [f64; 2], display: &DisplaySettings) -> f64 {
    flare.dirt.as_ref().map_or(0.0, |d| d.taken_share(&flare.system, u, display.dirt_amount))
}

/// `instance` with its colour times `weight` (one time sample of a shutter).
fn weighted(mut instance: GhostInstance, weight: f32) -> GhostInstance {
    for c in &mut instance.colour[..3] {
        *c *= weight;
    }
    instance
}

/// What a frame reads besides itself: the prepared optics (aperture mask, starburst), the LUT and the plate.
#[derive(Clone, Copy)]
pub struct Sources<'a> {
    pub flare: &'a PreparedFlare,
    pub lut: Option<&'a LiveLut>,
    pub plate: Option<&'a HdrImage>,
}

/// A drawn frame: the HDR accumulation (linear relative irradiance before any gain, at the accumulation's
/// size) and the display image (the tonemapped composite at the frame's size).
#[derive(Clone, Debug, PartialEq)]
pub struct Drawn {
    pub hdr: HdrImage,
    pub display: DisplayImage,
}

impl Drawn {
    /// The frame's linear layers (no ghost layers; see [`ghost_layers`]).
    pub fn layers(&self, frame: &Frame, sources: &Sources) -> FrameLayers {
        linear_layers(frame, sources, &self.hdr)
    }
}

/// The linear layers of a frame whose accumulation is `hdr` (no ghost layers; see [`ghost_layers`]): what an
/// EXR holds, and all it needs of a drawn frame.
pub(crate) fn linear_layers(frame: &Frame, sources: &Sources, hdr: &HdrImage) -> FrameLayers {
    let scene = &frame.scene;
    let flare = cpu::flare_layer(scene, hdr);
    // A frame without a starburst writes its layer black (the layers are the same in every file).
    let starburst = if scene.draws_starburst() {
        let mut starburst = HdrImage::black(scene.hdr_width, scene.hdr_height);
        cpu::starburst_pass(scene, &sources.flare.starburst_texture, &mut starburst);
        cpu::flare_layer(scene, &starburst)
    } else {
        HdrImage::black(scene.output_size.0, scene.output_size.1)
    };
    let dirt = sources.flare.dirt.as_ref().filter(|_| scene.has_dirt_glow()).map(|d| {
        let mut glow = HdrImage::black(scene.hdr_width, scene.hdr_height);
        cpu::dirt_pass(scene, Some(d), &mut glow);
        cpu::flare_layer(scene, &glow)
    });
    let plate = sources.plate.map(|p| cpu::plate_layer(scene, p));
    let mut composite = match &plate {
        Some(p) => flare.plus(p),
        None => flare.clone(),
    };
    for p in &mut composite.pixels {
        p[3] = 1.0;
    }
    FrameLayers { composite, flare, starburst, dirt, plate, ghosts: Vec::new() }
}

/// Why a frame could not be drawn or written.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error(transparent)]
    Image(#[from] crate::output::ImageError),
    #[error("{0}")]
    Request(String),
}

/// A headless GPU renderer with the sources it last uploaded (uploads happen only when a source changes).
pub struct GpuDrawer {
    pub ctx: GpuContext,
    pub renderer: FlareRenderer,
    /// What was last uploaded: the prepared flare's and the LUT's ids (0: none) and the plate's key.
    uploaded: Option<(u64, u64, u64)>,
}

impl GpuDrawer {
    /// A headless device (`prefer_software`: a CPU adapter such as lavapipe first, for reproducible images).
    pub fn new(prefer_software: bool) -> Result<Self, GpuError> {
        Ok(Self::on(GpuContext::headless(prefer_software)?))
    }

    /// A drawer on a device already made.
    pub fn on(ctx: GpuContext) -> Self {
        let renderer = FlareRenderer::new(&ctx.device, &ctx.queue, wgpu::TextureFormat::Rgba8Unorm);
        Self { ctx, renderer, uploaded: None }
    }

    /// Uploads `sources` to the renderer unless they are the ones last uploaded.
    fn upload(&mut self, sources: &Sources) {
        let key = (sources.flare.id, sources.lut.map_or(0, |l| l.id), sources.plate.map_or(0, plate_key));
        if self.uploaded == Some(key) {
            return;
        }
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        self.renderer.set_aperture(device, queue, &sources.flare.ghost_masks);
        self.renderer.set_starburst(device, queue, &sources.flare.starburst);
        self.renderer.set_dirt(device, queue, sources.flare.dirt.as_ref());
        self.renderer.set_background(device, queue, sources.plate);
        self.renderer.set_lut(device, queue, sources.lut);
        self.uploaded = Some(key);
    }

    /// Draws `frame` and reads back its accumulation and display image; [`GpuError::Lost`] when the device
    /// was lost or reported an error of its own, before or during the draw.
    pub fn draw(&mut self, frame: &Frame, sources: &Sources) -> Result<Drawn, GpuError> {
        if let Some(reason) = self.ctx.failure() {
            return Err(GpuError::Lost(reason));
        }
        // Refused before anything is made: a texture beyond the adapter's limit would be a validation error.
        let max = self.ctx.device.limits().max_texture_dimension_2d;
        let (width, height) = (frame.scene.width.max(frame.size().0), frame.scene.height.max(frame.size().1));
        if width > max || height > max {
            return Err(GpuError::TooLarge { width, height, max });
        }
        let drawn = self.draw_unchecked(frame, sources);
        match self.ctx.failure() {
            Some(reason) => Err(GpuError::Lost(reason)),
            None => drawn,
        }
    }

    fn draw_unchecked(&mut self, frame: &Frame, sources: &Sources) -> Result<Drawn, GpuError> {
        self.upload(sources);
        let display = crate::render::gpu::render_display_with_lut(
            &self.ctx,
            &mut self.renderer,
            &frame.scene,
            frame.lut.as_ref(),
        )?;
        let hdr = crate::render::gpu::read_hdr(&self.ctx, &self.renderer)?;
        Ok(Drawn { hdr, display })
    }

    /// Draws `frame` into `target` (of the renderer's format and the frame's size) and waits for the GPU,
    /// reading nothing back (what a benchmark times).
    pub fn render_into(
        &mut self,
        frame: &Frame,
        sources: &Sources,
        target: &wgpu::TextureView,
    ) -> Result<(), GpuError> {
        self.upload(sources);
        let mut encoder = self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
        self.renderer.render_with_lut(
            &self.ctx.device,
            &self.ctx.queue,
            &mut encoder,
            target,
            &frame.scene,
            frame.lut.as_ref(),
        );
        self.ctx.queue.submit(Some(encoder.finish()));
        self.ctx.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| GpuError::Readback(e.to_string()))?;
        Ok(())
    }
}

/// A plate's key for the upload cache: its size and a hash of every 97th pixel (plates can be large; two
/// different plates of one size that agree on all of those pixels are not told apart, and would differ by
/// less than can be seen).
fn plate_key(plate: &HdrImage) -> u64 {
    use crate::fingerprint::{FNV_OFFSET, fnv1a};
    let size = fnv1a(&[plate.width.to_le_bytes(), plate.height.to_le_bytes()].concat(), FNV_OFFSET);
    plate.pixels.iter().step_by(97).fold(size, |h, p| fnv1a(bytemuck::cast_slice(p), h)) | 1
}

/// Where frames are drawn: a GPU (any wgpu adapter, software ones included) or the CPU twin.
pub enum Device {
    Gpu(Box<GpuDrawer>),
    Cpu,
    /// Was a GPU whose device was lost (the reason): draws on the CPU twin from then on.
    LostGpu(String),
}

impl Device {
    /// A headless GPU device (see [`GpuDrawer::new`]).
    pub fn gpu(prefer_software: bool) -> Result<Self, GpuError> {
        Ok(Self::Gpu(Box::new(GpuDrawer::new(prefer_software)?)))
    }

    /// The adapter's name, or "CPU twin".
    pub fn name(&self) -> String {
        match self {
            Self::Gpu(g) => format!("{} ({:?})", g.ctx.adapter.name, g.ctx.adapter.backend),
            Self::Cpu => "CPU twin".into(),
            Self::LostGpu(reason) => format!("CPU twin (the GPU device was lost: {reason})"),
        }
    }

    /// Draws `frame` (see the module documentation). A GPU whose device is lost (before or during the draw)
    /// is dropped for the CPU twin, which draws this frame and the next ones; [`Self::name`] says why.
    pub fn draw(&mut self, frame: &Frame, sources: &Sources) -> Result<Drawn, GpuError> {
        self.draw_as(frame, sources, Ok, || draw_cpu(frame, sources))
    }

    /// The frame's accumulation alone, as [`Self::draw`] makes it, for a file that holds only linear layers
    /// (an EXR): the CPU twin leaves out its tonemap pass, whose display transform (the OCIO view, every pixel
    /// through it) is most of a CPU frame's time and none of an EXR's; a GPU draws as ever (its tonemap is a
    /// pass of its own, a small share of the frame).
    pub fn draw_linear(&mut self, frame: &Frame, sources: &Sources) -> Result<HdrImage, GpuError> {
        self.draw_as(frame, sources, |drawn| Ok(drawn.hdr), || draw_cpu_hdr(frame, sources))
    }

    /// A GPU's drawing through `on_gpu`, or the CPU twin's (`on_cpu`); a lost GPU is dropped for the twin.
    fn draw_as<T>(
        &mut self,
        frame: &Frame,
        sources: &Sources,
        on_gpu: impl FnOnce(Drawn) -> Result<T, GpuError>,
        on_cpu: impl FnOnce() -> T,
    ) -> Result<T, GpuError> {
        match self {
            Self::Gpu(g) => match g.draw(frame, sources) {
                Err(GpuError::Lost(reason)) => {
                    *self = Self::LostGpu(reason);
                    Ok(on_cpu())
                }
                drawn => drawn.and_then(on_gpu),
            },
            Self::Cpu | Self::LostGpu(_) => Ok(on_cpu()),
        }
    }
}

/// The CPU twin of [`GpuDrawer::draw`]: [`draw_cpu_hdr`], then the tonemap pass.
pub fn draw_cpu(frame: &Frame, sources: &Sources) -> Drawn {
    let hdr = draw_cpu_hdr(frame, sources);
    let display = cpu::tonemap_pass(&frame.scene, &hdr, sources.plate);
    Drawn { hdr, display }
}

/// A frame whose ghosts were ray-traced instead of drawn as sprites (`render --method raygrid`, the app's
/// ray-grid view): `ghosts` is every ghost at gain 1 in linear relative irradiance (resampled to the frame's
/// accumulation when its size differs), scaled by the frame's light gain (the timeline's light and its
/// visibility in the plate, as the sprites are), then the frame's starburst, tonemap and plate as
/// [`draw_cpu`] adds them. Per-ghost gains are the trace's to apply (a ray-traced image holds its ghosts summed):
/// callers trace with the request's `ghost_gains` ([`crate::raytrace::Ghosts::Weighted`]).
pub fn drawn_with_traced_ghosts(frame: &Frame, sources: &Sources, ghosts: HdrImage) -> Drawn {
    let hdr = linear_with_traced_ghosts(frame, sources, ghosts);
    let display = cpu::tonemap_pass(&frame.scene, &hdr, sources.plate);
    Drawn { hdr, display }
}

/// [`drawn_with_traced_ghosts`]'s accumulation alone (no tonemap pass): what an EXR of it is written from.
pub(crate) fn linear_with_traced_ghosts(frame: &Frame, sources: &Sources, ghosts: HdrImage) -> HdrImage {
    let scene = &frame.scene;
    let mut hdr = traced_accumulation(frame, &ghosts);
    cpu::starburst_pass(scene, &sources.flare.starburst_texture, &mut hdr);
    cpu::dirt_pass(scene, sources.flare.dirt.as_ref(), &mut hdr);
    hdr
}

/// Ray-traced ghosts (linear, before the light's gain, any size) as the frame's accumulation: at its size,
/// times the light's gain (a changing light's intensity on a shot) and what the front dirt leaves of the light
/// ([`Frame::dirt_taken`]; a clean lens multiplies nothing).
pub fn traced_accumulation(frame: &Frame, ghosts: &HdrImage) -> HdrImage {
    let scene = &frame.scene;
    // At its own size, bilinear resampling reads every pixel exactly: only the gain is applied then.
    ghosts.resampled(scene.hdr_width, scene.hdr_height, crate::image::Sampling::Bilinear, traced_light_gain(frame))
}

/// The gain a frame's traced ghosts are multiplied by: the light's, less the front dirt's share (0 for a light
/// gain that is not finite).
pub(crate) fn traced_light_gain(frame: &Frame) -> f32 {
    let mut light_gain =
        if frame.request.light_gain.is_finite() { frame.request.light_gain.max(0.0) as f32 } else { 0.0 };
    if frame.dirt_taken > 0.0 {
        light_gain *= (1.0 - frame.dirt_taken) as f32;
    }
    light_gain
}

/// The accumulation passes of the CPU twin: ghosts, LUT ghosts, starburst, the front dirt's glow.
pub fn draw_cpu_hdr(frame: &Frame, sources: &Sources) -> HdrImage {
    let scene = &frame.scene;
    let mut hdr = crate::timing::span("ghosts", || cpu::ghost_pass(scene, &sources.flare.ghost_masks));
    if let (Some(l), Some(live)) = (&frame.lut, sources.lut) {
        crate::timing::span("LUT ghosts", || lut_pass((scene.width, scene.height), l, live, &mut hdr));
    }
    crate::timing::span("starburst", || cpu::starburst_pass(scene, &sources.flare.starburst_texture, &mut hdr));
    cpu::dirt_pass(scene, sources.flare.dirt.as_ref(), &mut hdr);
    hdr
}

/// Where ghost layers go as they are made: each layer's name and image, once (the writer keeps only its
/// channels).
pub(crate) type LayerSink<'a> = dyn FnMut(String, HdrImage) + 'a;

/// One layer per ghost the frame draws (`ghost_I_J`, surfaces I < J), each drawn alone on `device` and
/// multiplied by the flare's gain.
pub fn ghost_layers(
    device: &mut Device,
    frame: &Frame,
    sources: &Sources,
) -> Result<Vec<(String, HdrImage)>, FrameError> {
    let mut layers = Vec::new();
    ghost_layers_into(device, frame, sources, ExrPixel::Auto, &mut |name, image| layers.push((name, image)))?;
    Ok(layers)
}

/// [`ghost_layers`] handed to `sink` one at a time (refused first when they would not fit
/// [`MAX_GHOST_LAYER_BYTES`] stored as `pixel` says).
pub(crate) fn ghost_layers_into(
    device: &mut Device,
    frame: &Frame,
    sources: &Sources,
    pixel: ExrPixel,
    sink: &mut LayerSink,
) -> Result<(), FrameError> {
    let ghosts = frame.drawn_ghosts(sources.lut);
    check_ghost_layers(ghosts.len(), frame.request.width, frame.request.height, pixel)?;
    for g in ghosts {
        let Some(model) = sources.flare.system.ghosts.get(g as usize) else { continue };
        let alone = frame.ghost_alone(g, sources.flare, sources.lut);
        let drawn = device.draw(&alone, &Sources { plate: None, ..*sources })?;
        sink(ghost_layer_name(model.i, model.j), cpu::flare_layer(&alone.scene, &drawn.hdr));
    }
    Ok(())
}

/// The most memory the ghost layers of one file may take while it is written (bytes): 3 GiB (the default
/// zoom's 254 ghost layers at 1920x1080 take 3.2 GB).
pub(crate) const MAX_GHOST_LAYER_BYTES: u64 = 3 << 30;

/// What one ghost layer keeps per pixel at most: its EXR channels (RGB, 6 bytes in half, 12 in float), made
/// as soon as it is drawn ([`crate::output::ExrLayers::add_ghost`], cropped to its lit pixels, which is
/// usually far less; only the layer being drawn has a float image). [`ExrPixel::Auto`] counts half: a ghost
/// layer has values beyond half's range only at exposures that turn the frame white.
pub(crate) fn ghost_layer_bytes_per_px(pixel: ExrPixel) -> u64 {
    if pixel == ExrPixel::Float { 12 } else { 6 }
}

/// Refuses `count` ghost layers of `width` x `height` stored as `pixel` when they could need more than
/// `MAX_GHOST_LAYER_BYTES`, naming what they need and the ways out.
pub fn check_ghost_layers(count: usize, width: u32, height: u32, pixel: ExrPixel) -> Result<(), FrameError> {
    let need = count as u64 * u64::from(width) * u64::from(height) * ghost_layer_bytes_per_px(pixel);
    if need > MAX_GHOST_LAYER_BYTES {
        return Err(FrameError::Request(format!(
            "{count} ghost layers at {width}x{height} need about {:.1} GB while written, more than the {:.1} GB \
             allowed: draw a smaller frame (--size) or fewer ghosts (--solo, or ghost gains of 0)",
            need as f64 / 1e9,
            MAX_GHOST_LAYER_BYTES as f64 / 1e9
        )));
    }
    Ok(())
}

/// The EXR layer name of ghost (i, j): `ghost_I_J`.
pub(crate) fn ghost_layer_name(i: usize, j: usize) -> String {
    format!("ghost_{i}_{j}")
}

/// Which layers a file gets, and how an EXR stores them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LayerChoice {
    /// One layer per drawn ghost (EXR only).
    pub ghosts: bool,
    /// The EXR's value type and compression (a document's `exr`).
    pub exr: crate::output::ExrSettings,
}

/// The kind of image `path` names, when it can hold the layers `choice` asks for (a PNG holds one tonemapped
/// image: no ghost layers). Callers check before any work; [`render_to_file`] checks too.
pub fn check_output(path: &std::path::Path, choice: LayerChoice) -> Result<crate::output::ImageKind, FrameError> {
    let kind = crate::output::ImageKind::from_path(path)?;
    if choice.ghosts && kind != crate::output::ImageKind::Exr {
        return Err(FrameError::Request(format!(
            "{}: ghost layers need an EXR file (a PNG holds one tonemapped image)",
            path.display()
        )));
    }
    Ok(kind)
}

/// Draws `frame` on `device` and writes it to `path` through the one writer: [`draw_for_file`], then
/// [`write_made`].
pub fn render_to_file(
    device: &mut Device,
    frame: &Frame,
    sources: &Sources,
    choice: LayerChoice,
    path: &std::path::Path,
) -> Result<(), FrameError> {
    let made = draw_for_file(device, frame, sources, choice, path)?;
    write_made(device, frame, sources, &made, choice, path)
}

/// A frame drawn for a file ([`draw_for_file`]): what a PNG or an EXR of it is written from.
pub enum Made {
    /// For a PNG: the accumulation and its display image.
    Drawn(Drawn),
    /// For an EXR: the accumulation alone. The file holds linear layers only, so no display image is made
    /// (on the CPU twin that is the tonemap pass, every pixel through the OCIO view).
    Linear(HdrImage),
}

/// Draws `frame` on `device` as the file at `path` needs it (see [`Made`]), once `path` and `choice` are
/// known to be writable together ([`check_output`]).
pub fn draw_for_file(
    device: &mut Device,
    frame: &Frame,
    sources: &Sources,
    choice: LayerChoice,
    path: &std::path::Path,
) -> Result<Made, FrameError> {
    Ok(match check_output(path, choice)? {
        crate::output::ImageKind::Png => Made::Drawn(device.draw(frame, sources)?),
        crate::output::ImageKind::Exr => Made::Linear(device.draw_linear(frame, sources)?),
    })
}

/// Writes a frame drawn by [`draw_for_file`] to `path` through the one writer ([`write_drawn`] or
/// `write_linear_with`), its ghost layers drawn on `device` when `choice` asks for them.
pub fn write_made(
    device: &mut Device,
    frame: &Frame,
    sources: &Sources,
    made: &Made,
    choice: LayerChoice,
    path: &std::path::Path,
) -> Result<(), FrameError> {
    write_made_with(frame, sources, made, path, choice.exr, |sink| {
        asked_ghost_layers(device, frame, sources, choice, sink)
    })
}

/// [`write_made`] with the ghost layers from `ghost_layers` (called only for an EXR file): the drawn ghosts on a
/// device, or ray-traced ones ([`crate::traced::TracedGhosts::write_made`]).
pub(crate) fn write_made_with(
    frame: &Frame,
    sources: &Sources,
    made: &Made,
    path: &std::path::Path,
    exr: crate::output::ExrSettings,
    ghost_layers: impl FnOnce(&mut LayerSink) -> Result<(), FrameError>,
) -> Result<(), FrameError> {
    match made {
        Made::Drawn(drawn) => write_drawn_with(frame, sources, drawn, path, exr, ghost_layers),
        Made::Linear(hdr) => write_linear_with(frame, sources, hdr, path, exr, ghost_layers),
    }
}

/// Writes a frame already drawn (by [`Device::draw`], or by a ray-traced method into the same kind of
/// accumulation) to `path`: the one rule for every image file FlareLab writes.
pub fn write_drawn(
    device: &mut Device,
    frame: &Frame,
    sources: &Sources,
    drawn: &Drawn,
    choice: LayerChoice,
    path: &std::path::Path,
) -> Result<(), FrameError> {
    write_drawn_with(frame, sources, drawn, path, choice.exr, |sink| {
        asked_ghost_layers(device, frame, sources, choice, sink)
    })
}

/// The ghost layers `choice` asks for ([`ghost_layers_into`]), none unless it asks.
fn asked_ghost_layers(
    device: &mut Device,
    frame: &Frame,
    sources: &Sources,
    choice: LayerChoice,
    sink: &mut LayerSink,
) -> Result<(), FrameError> {
    if choice.ghosts { ghost_layers_into(device, frame, sources, choice.exr.pixel_type, sink) } else { Ok(()) }
}

/// [`write_drawn`] with the ghost layers from `ghost_layers` (called only for an EXR file): the drawn ghosts
/// on a device, or ray-traced ones ([`crate::traced::TracedGhosts::write`]).
pub(crate) fn write_drawn_with(
    frame: &Frame,
    sources: &Sources,
    drawn: &Drawn,
    path: &std::path::Path,
    exr: crate::output::ExrSettings,
    ghost_layers: impl FnOnce(&mut LayerSink) -> Result<(), FrameError>,
) -> Result<(), FrameError> {
    match crate::output::ImageKind::from_path(path)? {
        crate::output::ImageKind::Png => crate::output::write_frame(path, &drawn.display, None)?,
        crate::output::ImageKind::Exr => write_linear_with(frame, sources, &drawn.hdr, path, exr, ghost_layers)?,
    }
    Ok(())
}

/// Writes the EXR of a frame whose accumulation is `hdr` ([`linear_layers`], then the ghost layers from
/// `ghost_layers`): what [`write_drawn_with`] does for an EXR, for a frame drawn without its display image
/// ([`Device::draw_linear`], [`linear_with_traced_ghosts`]).
pub(crate) fn write_linear_with(
    frame: &Frame,
    sources: &Sources,
    hdr: &HdrImage,
    path: &std::path::Path,
    exr: crate::output::ExrSettings,
    ghost_layers: impl FnOnce(&mut LayerSink) -> Result<(), FrameError>,
) -> Result<(), FrameError> {
    if crate::output::ImageKind::from_path(path)? != crate::output::ImageKind::Exr {
        return Err(FrameError::Request(format!(
            "{}: a frame drawn without its display image can only be written as an EXR",
            path.display()
        )));
    }
    let layers = crate::timing::span("layers", || linear_layers(frame, sources, hdr));
    let mut file = crate::timing::span("EXR channels", || crate::output::ExrLayers::new(&layers, exr));
    drop(layers);
    ghost_layers(&mut |name, image| file.add_ghost(&name, &image))?;
    crate::timing::span("EXR encode and write", || file.write(path))?;
    Ok(())
}

/// Parses an image size `WIDTHxHEIGHT` (each side 1 to 8192 pixels).
pub fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(|| format!("`{s}` is not WIDTHxHEIGHT"))?;
    let (w, h): (u32, u32) = (
        w.trim().parse().map_err(|_| format!("`{s}` is not WIDTHxHEIGHT"))?,
        h.trim().parse().map_err(|_| format!("`{s}` is not WIDTHxHEIGHT"))?,
    );
    if !(1..=8192).contains(&w) || !(1..=8192).contains(&h) {
        return Err(format!("`{s}`: each side must be 1 to 8192 pixels"));
    }
    Ok((w, h))
}
