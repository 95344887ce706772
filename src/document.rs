//! The document: everything a preset saves and undo restores (lens, aperture, coatings, blend, ghost gains,
//! light, exposure), separate from GPU and transient state.
//!
//! # How it works
//! [`Document`] is plain data with `#[serde(default)]` on every struct, so a preset written by an older
//! FlareLab (a lower [`PRESET_VERSION`], fewer fields) loads with today's defaults for what it lacks; a preset
//! from a newer FlareLab is refused by its version, never half-read. [`Document::from_json`] names the field
//! that is wrong (through `serde_path_to_error`) and then checks values serde cannot (a lens that is not
//! physically possible, a negative gain, an unknown blend mode); [`Document::save`] writes to a temporary
//! file renamed over the target, so a crash never leaves half a preset. The app derives everything it draws
//! from the document ([`Document::flare_config`], [`Document::ghost_gain`]) and rebuilds what depends on
//! the optics only when [`Document::optics_key`] changes.

use std::collections::BTreeMap;
use std::path::Path;

use flare_core::aperture::{Aperture, ApertureShape};
use flare_core::flare::FlareConfig;
use flare_core::lut::blend::{BlendMode, BlendSettings};
use flare_core::optics::formats::write_atomic;
use flare_core::optics::library::default_lens;
use flare_core::optics::{Coating, Lens};
use flare_core::render::{DisplaySettings, Tonemap};
use serde::{Deserialize, Serialize};

/// The preset format this build writes; it reads every version up to this one.
pub const PRESET_VERSION: u32 = 1;

/// Why a preset is refused.
#[derive(Debug, thiserror::Error)]
pub enum PresetError {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("not a FlareLab preset: at `{path}`: {reason}")]
    Json { path: String, reason: String },
    #[error("preset version {0} is newer than this FlareLab reads ({PRESET_VERSION}); update FlareLab")]
    Newer(u32),
    #[error("preset field `{field}`: {reason}")]
    Value { field: String, reason: String },
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

/// The tonemap, by name in files.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TonemapDoc {
    None,
    Reinhard,
    #[default]
    Aces,
}

impl From<TonemapDoc> for Tonemap {
    fn from(t: TonemapDoc) -> Self {
        match t {
            TonemapDoc::None => Tonemap::None,
            TonemapDoc::Reinhard => Tonemap::Reinhard,
            TonemapDoc::Aces => Tonemap::Aces,
        }
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
    pub blend: BlendDoc,
    /// Per ghost, keyed by its surface pair `"I-J"`; absent ghosts are on at gain 1.
    pub ghosts: BTreeMap<String, GhostDoc>,
    /// Show only this ghost (`"I-J"`).
    pub solo: Option<String>,
    /// Where the light appears in the frame (degrees, X right, Y up).
    pub light_deg: [f64; 2],
    pub exposure: f32,
    pub tonemap: TonemapDoc,
    pub starburst: bool,
    /// Background plate file (PNG/EXR/HDR), if any.
    pub background: Option<String>,
}

impl Default for Document {
    fn default() -> Self {
        Self {
            version: PRESET_VERSION,
            lens: default_lens(),
            aperture: ApertureDoc::default(),
            // Coated ghosts are ~100x dimmer than bare ones: the default exposure matches a quarter-wave coat.
            coating_override: Some(Coating::QuarterWave { design_wavelength_nm: 550.0, layer_index: None }),
            blend: BlendDoc::default(),
            ghosts: BTreeMap::new(),
            solo: None,
            light_deg: [6.0, 4.0],
            exposure: 1500.0,
            tonemap: TonemapDoc::Aces,
            starburst: true,
            background: None,
        }
    }
}

/// The key of a ghost in [`Document::ghosts`].
pub fn ghost_key(i: usize, j: usize) -> String {
    format!("{i}-{j}")
}

impl Document {
    /// The flare settings of this document (`divisor`: the accumulation divisor the adapter wants).
    pub fn flare_config(&self, divisor: u32) -> FlareConfig {
        let a = &self.aperture;
        let shape = if a.blades < 3 {
            ApertureShape::Circle
        } else {
            ApertureShape::Blades { count: a.blades, rotation_deg: a.rotation_deg, roundness: a.roundness }
        };
        FlareConfig {
            aperture: Aperture { shape, f_number: a.f_number },
            coating_override: self.coating_override.clone(),
            display: DisplaySettings {
                exposure: self.exposure,
                tonemap: self.tonemap.into(),
                starburst: self.starburst,
                accumulation_divisor: divisor,
                ..DisplaySettings::default()
            },
            ..FlareConfig::default()
        }
    }

    /// What the prepared flare depends on (everything but the light, the gains and the blend): the app
    /// rebuilds the ghost system only when this changes.
    pub fn optics_key(&self) -> String {
        format!(
            "{:?}|{:?}|{:?}|{}|{:?}|{}",
            self.lens, self.aperture, self.coating_override, self.exposure, self.tonemap, self.starburst
        )
    }

    /// The gain ghost (i, j) is drawn with: 0 when it is off or another ghost is solo.
    pub fn ghost_gain(&self, i: usize, j: usize) -> f64 {
        let key = ghost_key(i, j);
        if self.solo.as_ref().is_some_and(|s| *s != key) {
            return 0.0;
        }
        match self.ghosts.get(&key) {
            Some(g) if !g.enabled => 0.0,
            Some(g) => g.gain,
            None => 1.0,
        }
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

    /// The preset's JSON text.
    pub fn to_json(&self) -> String {
        let mut doc = self.clone();
        doc.version = PRESET_VERSION;
        serde_json::to_string_pretty(&doc).expect("a document always serialises")
    }

    /// Reads a preset (any version up to [`PRESET_VERSION`]) and checks it.
    pub fn from_json(text: &str) -> Result<Self, PresetError> {
        let value: serde_json::Value = serde_json::from_str(text)
            .map_err(|e| PresetError::Json { path: format!("line {}", e.line()), reason: e.to_string() })?;
        let version = value.get("version").and_then(serde_json::Value::as_u64).unwrap_or(0);
        if version > u64::from(PRESET_VERSION) {
            return Err(PresetError::Newer(version as u32));
        }
        let mut doc: Document = serde_path_to_error::deserialize(value)
            .map_err(|e| PresetError::Json { path: e.path().to_string(), reason: e.inner().to_string() })?;
        doc.version = PRESET_VERSION;
        doc.check()?;
        Ok(doc)
    }

    /// Values serde cannot check.
    pub fn check(&self) -> Result<(), PresetError> {
        let bad = |field: &str, reason: String| Err(PresetError::Value { field: field.into(), reason });
        if let Err(e) = self.lens.validate() {
            return bad("lens", e.to_string());
        }
        if !(self.exposure.is_finite() && self.exposure > 0.0) {
            return bad("exposure", format!("{} must be a positive number", self.exposure));
        }
        if !self.light_deg.iter().all(|a| a.is_finite() && a.abs() <= 89.0) {
            return bad("light_deg", format!("{:?}: angles from -89 to 89 degrees", self.light_deg));
        }
        if let Some(f) = self.aperture.f_number
            && !(f.is_finite() && f > 0.0)
        {
            return bad("aperture.f_number", format!("{f} must be positive"));
        }
        if !(self.aperture.roundness.is_finite() && (0.0..=1.0).contains(&self.aperture.roundness)) {
            return bad("aperture.roundness", format!("{} must be from 0 to 1", self.aperture.roundness));
        }
        if self.aperture.blades > 32 || !self.aperture.rotation_deg.is_finite() {
            return bad("aperture", "at most 32 blades, a finite rotation".into());
        }
        if let Err(e) = BlendMode::parse(&self.blend.mode) {
            return bad("blend.mode", e);
        }
        if !(self.blend.gain.is_finite() && self.blend.gain >= 0.0) {
            return bad("blend.gain", format!("{} must be 0 or more", self.blend.gain));
        }
        for (key, g) in &self.ghosts {
            if !(g.gain.is_finite() && g.gain >= 0.0) {
                return bad(&format!("ghosts.{key}.gain"), format!("{} must be 0 or more", g.gain));
            }
        }
        Ok(())
    }

    /// Opens a preset file.
    pub fn open(path: &Path) -> Result<Self, PresetError> {
        Self::from_json(&std::fs::read_to_string(path)?)
    }

    /// Writes the preset atomically (temporary file, then rename).
    pub fn save(&self, path: &Path) -> Result<(), PresetError> {
        write_atomic(path, self.to_json().as_bytes())?;
        Ok(())
    }
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
        // Version 0 (before versions were written): only a light and an exposure.
        let old = Document::from_json(r#"{"light_deg": [1.0, 2.0], "exposure": 10.0}"#).unwrap();
        assert_eq!(old.light_deg, [1.0, 2.0]);
        assert_eq!(old.aperture, ApertureDoc::default());
        assert_eq!(old.version, PRESET_VERSION);
    }

    #[test]
    fn bad_presets_are_refused_with_the_field_named() {
        let e = Document::from_json(r#"{"version": 99}"#).unwrap_err().to_string();
        assert!(e.contains("99") && e.contains("newer"), "{e}");
        let e = Document::from_json(r#"{"aperture": {"blades": "six"}}"#).unwrap_err().to_string();
        assert!(e.contains("aperture.blades"), "{e}");
        let e = Document::from_json(r#"{"exposure": -1}"#).unwrap_err().to_string();
        assert!(e.contains("exposure"), "{e}");
        let e = Document::from_json(r#"{"blend": {"mode": "sideways"}}"#).unwrap_err().to_string();
        assert!(e.contains("blend.mode"), "{e}");
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
    fn saving_replaces_the_file_whole() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("flare.json");
        std::fs::write(&path, "old").unwrap();
        Document::default().save(&path).unwrap();
        assert_eq!(Document::open(&path).unwrap(), Document::default());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "no temporary file left behind");
    }
}
