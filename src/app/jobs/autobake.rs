//! LUT ghosts without a click: when the lens, its stop, coatings or spectrum change, the app looks for their
//! LUT in memory, then in the on-disk cache ([`flare_core::bake::cache`]), and bakes it on a thread when
//! neither has it, showing the paraxial flare (and saying so) until it is ready. This module holds the state;
//! the job board ([`super`]) runs its step.
//!
//! # How it works
//! Each frame the job board's poll computes the cache key of the prepared flare (once per optics
//! change) and, unless the LUT on screen already has that key, takes the first of: a LUT kept in memory
//! ([`MEMORY`] of them, so an undo to a lens baked in this session is instant), a checked cache file (a
//! damaged one is removed, reported, and baked again), or a new bake. A bake for older optics is cancelled
//! when the optics change, an undo to a lens whose LUT is at hand included (no bake for optics the user left
//! runs on in the background; its thread is watched until it ends, and the next bake starts only then:
//! [`super::job::Slot`]); a bake the user
//! cancelled is not started again until they change. A finished
//! bake is stored on disk and in memory, and shown if its optics are still the live ones. A new bake starts only
//! once the optics have stood for [`SETTLE`] (a drag through many values bakes the last one), and takes the
//! ghosts it can from the latest LUT (`bake_with`'s `previous`: unchanged ghosts are not baked again); a setting
//! outside the optics (exposure, tonemap, light, plate) never restarts it. When a bake lands, the status bar says
//! that its LUT ghosts replace the paraxial ones. A baked LUT is shown
//! without writing the document (which may name no LUT: undo gives back exactly what was there); a preset saved
//! then says "simulated" (`Derived::resolved`), so it renders the same blended frame on the command line (which
//! reads the same cache). Nothing happens while
//! the user has a LUT file or a photo LUT open, or has turned automatic baking off.

use std::sync::Arc;

use flare_core::bake::BakeSettings;
use flare_core::bake::cache::LutCache;
use flare_core::bake::classify::GhostClass;
use flare_core::flare::PreparedFlare;
use flare_core::lut::blend::LiveLut;

/// LUTs kept in memory.
pub const MEMORY: usize = 6;

/// A baked LUT and, when this session baked it, the classification that chose its ghosts.
/// The LUT comes prepared for the frame ([`LiveLut::new`], done on the job's thread).
pub type Baked = (Arc<LiveLut>, Option<Vec<GhostClass>>);

/// What the disk cache held for the live optics, read and prepared on a thread.
pub enum Found {
    Hit(Arc<LiveLut>),
    /// A damaged or stale file (removed by the cache), and why.
    Rejected(String),
    Miss,
}

/// The automatic bake's state.
pub struct AutoBake {
    /// Bake LUT ghosts by themselves (the Blend panel's switch).
    pub enabled: bool,
    /// What the bakes use (the default settings; tests make them coarse).
    pub settings: BakeSettings,
    /// The on-disk cache (`None`: no home folder; memory only).
    pub cache: Option<LutCache>,
    memory: Vec<(u64, Baked)>,
    /// The key of the LUT on screen.
    pub shown: Option<u64>,
    /// A key whose bake the user cancelled.
    pub declined: Option<u64>,
    /// A key already looked for on disk (a miss is not looked for again every frame).
    pub looked_up: Option<u64>,
    /// The optics fingerprint and the cache key computed for it.
    pub key_of: Option<(u64, u64)>,
    /// How many bakes were started (for the tests: an undo to a baked lens starts none).
    pub bakes_started: u64,
    /// The key of the live optics as last seen (an edit is a change of it).
    pub live: Option<u64>,
    /// Optics an edit made, waiting to settle before their bake starts: their key and since when they are the
    /// live ones.
    pub settling: Option<(u64, std::time::Instant)>,
    /// How long the optics must stay as they are before a bake starts ([`SETTLE`]; tests set 0).
    pub settle: std::time::Duration,
}

/// How long an edit of the optics must stand before the automatic bake starts for it: dragging a radius or a
/// stop through many values starts one bake, for the value let go, not one per value.
pub const SETTLE: std::time::Duration = std::time::Duration::from_millis(800);

impl Default for AutoBake {
    fn default() -> Self {
        Self {
            enabled: true,
            settings: BakeSettings::default(),
            cache: LutCache::user(),
            memory: Vec::new(),
            shown: None,
            declined: None,
            looked_up: None,
            key_of: None,
            bakes_started: 0,
            live: None,
            settling: None,
            settle: SETTLE,
        }
    }
}

impl AutoBake {
    /// The cache key of `flare` (computed again only when `optics` changes).
    pub(super) fn key(&mut self, flare: &PreparedFlare, optics: u64) -> u64 {
        match self.key_of {
            Some((o, key)) if o == optics => key,
            _ => {
                let key = LutCache::key(&flare.system.lens, &flare.config, &self.settings);
                self.key_of = Some((optics, key));
                key
            }
        }
    }

    pub(super) fn remembered(&self, key: u64) -> Option<Baked> {
        self.memory.iter().find(|(k, _)| *k == key).map(|(_, b)| b.clone())
    }

    pub(super) fn remember(&mut self, key: u64, baked: Baked) {
        self.memory.retain(|(k, _)| *k != key);
        self.memory.push((key, baked));
        let excess = self.memory.len().saturating_sub(MEMORY);
        self.memory.drain(..excess);
    }

    /// The latest LUT in memory: it lends a new bake the ghosts whose images cannot have changed.
    pub(super) fn latest(&self) -> Option<Arc<LiveLut>> {
        self.memory.last().map(|(_, (live, _))| live.clone())
    }
}
