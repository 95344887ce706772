//! The document: everything a preset saves and undo restores (lens, aperture, coatings, spectrum, blend, ghost
//! gains, light, exposures), shared by the app and the command line, with one [`Default`]: the app's fresh
//! start and `flarelab render` with no flags are the same frame.
//!
//! # How it works
//! [`Document`] is plain data with `#[serde(default)]` on every struct, so a preset written by an older
//! FlareLab (a lower `PRESET_VERSION`, fewer fields) loads with today's defaults for what it lacks; a preset
//! from a newer FlareLab is refused by its version, never half-read. Version 1 stored a linear `exposure`
//! multiplier: it converts to `flare_ev = log2(exposure)` on load. [`Document::from_json`] names the field that
//! is wrong (through `serde_path_to_error`) and then checks values serde cannot (a lens that is not
//! physically possible, a negative gain, an unknown blend mode); [`Document::save`] writes through a
//! temporary file renamed over the target.
//!
//! What the document implies is derived in two halves that never mix: [`Document::flare_config`] (the optics:
//! lens, aperture, coatings, spectrum, culling) keyed by [`Document::optics_fingerprint`], and
//! [`Document::frame_request`] (light, display settings, per-ghost gains, blend), which costs only a new
//! frame. Exposures, tonemap, plate and starburst are display settings: changing them rebuilds no optics.
//!
//! Presets shipped in the binary ([`shipped`]) are JSON files under `assets/presets/`, read through the same
//! loader; [`Document::open_named`] takes a file path or a shipped name. A preset's `lens` may be a built-in
//! lens's name instead of a whole prescription (the shipped presets use that); it is saved whole.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::aperture::{Aperture, ApertureShape, DEFAULT_MASK_SIZE};
use crate::color::Tonemap;
use crate::exposure::DEFAULT_FLARE_EV;
use crate::files::write_atomic;
use crate::flare::FlareConfig;
use crate::footage::detect::AutoLight;
use crate::footage::pattern::FramePattern;
use crate::frame::{FrameRequest, LutUse};
use crate::ghost::GhostSystem;
use crate::lut::blend::{BlendMode, BlendSettings};
use crate::optics::library::default_lens;
use crate::optics::sensor::FULL_FRAME_WIDTH_MM;
use crate::optics::{Coating, Lens};
use crate::render::DisplaySettings;
use crate::spectrum::Spectrum;
use crate::timeline::Timeline;

/// The preset format this build writes; it reads every version up to this one.
pub(crate) const PRESET_VERSION: u32 = 3;

/// Why a preset is refused.
#[derive(Debug, thiserror::Error)]
pub enum PresetError {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    /// The file could not be read, or is larger than any preset (`crate::files::MAX_TEXT_BYTES`).
    #[error("{0}")]
    Read(String),
    #[error("not a FlareLab preset: at `{path}`: {reason}")]
    Json { path: String, reason: String },
    #[error("preset version {0} is newer than this FlareLab reads ({PRESET_VERSION}); update FlareLab")]
    Newer(u64),
    #[error("preset field `{field}`: {reason}")]
    Value { field: String, reason: String },
    #[error("no preset file or shipped preset named `{name}`; the shipped presets are: {shipped}")]
    Unknown { name: String, shipped: String },
}

/// The stop: blade count (0 for a circle), their rotation and roundness, and the f-number.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ApertureDoc {
    pub blades: u32,
    pub rotation_deg: f64,
    /// 0 straight blades, 1 a circle.
    pub roundness: f64,
    /// `None`: the lens wide open.
    pub f_number: Option<f64>,
    /// A custom aperture image (grey, white open) replacing the blades.
    pub image: Option<String>,
}

impl Default for ApertureDoc {
    fn default() -> Self {
        Self { blades: 6, rotation_deg: 0.0, roundness: 0.0, f_number: None, image: None }
    }
}

/// Where the LUT ghosts come from.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum LutSource {
    /// Paraxial ghosts only.
    #[default]
    None,
    /// Baked from the lens by ray tracing (in the app, or loaded from `path`).
    Simulated { path: Option<String> },
    /// A photo LUT file.
    Photo { path: String },
}

/// How LUT ghosts blend with the paraxial flare.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct BlendDoc {
    /// `additive`, `alpha`, `linear:FROM:TO` or `smooth:FROM:TO` (degrees); see [`BlendMode::parse`].
    pub mode: String,
    /// Multiplies the LUT layer.
    pub gain: f64,
    pub lut: LutSource,
}

impl Default for BlendDoc {
    fn default() -> Self {
        Self { mode: "additive".into(), gain: 1.0, lut: LutSource::None }
    }
}

/// One ghost's switches: on or off, and a gain.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct GhostDoc {
    pub enabled: bool,
    pub gain: f64,
}

impl Default for GhostDoc {
    fn default() -> Self {
        Self { enabled: true, gain: 1.0 }
    }
}

/// Everything the user edits (see the module documentation).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Document {
    pub version: u32,
    pub lens: Lens,
    pub aperture: ApertureDoc,
    /// One coating for every surface, replacing the lens's own (`None`: each surface's own, as edited in the
    /// coatings panel).
    pub coating_override: Option<Coating>,
    /// Wavelengths the flare is made of: 3 is RGB (650 / 510 / 475 nm), 2 to 32 are CIE-weighted, 1 the d-line.
    pub wavelengths: usize,
    /// The culling threshold (relative irradiance all culled sprites together may take from a pixel);
    /// `None`: a quarter of an 8-bit step at the flare's exposure.
    pub cull_threshold: Option<f64>,
    pub blend: BlendDoc,
    /// Per ghost, keyed by its surface pair `"I-J"`; absent ghosts are on at gain 1.
    pub ghosts: BTreeMap<String, GhostDoc>,
    /// Show only this ghost (`"I-J"`).
    pub solo: Option<String>,
    /// Where the light appears in the frame (degrees, X right, Y up).
    pub light_deg: [f64; 2],
    /// The flare's exposure in stops (its relative irradiance times `2^flare_ev`); with `exposure_auto`, set
    /// from the optics by [`Self::resolve_exposure`].
    pub flare_ev: f64,
    /// The flare's exposure follows the optics ([`crate::exposure::auto_flare_ev`]: the brightest ghost at a
    /// fixed display level); false: the user locked `flare_ev`.
    pub exposure_auto: bool,
    /// The background plate's exposure in stops (0: as shot).
    pub plate_ev: f64,
    pub tonemap: Tonemap,
    pub starburst: bool,
    /// The starburst's brightness in stops relative to the physical one (0: the light's own image as the lens
    /// makes it, see [`crate::starburst`]).
    pub starburst_ev: f64,
    /// Background plate file (PNG/EXR/HDR/JPEG), if any; a sequence when it has a frame field
    /// (`shot.####.exr` or `shot.%04d.exr`, [`crate::footage::pattern`]).
    pub background: Option<String>,
    /// The width of the sensor the frame (and the plate) spans, in mm (36: full frame).
    pub sensor_width_mm: f64,
    /// The shot: frame range, frame rate and keys ([`crate::timeline`]).
    pub timeline: Timeline,
    /// Find the light in the plate on every frame ([`crate::footage::detect`]); `None`: the keys or the static
    /// light say where it is.
    pub auto_light: Option<AutoLight>,
    /// Depth of field of the plate through the same lens and stop ([`crate::dof`]).
    pub dof: crate::dof::DofDoc,
    /// How EXR files are written: value type and compression ([`crate::output::ExrSettings`]).
    pub exr: crate::output::ExrSettings,
    /// Colour management: the OCIO config, display, view, looks, `.cube` and plates' input space
    /// ([`crate::view_transform`]).
    pub color: crate::view_transform::ColorDoc,
    /// The front element's dirt ([`crate::dirt`]): the pattern (none: a clean lens), its amount and spread.
    pub dirt: crate::dirt::DirtDoc,
    /// The delivered frame shows the sensor stretched along x by this factor, 1/4 to 4 (an anamorphic lens's
    /// squeeze undone, for desqueezed plates; 1: the sensor as it is): [`FrameRequest::desqueeze`].
    pub desqueeze: f64,
}

impl Default for Document {
    fn default() -> Self {
        Self {
            version: PRESET_VERSION,
            lens: default_lens(),
            aperture: ApertureDoc::default(),
            // The default look: the zoom's chain of polygonal ghosts, coloured by a quarter-wave coat.
            coating_override: Some(Coating::QuarterWave { design_wavelength_nm: 550.0, layer_index: None }),
            wavelengths: 3,
            cull_threshold: None,
            blend: BlendDoc::default(),
            ghosts: BTreeMap::new(),
            solo: None,
            light_deg: [9.0, 5.0],
            flare_ev: DEFAULT_FLARE_EV,
            exposure_auto: true,
            plate_ev: 0.0,
            tonemap: Tonemap::View,
            starburst: true,
            starburst_ev: 0.0,
            background: None,
            sensor_width_mm: FULL_FRAME_WIDTH_MM,
            timeline: Timeline::default(),
            auto_light: None,
            dof: crate::dof::DofDoc::default(),
            exr: crate::output::ExrSettings::default(),
            color: crate::view_transform::ColorDoc::default(),
            dirt: crate::dirt::DirtDoc::default(),
            desqueeze: 1.0,
        }
    }
}

/// The key of a ghost in [`Document::ghosts`].
pub fn ghost_key(i: usize, j: usize) -> String {
    format!("{i}-{j}")
}

/// The part of a document that decides the optics (for [`Document::optics_fingerprint`]).
#[derive(Serialize)]
struct OpticsPart<'a> {
    lens: &'a Lens,
    aperture: &'a ApertureDoc,
    coating_override: &'a Option<Coating>,
    wavelengths: usize,
    cull_threshold: Option<f64>,
    /// The dirt's pattern, seed and image (left out for a clean lens: the fingerprint it had before dirt).
    #[serde(skip_serializing_if = "Option::is_none")]
    dirt: Option<(crate::dirt::DirtKind, u64, &'a Option<String>)>,
}

impl Document {
    /// A fresh document on `lens` (everything else the default).
    pub fn for_lens(lens: Lens) -> Self {
        Self { lens, ..Self::default() }
    }

    /// The aperture this document asks for (the image file read when there is one).
    pub fn aperture(&self) -> Result<Aperture, PresetError> {
        let a = &self.aperture;
        let shape = match &a.image {
            Some(path) => Aperture::image_shape_from_file(Path::new(path), DEFAULT_MASK_SIZE)
                .map_err(|e| PresetError::Value { field: "aperture.image".into(), reason: e.to_string() })?,
            None if a.blades < 3 => ApertureShape::Circle,
            None => ApertureShape::Blades { count: a.blades, rotation_deg: a.rotation_deg, roundness: a.roundness },
        };
        Ok(Aperture { shape, f_number: a.f_number })
    }

    /// The optics settings of this document (everything but the lens that changes the ghosts).
    pub fn flare_config(&self) -> Result<FlareConfig, PresetError> {
        let spectrum = Spectrum::with_count(self.wavelengths)
            .map_err(|e| PresetError::Value { field: "wavelengths".into(), reason: e.to_string() })?;
        Ok(FlareConfig {
            aperture: self.aperture()?,
            spectrum,
            coating_override: self.coating_override.clone(),
            intensity_threshold: self.cull_threshold,
            dirt: self
                .dirt
                .pattern()
                .map_err(|e| PresetError::Value { field: "dirt.image".into(), reason: e.to_string() })?,
        })
    }

    /// A stable fingerprint of what [`Self::flare_config`] and the lens depend on: the app rebuilds the ghost
    /// system only when it changes, and never for a display setting.
    pub fn optics_fingerprint(&self) -> u64 {
        crate::fingerprint::of(&OpticsPart {
            lens: &self.lens,
            aperture: &self.aperture,
            coating_override: &self.coating_override,
            wavelengths: self.wavelengths,
            cull_threshold: self.cull_threshold,
            dirt: (self.dirt.pattern != crate::dirt::DirtKind::None).then_some((
                self.dirt.pattern,
                self.dirt.seed,
                &self.dirt.image,
            )),
        })
    }

    /// The display settings (`divisor`: the accumulation divisor, 1 for files).
    pub fn display(&self, divisor: u32) -> DisplaySettings {
        DisplaySettings {
            flare_ev: self.flare_ev,
            plate_ev: self.plate_ev,
            tonemap: self.tonemap,
            starburst: self.starburst,
            starburst_intensity: crate::color::gain_from_ev(self.starburst_ev),
            accumulation_divisor: divisor,
            dirt_amount: if self.dirt.pattern == crate::dirt::DirtKind::None { 0.0 } else { self.dirt.amount },
            dirt_spread_deg: self.dirt.spread_deg,
        }
    }

    /// The gain ghost (i, j) is drawn with: 0 when it is off or another ghost is solo.
    pub fn ghost_gain(&self, i: usize, j: usize) -> f64 {
        self.ghost_gain_keyed(i, j, None)
    }

    /// [`Self::ghost_gain`], the panel's gain replaced by `keyed` when the timeline animates it.
    fn ghost_gain_keyed(&self, i: usize, j: usize, keyed: Option<f64>) -> f64 {
        let key = ghost_key(i, j);
        if self.solo.as_ref().is_some_and(|s| *s != key) {
            return 0.0;
        }
        match (self.ghosts.get(&key), keyed) {
            (Some(g), _) if !g.enabled => 0.0,
            (_, Some(gain)) => gain,
            (Some(g), None) => g.gain,
            (None, None) => 1.0,
        }
    }

    /// Every lens ghost's gain, by the ghost's index in `system` (the static gains, no timeline).
    pub fn ghost_gains(&self, system: &GhostSystem) -> Vec<f32> {
        system.ghosts.iter().map(|g| self.ghost_gain(g.i, g.j) as f32).collect()
    }

    /// Every lens ghost's gain at `frame` of the timeline.
    pub fn ghost_gains_at(&self, system: &GhostSystem, frame: f64) -> Vec<f32> {
        let sample = self.timeline.sample(frame);
        system
            .ghosts
            .iter()
            .map(|g| self.ghost_gain_keyed(g.i, g.j, sample.ghost_gain.get(&ghost_key(g.i, g.j)).copied()) as f32)
            .collect()
    }

    /// Where the light is at `frame`: the timeline's light keys, else the static light.
    pub fn light_at(&self, frame: f64) -> [f64; 2] {
        self.timeline.light_deg.value_at(frame, self.timeline.interpolation).unwrap_or(self.light_deg)
    }

    /// The plate file of `frame`: the background itself, or its sequence's file of that frame.
    pub fn plate_at(&self, frame: i64) -> Option<std::path::PathBuf> {
        let background = self.background.as_deref()?;
        Some(match FramePattern::parse(background) {
            Ok(Some(pattern)) => pattern.path(frame),
            _ => background.into(),
        })
    }

    /// The depth map file of `frame` (the depth of field's): the file itself, or its sequence's file of that
    /// frame, like [`Self::plate_at`].
    pub fn depth_at(&self, frame: i64) -> Option<std::path::PathBuf> {
        let depth = self.dof.depth.as_deref()?;
        Some(match FramePattern::parse(depth) {
            Ok(Some(pattern)) => pattern.path(frame),
            _ => depth.into(),
        })
    }

    /// The ghost's switches, created on first edit.
    pub fn ghost_mut(&mut self, i: usize, j: usize) -> &mut GhostDoc {
        self.ghosts.entry(ghost_key(i, j)).or_default()
    }

    /// The blend settings (an unparsable mode falls back to additive; [`Self::check`] refuses it on load).
    pub fn blend_settings(&self) -> BlendSettings {
        BlendSettings {
            mode: BlendMode::parse(&self.blend.mode).unwrap_or(BlendMode::Additive),
            gain: self.blend.gain,
            ..BlendSettings::default()
        }
    }

    /// How the LUT ghosts are used: blended for a ray-traced LUT, alone for a photo.
    pub fn lut_use(&self) -> LutUse {
        match self.blend.lut {
            LutSource::None => LutUse::Off,
            LutSource::Simulated { .. } => LutUse::Blend,
            LutSource::Photo { .. } => LutUse::Alone,
        }
    }

    /// The frame this document shows at the timeline's first frame, `width` x `height` (`divisor`: the
    /// accumulation divisor): a still.
    pub fn frame_request(&self, system: &GhostSystem, width: u32, height: u32, divisor: u32) -> FrameRequest {
        self.frame_request_at(system, self.timeline.first_frame as f64, width, height, divisor)
    }

    /// The frame this document shows at `frame` of its timeline: the keyed light, light intensity and ghost
    /// gains there (the light found in a plate is applied on top by [`crate::shot::plan`]).
    pub fn frame_request_at(
        &self,
        system: &GhostSystem,
        frame: f64,
        width: u32,
        height: u32,
        divisor: u32,
    ) -> FrameRequest {
        let sample = self.timeline.sample(frame);
        FrameRequest {
            light_deg: sample.light_deg.unwrap_or(self.light_deg),
            light_gain: crate::color::gain_from_ev(sample.light_ev) as f64,
            width,
            height,
            sensor_width_mm: self.sensor_width_mm,
            display: self.display(divisor),
            ghost_gains: self.ghost_gains_at(system, frame),
            cull_gains: None,
            blend: self.blend_settings(),
            lut_use: self.lut_use(),
            draft: None,
            motion: self.light_path(frame),
            view: self.view_transform().ok(),
            desqueeze: self.desqueeze,
        }
    }

    /// The document's colour management resolved ([`crate::view_transform::ViewTransform::cached`]).
    pub fn view_transform(
        &self,
    ) -> Result<std::sync::Arc<crate::view_transform::ViewTransform>, crate::view_transform::ViewError> {
        crate::view_transform::ViewTransform::cached(&self.color)
    }

    /// The layers a file of this document gets: the ghost layers when `ghosts`, and the document's EXR settings.
    pub fn layer_choice(&self, ghosts: bool) -> crate::frame::LayerChoice {
        crate::frame::LayerChoice { ghosts, exr: self.exr }
    }

    /// The light while the shutter is open at `frame` ([`crate::shutter`]): the timeline's light position and
    /// intensity (relative to the frame's) as its keys interpolate; `None` when the shutter is closed or the
    /// light stands still while it is open.
    pub fn light_path(&self, frame: f64) -> Option<crate::shutter::LightPath> {
        let (open, close) = crate::shutter::open_interval(frame, self.timeline.shutter_deg);
        let ev_here = self.timeline.sample(frame).light_ev;
        let how = self.timeline.interpolation;
        let path = crate::shutter::LightPath::over(open, close, |t| {
            let ev = self.timeline.light_ev.value_at(t, how).unwrap_or(0.0);
            (self.light_at(t), f64::from(crate::color::gain_from_ev(ev - ev_here)))
        })?;
        path.moves().then_some(path)
    }

    /// Sets `flare_ev` from the optics of `system` when the exposure is automatic (see
    /// [`crate::exposure`]); a locked exposure is left as it is. The app calls it when the optics change and
    /// the command line before it draws, so both show the same exposure.
    pub fn resolve_exposure(&mut self, system: &GhostSystem) {
        if self.exposure_auto {
            self.flare_ev = crate::exposure::auto_flare_ev(system, self.sensor_width_mm);
        }
    }

    /// This document with `look`'s optics, camera and display: lens, stop, coatings, spectrum, culling, blend,
    /// ghost switches, the sensor and desqueeze, exposures of the flare and the starburst, tonemap; applied to
    /// a fresh document it is the look itself, the frame `flarelab render --preset NAME` draws (the anamorphic
    /// look is framed on its own Super 35 sensor, not the 36 mm one the app had before). The user's shot stays
    /// where there is one (a plate, a timeline changed from the default, a light found in the plate): the plate
    /// and its exposure, the timeline, the light found in the plate; the static light comes from the look unless
    /// the timeline keys the light. Without one, the look's own shot comes with it (an animated look's keys).
    pub fn with_look(&self, look: &Document) -> Document {
        let has_shot = self.background.is_some()
            || self.auto_light.is_some()
            || self.timeline != crate::timeline::Timeline::default();
        if !has_shot {
            return look.clone();
        }
        Document {
            background: self.background.clone(),
            plate_ev: self.plate_ev,
            timeline: self.timeline.clone(),
            auto_light: self.auto_light.clone(),
            light_deg: if self.timeline.light_deg.is_empty() { look.light_deg } else { self.light_deg },
            ..look.clone()
        }
    }

    /// A small still of this document's first frame on the CPU twin (its own flare prepared, its exposure
    /// resolved, no plate and no LUT): a preset's thumbnail.
    pub fn thumbnail(&self, width: u32, height: u32) -> Result<crate::image::DisplayImage, PresetError> {
        let config = self.flare_config()?;
        let flare = crate::flare::PreparedFlare::new(&self.lens, &config)
            .map_err(|e| PresetError::Value { field: "lens".into(), reason: e.to_string() })?;
        let mut doc = self.clone();
        doc.resolve_exposure(&flare.system);
        doc.blend.lut = LutSource::None;
        let request = doc.frame_request(&flare.system, width, height, 1);
        let frame = crate::frame::Frame::build(&flare, None, &request);
        let sources = crate::frame::Sources { flare: &flare, lut: None, plate: None };
        Ok(crate::frame::draw_cpu(&frame, &sources).display)
    }

    /// The preset's JSON text (without keys of ghosts the lens does not have: see [`Self::pruned_to_lens`]), which
    /// [`Self::from_json`] reads back.
    pub fn to_json(&self) -> String {
        let mut doc = self.pruned_to_lens();
        doc.version = PRESET_VERSION;
        serde_json::to_string_pretty(&doc).expect("a document always serialises")
    }

    /// Reads a preset (any version up to `PRESET_VERSION`) and checks it.
    pub fn from_json(text: &str) -> Result<Self, PresetError> {
        let mut value: serde_json::Value = serde_json::from_str(text).map_err(|e| PresetError::Json {
            path: format!("line {}", e.line()),
            reason: crate::files::one_line(&e.to_string()),
        })?;
        let version = value.get("version").and_then(serde_json::Value::as_u64).unwrap_or(0);
        if version > u64::from(PRESET_VERSION) {
            return Err(PresetError::Newer(version));
        }
        if version < 2 {
            upgrade_exposure(&mut value)?;
        }
        if let Some(id) = value.get("lens").and_then(serde_json::Value::as_str) {
            // A built-in lens by name (as the shipped presets give it): its whole prescription.
            let lens = crate::optics::library::builtin_lens(id)
                .map_err(|e| PresetError::Value { field: "lens".into(), reason: e.to_string() })?;
            value["lens"] = serde_json::to_value(&lens).expect("a lens always serialises");
        }
        if version < 3
            && let Some(object) = value.as_object_mut()
        {
            // Before auto exposure, a preset's exposure was the one chosen: it stays locked.
            object.entry("exposure_auto").or_insert(serde_json::Value::Bool(false));
        }
        let mut doc: Document = serde_path_to_error::deserialize(value.clone()).map_err(|e| PresetError::Json {
            path: crate::files::one_line(&e.path().to_string()),
            reason: crate::files::one_line(&e.inner().to_string()),
        })?;
        doc.version = PRESET_VERSION;
        // A key the document does not have (a misspelling, a field of another tool) is refused with its name:
        // serde would drop it silently.
        let known = serde_json::to_value(&doc).expect("a document always serialises");
        if let Some((path, key, meant)) = unknown_key(&value, &known, "") {
            let hint = meant.map_or(String::new(), |m| format!(" (did you mean `{m}`?)"));
            return Err(PresetError::Json {
                path,
                reason: format!("unknown key `{}`{hint}", crate::files::shorten(&key)),
            });
        }
        doc.check()?;
        Ok(doc)
    }

    /// Values serde cannot check.
    pub fn check(&self) -> Result<(), PresetError> {
        let bad = |field: &str, reason: String| Err(PresetError::Value { field: field.into(), reason });
        if let Err(e) = self.lens.validate() {
            return bad("lens", e.to_string());
        }
        if let Some(refusal) = self.exr.compression.refusal() {
            return bad("exr.compression", refusal);
        }
        for (field, ev) in
            [("flare_ev", self.flare_ev), ("plate_ev", self.plate_ev), ("starburst_ev", self.starburst_ev)]
        {
            if !(ev.is_finite() && (-40.0..=40.0).contains(&ev)) {
                return bad(field, format!("{ev}: stops from -40 to 40"));
            }
        }
        if !self.light_deg.iter().all(|a| a.is_finite() && a.abs() <= 89.0) {
            return bad("light_deg", format!("{:?}: angles from -89 to 89 degrees", self.light_deg));
        }
        if let Err(e) = Spectrum::with_count(self.wavelengths) {
            return bad("wavelengths", e.to_string());
        }
        if let Some(t) = self.cull_threshold
            && !(t.is_finite() && t >= 0.0)
        {
            return bad("cull_threshold", format!("{t} must be 0 or more"));
        }
        if let Some(f) = self.aperture.f_number
            && !(f.is_finite() && f > 0.0 && f <= crate::aperture::MAX_F_NUMBER)
        {
            return bad(
                "aperture.f_number",
                format!(
                    "{} must be above 0 and at most {}",
                    crate::files::shorten_numbers(&f.to_string()),
                    crate::aperture::MAX_F_NUMBER
                ),
            );
        }
        if !(self.aperture.roundness.is_finite() && (0.0..=1.0).contains(&self.aperture.roundness)) {
            return bad("aperture.roundness", format!("{} must be from 0 to 1", self.aperture.roundness));
        }
        if self.aperture.blades > crate::aperture::MAX_BLADES || !self.aperture.rotation_deg.is_finite() {
            return bad("aperture", format!("at most {} blades, a finite rotation", crate::aperture::MAX_BLADES));
        }
        if let Err((field, reason)) = self.dirt.check() {
            return bad(field, reason);
        }
        let most = crate::frame::MAX_DESQUEEZE;
        if !(self.desqueeze.is_finite() && (1.0 / most..=most).contains(&self.desqueeze)) {
            let reason =
                format!("{}: from {} to {most} (the sensor stretched along x; 1: none)", self.desqueeze, 1.0 / most);
            return bad("desqueeze", reason);
        }
        if let Err(e) = BlendMode::parse(&self.blend.mode) {
            return bad("blend.mode", e);
        }
        if !(self.blend.gain.is_finite() && (0.0..=MAX_GHOST_GAIN).contains(&self.blend.gain)) {
            return bad("blend.gain", format!("{} must be from 0 to {MAX_GHOST_GAIN}", self.blend.gain));
        }
        self.check_keys()?;
        if !(self.sensor_width_mm.is_finite() && (1.0..=200.0).contains(&self.sensor_width_mm)) {
            return bad("sensor_width_mm", format!("{} mm: a sensor from 1 to 200 mm wide", self.sensor_width_mm));
        }
        if let Err(e) = self.view_transform() {
            return bad(&format!("color.{}", e.field), e.reason);
        }
        if let Err((field, reason)) = self.timeline.check() {
            return bad(&field, reason);
        }
        if let Some(auto) = &self.auto_light
            && let Err((field, reason)) = auto.check()
        {
            return bad(&format!("auto_light.{field}"), reason);
        }
        if let Some(background) = &self.background
            && let Err(reason) = FramePattern::parse(background)
        {
            return bad("background", reason);
        }
        if let Err((field, reason)) = self.dof.check() {
            return bad(&field, reason);
        }
        if let Some(depth) = &self.dof.depth
            && let Err(reason) = FramePattern::parse(depth)
        {
            return bad("dof.depth", reason);
        }
        Ok(())
    }

    /// The keys [`Self::check`] cannot leave to serde: a lens surface's unknown key, and every ghost a gain,
    /// the solo or the timeline names, which must be one of the lens's (one it lacks did nothing).
    fn check_keys(&self) -> Result<(), PresetError> {
        let bad = |field: &str, reason: String| Err(PresetError::Value { field: field.into(), reason });
        for (k, surface) in self.lens.surfaces.iter().enumerate() {
            if let Some(key) = surface.extra.keys().next() {
                let surface_keys = crate::optics::formats::json::SURFACE_KEYS;
                let hint = crate::optics::formats::json::near_miss(key, surface_keys)
                    .map_or(String::new(), |m| format!(" (did you mean `{m}`?)"));
                return bad(
                    &format!("lens.surfaces[{k}]"),
                    format!("unknown surface key `{}`{hint}", crate::files::shorten(key)),
                );
            }
        }
        for (key, g) in &self.ghosts {
            if !(g.gain.is_finite() && (0.0..=MAX_GHOST_GAIN).contains(&g.gain)) {
                return bad(&format!("ghosts.{key}.gain"), format!("{} must be from 0 to {MAX_GHOST_GAIN}", g.gain));
            }
        }
        let pairs = self.lens.ghost_pairs();
        let has = |key: &str| pairs.iter().any(|&(i, j)| ghost_key(i, j) == key);
        let lacks = |key: &str| {
            format!(
                "the lens `{}` has no ghost `{}` (ghosts are named I-J by their two reflecting surfaces, from {} to {})",
                self.lens.id,
                crate::files::shorten(key),
                pairs.first().map_or("-".into(), |&(i, j)| ghost_key(i, j)),
                pairs.last().map_or("-".into(), |&(i, j)| ghost_key(i, j)),
            )
        };
        if let Some(key) = self.ghosts.keys().find(|k| !has(k)) {
            return bad(&format!("ghosts.{}", crate::files::shorten(key)), lacks(key));
        }
        if let Some(solo) = &self.solo
            && !has(solo)
        {
            return bad("solo", lacks(solo));
        }
        if let Some(key) = self.timeline.ghost_gain.keys().find(|k| !has(k)) {
            return bad(&format!("timeline.ghost_gain.{}", crate::files::shorten(key)), lacks(key));
        }
        Ok(())
    }

    /// Opens a preset file.
    pub fn open(path: &Path) -> Result<Self, PresetError> {
        let text = crate::files::read_text_bounded(path, crate::files::MAX_TEXT_BYTES).map_err(PresetError::Read)?;
        Self::from_json(&text)
    }

    /// Opens a preset file, or a shipped preset by name when no such file exists.
    pub fn open_named(name: &str) -> Result<Self, PresetError> {
        let path = Path::new(name);
        if path.exists() {
            return Self::open(path);
        }
        match shipped().iter().find(|p| p.name == name) {
            Some(p) => p.document(),
            None => Err(PresetError::Unknown {
                name: name.to_owned(),
                shipped: shipped().iter().map(|p| p.name).collect::<Vec<_>>().join(", "),
            }),
        }
    }

    /// Writes the preset atomically (temporary file, then rename).
    pub fn save(&self, path: &Path) -> Result<(), PresetError> {
        write_atomic(path, self.to_json().as_bytes())?;
        Ok(())
    }

    /// A copy without the gains, solo and keyed gains of ghosts the lens does not have (left from a lens
    /// before this one): what [`Self::to_json`] and [`Self::save`] write, so a saved preset always reads back ([`Self::check`]
    /// refuses such keys in a file).
    pub fn pruned_to_lens(&self) -> Document {
        let pairs = self.lens.ghost_pairs();
        let has = |key: &str| pairs.iter().any(|&(i, j)| ghost_key(i, j) == key);
        let mut doc = self.clone();
        doc.ghosts.retain(|k, _| has(k));
        doc.timeline.ghost_gain.retain(|k, _| has(k));
        if doc.solo.as_deref().is_some_and(|s| !has(s)) {
            doc.solo = None;
        }
        doc
    }
}

pub(crate) use crate::timeline::MAX_GHOST_GAIN;

/// The first key of `input` (a preset's JSON) that the document read from it does not have (`known`, the
/// document written back), with its path and the known key it is a near miss of. The lens is checked by its
/// own rules ([`Document::check`]); maps (ghost gains, keys) come back whole.
fn unknown_key(
    input: &serde_json::Value,
    known: &serde_json::Value,
    path: &str,
) -> Option<(String, String, Option<String>)> {
    let (serde_json::Value::Object(a), serde_json::Value::Object(b)) = (input, known) else { return None };
    for (key, value) in a {
        let here = if path.is_empty() { key.clone() } else { format!("{path}.{key}") };
        match b.get(key) {
            None => {
                let names: Vec<&str> = b.keys().map(String::as_str).collect();
                let meant = crate::optics::formats::json::near_miss(key, &names).map(str::to_owned);
                return Some((crate::files::shorten(&here), key.clone(), meant));
            }
            Some(_) if here == "lens" => {}
            Some(k) => {
                if let Some(found) = unknown_key(value, k, &here) {
                    return Some(found);
                }
            }
        }
    }
    None
}

/// Version 1's linear `exposure` becomes `flare_ev = log2(exposure)`.
fn upgrade_exposure(value: &mut serde_json::Value) -> Result<(), PresetError> {
    let Some(object) = value.as_object_mut() else { return Ok(()) };
    let Some(exposure) = object.remove("exposure") else { return Ok(()) };
    let linear = exposure.as_f64().filter(|e| e.is_finite() && *e > 0.0).ok_or_else(|| PresetError::Value {
        field: "exposure".into(),
        reason: format!("{exposure} must be a positive number (a version 1 linear exposure)"),
    })?;
    object.insert("flare_ev".into(), serde_json::json!(linear.log2()));
    Ok(())
}

/// A preset shipped in the binary.
#[derive(Clone, Copy, Debug)]
pub struct ShippedPreset {
    pub name: &'static str,
    pub title: &'static str,
    pub json: &'static str,
}

impl ShippedPreset {
    /// The preset's document (through the same loader and checks as a file).
    pub fn document(&self) -> Result<Document, PresetError> {
        Document::from_json(self.json)
    }
}

/// The presets shipped in the binary (`assets/presets/*.json`).
pub fn shipped() -> &'static [ShippedPreset] {
    const PRESETS: &[ShippedPreset] = &[
        ShippedPreset {
            name: "default",
            title: "Nikon 28-75 mm zoom, quarter-wave coated: a chain of polygonal ghosts through the centre (the app's first frame)",
            json: include_str!("../../../assets/presets/default.json"),
        },
        ShippedPreset {
            name: "zoom-multicoated",
            title: "Modern multicoated zoom: the Nikon with a broadband AR stack, faint warm ghosts and a crisp star",
            json: include_str!("../../../assets/presets/zoom-multicoated.json"),
        },
        ShippedPreset {
            name: "zoom-own-coatings",
            title: "The Nikon zoom with each surface's own single coat (the patent table's design wavelengths): teal ghosts",
            json: include_str!("../../../assets/presets/zoom-own-coatings.json"),
        },
        ShippedPreset {
            name: "zoom-stopped-down",
            title: "The Nikon zoom stopped down to f/11 with 7 rounded blades: small ghosts, a long star",
            json: include_str!("../../../assets/presets/zoom-stopped-down.json"),
        },
        ShippedPreset {
            name: "zoom-sun-sweep",
            title: "The Nikon zoom with the sun sweeping across the frame over two seconds (timeline keys)",
            json: include_str!("../../../assets/presets/zoom-sun-sweep.json"),
        },
        ShippedPreset {
            name: "master-prime-100",
            title: "Cine prime 100 mm (Master Prime type, one asphere), single coat, 9 rounded blades at f/4: a row of soft nonagons",
            json: include_str!("../../../assets/presets/master-prime-100.json"),
        },
        ShippedPreset {
            name: "compact-zoom-aspheric",
            title: "Compact zoom with three aspheres at f/5.6, six straight blades, single coat: a hexagon chain",
            json: include_str!("../../../assets/presets/compact-zoom-aspheric.json"),
        },
        ShippedPreset {
            name: "vintage-uncoated",
            title: "Vintage uncoated double Gauss 50 mm, wide open, round stop: bright colourless ghosts and haze",
            json: include_str!("../../../assets/presets/vintage-uncoated.json"),
        },
        ShippedPreset {
            name: "dgauss-single-coat",
            title: "Double Gauss 50 mm at f/4, single quarter-wave coat at 520 nm, 8 blades: the post-war look",
            json: include_str!("../../../assets/presets/dgauss-single-coat.json"),
        },
        ShippedPreset {
            name: "heliar-portrait",
            title: "Heliar 100 mm wide open (f/3.4), quarter-wave coated: two large soft discs, the star toned down 4 stops",
            json: include_str!("../../../assets/presets/heliar-portrait.json"),
        },
        ShippedPreset {
            name: "tessar-f8",
            title: "Tessar stopped down to f/8 with 7 rounded blades",
            json: include_str!("../../../assets/presets/tessar-f8.json"),
        },
        ShippedPreset {
            name: "telephoto-250",
            title: "Telephoto 250 mm, 9 rounded blades: a narrow field, the sun near the corner, the star toned down 6 stops",
            json: include_str!("../../../assets/presets/telephoto-250.json"),
        },
        ShippedPreset {
            name: "fisheye-10",
            title: "Fisheye 10 mm, 5 blades: the sun far off axis, ghosts strung across the whole frame",
            json: include_str!("../../../assets/presets/fisheye-10.json"),
        },
        ShippedPreset {
            name: "wide-22-broadband",
            title: "Wide angle 22 mm at f/5.6, broadband AR coat, 9 blades: a clean modern prime",
            json: include_str!("../../../assets/presets/wide-22-broadband.json"),
        },
        ShippedPreset {
            name: "wide-22-uncoated-night",
            title: "Wide angle 22 mm at f/2.8, bare glass, a street light low in the frame: strong ghosts for night",
            json: include_str!("../../../assets/presets/wide-22-uncoated-night.json"),
        },
        ShippedPreset {
            name: "zoom-dusty-front",
            title: "The Nikon zoom at f/11 with dust on its front element: hexagonal specks lit around the light (3% scattered)",
            json: include_str!("../../../assets/presets/zoom-dusty-front.json"),
        },
        ShippedPreset {
            name: "anamorphic-panavision",
            title: "Panavision's 20 mm anamorphic (US 2006/0050403), round iris, desqueezed 1.29 on Super 35: \
                    horizontal streaks between its cylinders, oval ghosts",
            json: include_str!("../../../assets/presets/anamorphic-panavision.json"),
        },
    ];
    PRESETS
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_preset_round_trips_and_an_older_one_loads_with_defaults() {
        let mut doc = Document { light_deg: [3.0, -2.0], ..Document::default() };
        doc.ghost_mut(2, 5).gain = 0.5;
        doc.solo = Some(ghost_key(2, 5));
        assert_eq!(Document::from_json(&doc.to_json()).unwrap(), doc);
        // Version 0 (before versions were written): only a light and a linear exposure, which becomes stops.
        let old = Document::from_json(r#"{"light_deg": [1.0, 2.0], "exposure": 1024.0}"#).unwrap();
        assert_eq!(old.light_deg, [1.0, 2.0]);
        assert_eq!(old.flare_ev, 10.0);
        assert_eq!(old.plate_ev, 0.0);
        assert_eq!(old.aperture, ApertureDoc::default());
        assert_eq!(old.version, PRESET_VERSION);
        // Version 1 with its exposure.
        let v1 = Document::from_json(r#"{"version": 1, "exposure": 2.0}"#).unwrap();
        assert_eq!(v1.flare_ev, 1.0);
        // Before version 3 an exposure was always chosen by hand: it stays locked.
        assert!(!v1.exposure_auto && !Document::from_json(r#"{"version": 2}"#).unwrap().exposure_auto);
        assert!(Document::from_json(r#"{"version": 3}"#).unwrap().exposure_auto);
    }

    #[test]
    fn bad_presets_are_refused_with_the_field_named() {
        let e = Document::from_json(r#"{"version": 99}"#).unwrap_err().to_string();
        assert!(e.contains("99") && e.contains("newer"), "{e}");
        let e = Document::from_json(r#"{"aperture": {"blades": "six"}}"#).unwrap_err().to_string();
        assert!(e.contains("aperture.blades"), "{e}");
        let e = Document::from_json(r#"{"exposure": -1}"#).unwrap_err().to_string();
        assert!(e.contains("exposure"), "{e}");
        let e = Document::from_json(r#"{"version": 2, "flare_ev": 1e9}"#).unwrap_err().to_string();
        assert!(e.contains("flare_ev"), "{e}");
        let e = Document::from_json(r#"{"blend": {"mode": "sideways"}}"#).unwrap_err().to_string();
        assert!(e.contains("blend.mode"), "{e}");
        let e = Document::from_json(r#"{"wavelengths": 0}"#).unwrap_err().to_string();
        assert!(e.contains("wavelengths"), "{e}");
        let e = Document::from_json("{ not json").unwrap_err().to_string();
        assert!(e.contains("line 1"), "{e}");
        let mut doc = Document::default();
        doc.lens.surfaces[0].semi_aperture_mm = -3.0;
        let e = Document::from_json(&doc.to_json()).unwrap_err().to_string();
        assert!(e.contains("lens") && e.contains("surface 0"), "{e}");
    }

    #[test]
    fn gains_follow_toggles_and_solo() {
        let mut doc = Document::default();
        assert_eq!(doc.ghost_gain(1, 2), 1.0);
        doc.ghost_mut(1, 2).enabled = false;
        assert_eq!(doc.ghost_gain(1, 2), 0.0);
        doc.ghost_mut(3, 4).gain = 2.0;
        doc.solo = Some(ghost_key(3, 4));
        assert_eq!((doc.ghost_gain(3, 4), doc.ghost_gain(0, 5)), (2.0, 0.0));
    }

    #[test]
    fn display_settings_do_not_change_the_optics_fingerprint() {
        let doc = Document::default();
        let key = doc.optics_fingerprint();
        let display = Document {
            flare_ev: 3.0,
            plate_ev: -2.0,
            tonemap: Tonemap::Reinhard,
            starburst: false,
            light_deg: [1.0, 1.0],
            background: Some("plate.exr".into()),
            ..doc.clone()
        };
        assert_eq!(display.optics_fingerprint(), key);
        let mut optics = doc.clone();
        optics.aperture.f_number = Some(8.0);
        assert_ne!(optics.optics_fingerprint(), key);
        let mut lens = doc;
        lens.lens.surfaces[1].radius_mm += 1e-9;
        assert_ne!(lens.optics_fingerprint(), key);
    }

    #[test]
    fn shipped_presets_load_and_the_default_one_is_the_default_document() {
        let docs: Vec<Document> =
            shipped().iter().map(|p| p.document().unwrap_or_else(|e| panic!("{}: {e}", p.name))).collect();
        assert!(docs.len() >= 12, "at least 12 looks ship: {}", docs.len());
        assert_eq!(docs[0], Document::default());
        // Every look is its own: no two share a name, a title or a document.
        for (a, pa) in shipped().iter().enumerate() {
            for (b, pb) in shipped().iter().enumerate().skip(a + 1) {
                assert_ne!(pa.name, pb.name);
                assert_ne!(pa.title, pb.title);
                assert_ne!(docs[a], docs[b], "{} and {} are the same look", pa.name, pb.name);
            }
        }
        // The looks span the library: at least nine different built-in lenses.
        let used: std::collections::BTreeSet<&str> = docs.iter().map(|d| d.lens.id.as_str()).collect();
        assert!(used.len() >= 9, "looks on {used:?}");
        assert!(used.iter().all(|id| crate::optics::library::ids().contains(id)));
        // Shipped looks follow the optics' exposure, but the anamorphic one, whose brightest ghost is a streak a
        // fraction of a millimetre thin (auto exposure sets that at display level 0.6 and the rest goes dark); a
        // preset naming its lens loads the whole prescription.
        for (p, d) in shipped().iter().zip(&docs) {
            assert_eq!(d.exposure_auto, p.name != "anamorphic-panavision", "{}", p.name);
        }
        assert_eq!(docs[0].lens, crate::optics::library::default_lens());
        let e = Document::open_named("no-such-look").unwrap_err().to_string();
        assert!(e.contains("no-such-look") && e.contains("fisheye-10") && e.contains("default"), "{e}");
        let e = Document::from_json(r#"{"version": 3, "lens": "leica"}"#).unwrap_err().to_string();
        assert!(e.contains("lens") && e.contains("leica"), "{e}");
    }

    #[test]
    fn a_look_replaces_the_optics_and_keeps_the_shot() {
        let mut shot = Document { background: Some("plate.exr".into()), plate_ev: -1.0, ..Document::default() };
        shot.timeline.last_frame = 48;
        let look = Document::open_named("fisheye-10").unwrap();
        let applied = shot.with_look(&look);
        assert_eq!((&applied.lens, &applied.aperture, applied.light_deg), (&look.lens, &look.aperture, look.light_deg));
        assert_eq!((&applied.background, applied.plate_ev), (&shot.background, -1.0));
        assert_eq!(applied.timeline, shot.timeline);
        // The camera is the look's: the anamorphic look frames its light on its own Super 35 sensor.
        let anamorphic = Document::open_named("anamorphic-panavision").unwrap();
        let applied = shot.with_look(&anamorphic);
        assert_ne!(anamorphic.sensor_width_mm, shot.sensor_width_mm);
        assert_eq!((applied.sensor_width_mm, applied.desqueeze), (anamorphic.sensor_width_mm, anamorphic.desqueeze));
        // On a fresh document a look is the preset itself.
        for preset in shipped() {
            let look = preset.document().unwrap();
            assert!(Document::default().with_look(&look) == look, "{}", preset.name);
        }
        let image = look.thumbnail(64, 36).unwrap();
        assert_eq!((image.width, image.height), (64, 36));
        assert!(image.pixels.iter().any(|p| p[0] > 40), "the thumbnail shows the flare");
    }

    #[test]
    fn saving_replaces_the_file_whole() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("flare.json");
        std::fs::write(&path, "old").unwrap();
        Document::default().save(&path).unwrap();
        assert_eq!(Document::open(&path).unwrap(), Document::default());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "no temporary file left behind");
    }

    /// Issue 33: a misspelled key, a gain, solo or keyed gain of a ghost the lens lacks, and an absurd gain are
    /// refused naming the field (they were ignored: 0 sprites, exit 0; 1e308 made a ghost vanish); a document
    /// carrying stale gains from another lens is written without them, so what is saved reads back.
    #[test]
    fn unknown_keys_and_ghosts_the_lens_lacks_are_refused_by_name() {
        let text = Document::default().to_json();
        let typo = text.replacen("\"flare_ev\"", "\"flare_evv\": 3.0,\n  \"flare_ev\"", 1);
        let e = Document::from_json(&typo).unwrap_err().to_string();
        assert!(e.contains("unknown key `flare_evv` (did you mean `flare_ev`?)"), "{e}");
        let nested = text.replacen("\"blades\"", "\"bladez\": 5,\n    \"blades\"", 1);
        let e = Document::from_json(&nested).unwrap_err().to_string();
        assert!(e.contains("aperture.bladez") && e.contains("`blades`"), "{e}");
        let pairs = Document::default().lens.ghost_pairs();
        let (i, j) = pairs[0];
        for (field, mut doc) in [
            ("ghosts.98-99", Document { ..Document::default() }),
            ("solo", Document { solo: Some("98-99".into()), ..Document::default() }),
            ("timeline.ghost_gain.98-99", Document::default()),
        ] {
            match field {
                "ghosts.98-99" => doc.ghost_mut(98, 99).gain = 2.0,
                "timeline.ghost_gain.98-99" => {
                    doc.timeline.ghost_gain.entry("98-99".into()).or_default().set(1, 2.0);
                }
                _ => {}
            }
            let e = doc.check().unwrap_err().to_string();
            assert!(e.contains(field) && e.contains("has no ghost `98-99`"), "{field}: {e}");
            // Saved, the stale keys are left out: the file reads back.
            let back = Document::from_json(&doc.to_json()).unwrap();
            assert!(back.ghosts.is_empty() && back.solo.is_none() && back.timeline.ghost_gain.is_empty());
        }
        let mut huge = Document::default();
        huge.ghost_mut(i, j).gain = 1e308;
        assert!(huge.check().unwrap_err().to_string().contains("must be from 0 to"), "an absurd gain is refused");
        // Issue 61: the LUT layer's gain had no upper bound (at 1e300 every LUT image was dropped, exit 0).
        let mut huge = Document::default();
        huge.blend.gain = 1e300;
        let e = huge.check().unwrap_err().to_string();
        assert!(e.contains("blend.gain") && e.contains("must be from 0 to 1000000"), "{e}");
        huge.blend.gain = MAX_GHOST_GAIN;
        huge.check().unwrap();
        let mut fine = Document::default();
        fine.ghost_mut(i, j).gain = 3.0;
        fine.solo = Some(ghost_key(i, j));
        assert_eq!(Document::from_json(&fine.to_json()).unwrap(), fine);
    }
}
