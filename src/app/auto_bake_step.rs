//! The automatic bake's step each frame and its hand-over to the screen (see [`super::autobake`]).

use std::sync::Arc;

use flare_core::flare::PreparedFlare;
use flare_core::lut::cache::Lookup;
use flare_core::preset::LutSource;

use super::FlareLabApp;
use super::autobake::Baked;
use super::bake::{self, BakeOutcome};
use crate::panels::BakeStatus;

impl FlareLabApp {
    /// One frame of the automatic bake (see the module documentation).
    pub(super) fn auto_bake_step(&mut self) {
        if !self.autobake.enabled
            || !matches!(self.session.doc().blend.lut, LutSource::None | LutSource::Simulated { path: None })
        {
            return;
        }
        if self.derived.lens_problem.is_some() {
            return;
        }
        let (Some(key), Some(flare)) = (self.live_bake_key(), self.derived.flare.clone()) else { return };
        // An edit of the optics (not the optics the session started with) starts the settling clock.
        if self.autobake.live != Some(key) {
            if self.autobake.live.is_some() {
                self.autobake.settling = Some((key, std::time::Instant::now()));
            }
            self.autobake.live = Some(key);
        }
        if self.autobake.shown == Some(key) && self.derived.lut.is_some() {
            return;
        }
        if let Some(baked) = self.autobake.remembered(key) {
            self.show_baked(key, baked, "kept from this session");
            return;
        }
        if self.autobake.looked_up != Some(key) {
            self.autobake.looked_up = Some(key);
            if let Some(cache) = &self.autobake.cache {
                match cache.load(&flare.system.lens, &flare.config, &self.autobake.settings) {
                    Lookup::Hit(lut) => {
                        let baked = (Arc::new(*lut), None);
                        self.autobake.remember(key, baked.clone());
                        self.show_baked(key, baked, "from the cache");
                        return;
                    }
                    Lookup::Rejected(reason) => self.session.say(format!("{reason}: baking it again")),
                    Lookup::Miss => {}
                }
            }
        }
        if (self.autobake.baking == Some(key) && self.bake.is_some()) || self.autobake.declined == Some(key) {
            return;
        }
        if let Some(old) = self.bake.take() {
            // A bake for optics that are no longer the live ones.
            old.cancel();
            self.autobake.baking = None;
        }
        // Optics an edit just made must stand for a moment before their bake starts (see `autobake::SETTLE`).
        if let Some((k, since)) = self.autobake.settling
            && k == key
            && since.elapsed() < self.autobake.settle
        {
            return;
        }
        self.autobake.settling = None;
        self.spawn_bake(flare, key);
    }

    /// Starts a bake of `flare` (cache key `key`) on its thread.
    pub(super) fn spawn_bake(&mut self, flare: Arc<PreparedFlare>, key: u64) {
        let previous = self.autobake.latest();
        let (settings, cache) = (self.autobake.settings.clone(), self.autobake.cache.clone());
        self.bake = Some(bake::start_bake(flare, previous, settings, cache));
        self.autobake.baking = Some(key);
        self.autobake.declined = None;
        self.autobake.bakes_started += 1;
        self.bake_status = BakeStatus::Running { fraction: 0.0, text: bake::CLASSIFYING.into() };
    }

    /// The cache key of the live optics (`None` while there is no valid flare).
    pub(super) fn live_bake_key(&mut self) -> Option<u64> {
        let (flare, optics) = (self.derived.flare.clone()?, self.derived.optics_key?);
        Some(self.autobake.key(&flare, optics))
    }

    /// A finished bake (already in the disk cache): kept in memory, and shown if its optics are still the
    /// live ones.
    pub(super) fn finish_bake(&mut self, outcome: BakeOutcome) {
        let key = self.autobake.baking.take();
        match outcome {
            Ok(done) => {
                if let Err(e) = done.cached {
                    self.session.say(e);
                }
                let ghosts = done.lut.ghosts.len();
                let source = format!("baked {}", done.device);
                let baked = (Arc::new(done.lut), Some(done.classes));
                let Some(key) = key else { return };
                self.autobake.remember(key, baked.clone());
                if Some(key) == self.live_bake_key() {
                    self.show_baked(key, baked, &source);
                } else {
                    self.bake_status = BakeStatus::Done(format!("baked {ghosts} ghosts for earlier optics (kept)"));
                }
            }
            Err(e) => {
                if e.contains("cancelled") {
                    self.autobake.declined = key;
                }
                self.bake_status = BakeStatus::Failed(format!("bake stopped: {e}"));
            }
        }
    }

    /// Puts a baked LUT on screen and records that the document uses it (no undo step of its own).
    fn show_baked(&mut self, key: u64, (lut, classes): Baked, source: &str) {
        let (ghosts, entries) = (lut.ghosts.len(), lut.entry_count());
        self.set_lut(Some((*lut).clone()));
        self.classes = classes;
        self.autobake.shown = Some(key);
        self.session.adopt_baked_lut();
        self.bake_status =
            BakeStatus::Done(format!("LUT ghosts on: {ghosts} non-linear ghosts, {entries} entries ({source})"));
        // The look changes under the artist: said in the status bar, replacing what it said.
        self.session.say(format!("LUT ghosts ({source}) now replace the paraxial flare's {ghosts} non-linear ghosts"));
    }
}
