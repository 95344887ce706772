//! The automatic bake's step each frame (the policy is described in [`crate::app::autobake`]): the LUT of the
//! live optics from memory, from the cache, or baked once their edit has stood.

use std::sync::Arc;

use flare_core::lut::cache::Lookup;

use super::{JobBoard, JobEvent, Live};

impl JobBoard {
    /// One frame of the automatic bake (see [`crate::app::autobake`]).
    pub(super) fn auto_bake_step(&mut self, live: &Live, events: &mut Vec<JobEvent>) {
        if !self.auto_bake_serves(live.doc) || live.lens_refused {
            return;
        }
        let (Some(key), Some(flare)) = (self.live_key(live), live.flare.cloned()) else { return };
        // An edit of the optics (not the optics the session started with) starts the settling clock.
        if self.autobake.live != Some(key) {
            if self.autobake.live.is_some() {
                self.autobake.settling = Some((key, std::time::Instant::now()));
            }
            self.autobake.live = Some(key);
        }
        if self.autobake.shown == Some(key) && live.lut_shown {
            return;
        }
        if let Some(baked) = self.autobake.remembered(key) {
            self.stop_bake_unless_for(key);
            self.show_baked(key, baked, "kept from this session", events);
            return;
        }
        if self.autobake.looked_up != Some(key) {
            self.autobake.looked_up = Some(key);
            if let Some(cache) = &self.autobake.cache {
                match cache.load(&flare.system.lens, &flare.config, &self.autobake.settings) {
                    Lookup::Hit(lut) => {
                        self.stop_bake_unless_for(key);
                        let baked = (Arc::new(*lut), None);
                        self.autobake.remember(key, baked.clone());
                        self.show_baked(key, baked, "from the cache", events);
                        return;
                    }
                    Lookup::Rejected(reason) => events.push(JobEvent::Say(format!("{reason}: baking it again"))),
                    Lookup::Miss => {}
                }
            }
        }
        if (self.autobake.baking == Some(key) && self.bake.is_some()) || self.autobake.declined == Some(key) {
            return;
        }
        // A bake for optics that are no longer the live ones.
        self.stop_bake_unless_for(key);
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
}
