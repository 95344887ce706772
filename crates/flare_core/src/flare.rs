//! One flare from end to end: a lens and its settings prepared once, then a scene per light position.
//!
//! # How it works
//! [`FlareConfig`] is everything besides the lens that changes the optics: aperture (shape, f-number), spectrum,
//! coating override and the culling threshold. [`PreparedFlare::new`] does the work that depends on those and on
//! the lens (ghost matrices and reflectance tables, the aperture mask (and, for the ghost passes, the same mask at two
//! and four times the resolution: [`GhostMasks`]), the starburst's FFT, the last two kept per
//! stop shape so a lens edit does not redo them, and the front dirt's map seen through the stop); it is redone only when one of them changes, never for a display
//! setting (exposure, tonemap, plate, starburst gain, view size). [`PreparedFlare::scene_with`] is the per-frame
//! part: ghost sprites for the light's position and the GPU-ready [`FlareScene`], with the display settings and
//! per-ghost gains of that frame. [`crate::frame`] builds every frame of the app, the command line and the
//! benchmarks through it.

use std::sync::Arc;

use crate::aperture::{Aperture, ApertureError, ApertureMask, DEFAULT_MASK_SIZE};
use crate::dirt::{DirtPattern, PreparedDirt};
use crate::ghost::light_slopes_for_frame_position;
use crate::ghost::{FrameSettings, GhostError, GhostFrame, GhostSettings, GhostSystem, Sensor};
use crate::optics::{Coating, Lens};
use crate::render::cpu::StarburstTexture;
use crate::render::cpu::ghosts::GhostMasks;
use crate::render::{DisplaySettings, FlareScene};
use crate::spectrum::Spectrum;
use crate::starburst::Starburst;

/// Everything but the lens that changes the optics (display settings are per frame: [`DisplaySettings`]).
#[derive(Clone, Debug, PartialEq)]
pub struct FlareConfig {
    pub aperture: Aperture,
    pub spectrum: Spectrum,
    pub coating_override: Option<Coating>,
    /// The most relative irradiance that culling the faintest sprites may take from any pixel (all the culled
    /// sprites together, see [`crate::ghost::FrameSettings::intensity_threshold`]); `None` picks, per frame,
    /// the level that would show as a quarter of one 8-bit step at that frame's flare exposure (invisible):
    /// "skip what the scene does not need". Culling is per frame, so an exposure change rebuilds nothing.
    pub intensity_threshold: Option<f64>,
    /// The front element's dirt ([`crate::dirt`]; `None`: a clean lens). Its amount and spread are display
    /// settings ([`DisplaySettings::dirt_amount`]).
    pub dirt: Option<DirtPattern>,
}

impl FlareConfig {
    /// The culling threshold in use for a flare drawn at the linear gain `flare_gain` (see
    /// [`Self::intensity_threshold`]).
    pub fn threshold(&self, flare_gain: f32) -> f64 {
        self.intensity_threshold.unwrap_or_else(|| 0.25 / 255.0 / f64::from(flare_gain.max(1e-12)))
    }
}

impl Default for FlareConfig {
    fn default() -> Self {
        Self {
            aperture: Aperture::default(),
            spectrum: Spectrum::rgb(),
            coating_override: None,
            intensity_threshold: None,
            dirt: None,
        }
    }
}

/// Why a flare cannot be prepared.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FlareError {
    #[error(transparent)]
    Ghosts(#[from] GhostError),
    #[error(transparent)]
    Aperture(#[from] ApertureError),
}

/// A lens with its settings, ready to render any light position.
#[derive(Clone, Debug)]
pub struct PreparedFlare {
    pub config: FlareConfig,
    pub system: GhostSystem,
    /// The stop's mask at the resolutions the ghost passes pick from per sprite (its first level is
    /// [`Self::mask`]).
    pub ghost_masks: Arc<GhostMasks>,
    pub starburst: Starburst,
    /// The starburst as the GPU holds it (half floats), for the CPU twin.
    pub starburst_texture: StarburstTexture,
    /// The front dirt seen through this stop (`None`: a clean lens).
    pub dirt: Option<PreparedDirt>,
    /// This flare's identity (`crate::fingerprint::unique_id`; a clone keeps it): what a GPU drawer checks
    /// before uploading the mask and the starburst again.
    pub id: u64,
}

/// Stop shapes whose mask and starburst were made lately (a lens edit keeps its stop: no new FFT).
const STOP_IMAGES_KEPT: usize = 4;

/// The aperture mask and the starburst of `aperture`'s shape (they do not depend on the f-number, the lens or
/// the spectrum), from a small process-wide cache keyed by the shape's fingerprint: the 1024^2 FFT and the
/// 512^2 raster take ~50 ms, and the ghost passes' mask levels (`GhostMasks`, up to 1024^2 texels) 17-22 ms
/// more on two cores, which a lens edit in the app should not pay.
fn stop_images(aperture: &Aperture) -> (Arc<GhostMasks>, Starburst) {
    type Kept = Vec<(u64, Arc<GhostMasks>, Starburst)>;
    static KEPT: std::sync::Mutex<Kept> = std::sync::Mutex::new(Vec::new());
    let key = crate::fingerprint::of(&aperture.shape);
    if let Ok(kept) = KEPT.lock()
        && let Some((_, mask, starburst)) = kept.iter().find(|(k, _, _)| *k == key)
    {
        return (mask.clone(), starburst.clone());
    }
    // The two are independent: side by side on rayon's threads (each is parallel within, with serial parts).
    let (mask, starburst) = rayon::join(
        || {
            crate::timing::span("aperture mask levels", || {
                Arc::new(GhostMasks::new(aperture, aperture.rasterise(DEFAULT_MASK_SIZE)))
            })
        },
        || {
            crate::timing::span("starburst (FFT)", || {
                Starburst::compute(&aperture.rasterise(crate::starburst::STARBURST_MASK_SIZE))
            })
        },
    );
    if let Ok(mut kept) = KEPT.lock() {
        kept.retain(|(k, _, _)| *k != key);
        kept.push((key, mask.clone(), starburst.clone()));
        let excess = kept.len().saturating_sub(STOP_IMAGES_KEPT);
        kept.drain(..excess);
    }
    (mask, starburst)
}

impl PreparedFlare {
    pub fn new(lens: &Lens, config: &FlareConfig) -> Result<Self, FlareError> {
        config.aperture.validate()?;
        let nominal = crate::optics::FirstOrder::d_line(lens).map_err(GhostError::from)?.f_number;
        let settings = GhostSettings {
            spectrum: config.spectrum.clone(),
            stop_scale: config.aperture.stop_scale(nominal),
            coating_override: config.coating_override.clone(),
        };
        let system = crate::timing::span("ghost system", || GhostSystem::build(lens, &settings))?;
        let (ghost_masks, starburst) = stop_images(&config.aperture);
        let starburst_texture = StarburstTexture::from_starburst(&starburst);
        let dirt =
            config.dirt.as_ref().map(|pattern| PreparedDirt::new(&system, &ghost_masks.levels()[0].mask, pattern));
        let id = crate::fingerprint::unique_id();
        Ok(Self { config: config.clone(), system, ghost_masks, starburst, starburst_texture, dirt, id })
    }

    /// The stop's mask at the base size ([`DEFAULT_MASK_SIZE`]): what the dirt, the ray grids, the reports and
    /// the panels read (the first of [`Self::ghost_masks`]' levels).
    pub fn mask(&self) -> &ApertureMask {
        &self.ghost_masks.levels()[0].mask
    }

    /// Frame settings for an image of `width` x `height` pixels on the full-frame sensor drawn at the flare gain
    /// `flare_gain`.
    pub fn frame_settings(&self, width: u32, height: u32, flare_gain: f32) -> FrameSettings {
        self.frame_settings_on(Sensor::full_frame_for(width, height), width, flare_gain)
    }

    /// [`Self::frame_settings`] on `sensor` (the image `width` pixels across it).
    pub fn frame_settings_on(&self, sensor: Sensor, width: u32, flare_gain: f32) -> FrameSettings {
        // A focused ghost is drawn at least a pixel across.
        let min_half_size_mm = 0.75 * sensor.width_mm / width.max(1) as f64;
        FrameSettings { sensor, intensity_threshold: self.config.threshold(flare_gain), min_half_size_mm }
    }

    /// Ghost sprites and the drawable scene for a light seen at the frame position `light_deg` (X right,
    /// Y up, degrees), at the default display settings with every ghost at gain 1 (the ghosts alone, as the
    /// ray-traced methods and the tests compare them; frames for the user come from [`crate::frame`]).
    pub fn scene(&self, light_deg: [f64; 2], width: u32, height: u32) -> (FlareScene, GhostFrame) {
        let sensor = Sensor::full_frame_for(width, height);
        self.scene_with(light_deg, sensor, width, height, &DisplaySettings::default(), &[])
    }

    /// [`Self::scene`] on `sensor` with the frame's display settings and per-ghost gains (see
    /// [`FlareScene::build`]).
    pub fn scene_with(
        &self,
        light_deg: [f64; 2],
        sensor: Sensor,
        width: u32,
        height: u32,
        display: &DisplaySettings,
        gains: &[f32],
    ) -> (FlareScene, GhostFrame) {
        self.scene_culled_with(light_deg, sensor, width, height, display, gains, None)
    }

    /// [`Self::scene_with`], the dim threshold seeing `cull_gains` instead of `gains` when given (a ghost's
    /// own layer is culled as its whole frame is: [`crate::frame::Frame::ghost_alone`]).
    #[allow(clippy::too_many_arguments)]
    pub fn scene_culled_with(
        &self,
        light_deg: [f64; 2],
        sensor: Sensor,
        width: u32,
        height: u32,
        display: &DisplaySettings,
        gains: &[f32],
        cull_gains: Option<&[f32]>,
    ) -> (FlareScene, GhostFrame) {
        let u = light_slopes_for_frame_position(light_deg[0], light_deg[1]);
        let frame_settings = self.frame_settings_on(sensor, width, display.flare_gain());
        // The dim threshold sees the gains: what is culled stays below it as drawn.
        let frame = self.system.frame_weighted(u, &frame_settings, cull_gains.unwrap_or(gains));
        let mut scene = FlareScene::build(&self.system, &frame, u, &frame_settings, display, width, height, gains);
        self.ghost_masks.assign_levels(&mut scene);
        scene.place_starburst(&self.system, &self.starburst, u, &sensor, display);
        scene.place_dirt(&self.system, self.dirt.as_ref(), u, &sensor, display);
        (scene, frame)
    }
}

impl PreparedFlare {
    /// The ray-traced renderer of this lens and its settings (`ray_grid_setup`).
    pub fn ray_grid_renderer(&self) -> crate::raytrace::RayGridRenderer {
        crate::raytrace::RayGridRenderer::new(ray_grid_setup(&self.system), self.mask())
    }
}

/// What the ray tracer needs of a ghost system: the lens and its settings, each ghost's surfaces and stop
/// crossings, and the paraxial entrance region as the hint of where to look when no coarse ray passes. The
/// ray tracer itself depends only on the optics, the coatings and the aperture.
pub(crate) fn ray_grid_setup(system: &GhostSystem) -> crate::raytrace::RayGridSetup {
    let ghosts = system
        .ghosts
        .iter()
        .map(|g| crate::raytrace::TracedGhost {
            i: g.i,
            j: g.j,
            stop_crossings: g.per_wavelength.iter().map(|w| w.matrices.stop_from_entrance.len()).collect(),
        })
        .collect();
    let wavelengths = system.settings.spectrum.len();
    let hint_system = std::sync::Arc::new(system.clone());
    let entrance_hint: crate::raytrace::EntranceHint = std::sync::Arc::new(move |g, w, u| {
        let region = hint_system.sprite_masks(g * wavelengths + w, u).region;
        // The entrance region's bounding disc (an anamorphic lens's box has two half-sizes: the larger).
        Some((region.offset, region.scale[0].abs().max(region.scale[1].abs())))
    });
    crate::raytrace::RayGridSetup {
        lens: system.lens.clone(),
        spectrum: system.settings.spectrum.clone(),
        coating_override: system.settings.coating_override.clone(),
        sensor_z_mm: system.first_order.sensor_z_mm(),
        stop_radius_mm: system.stop_radius_mm,
        ghosts,
        entrance_hint,
    }
}
