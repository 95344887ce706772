//! The automatic bake's step each frame (the policy is described in [`super::autobake`]): the LUT of the
//! live optics from memory, from the cache, or baked once their edit has stood.

use std::sync::Arc;

use flare_core::bake::cache::Lookup;
use flare_core::lut::blend::LiveLut;

use super::job::Job;

use super::autobake::Found;
use super::{JobBoard, JobEvent, Live};

impl JobBoard {
    /// One frame of the automatic bake (see [`super::autobake`]).
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
        // Shown, or being shown this very frame (a bake that just landed: `live` is from before it).
        let landing = self.landing(key) || events.iter().any(|e| matches!(e, JobEvent::ShowLut(..)));
        if self.autobake.shown == Some(key) && (live.lut_shown || landing) {
            return;
        }
        if let Some(baked) = self.autobake.remembered(key) {
            self.stop_bake_unless_for(key);
            self.show_baked(key, baked, "kept from this session");
            return;
        }
        // The disk cache, read on a thread (a large LUT is hundreds of MB, and preparing it for the frame takes
        // a moment more): nothing is baked until it answers.
        if self.autobake.looked_up != Some(key) {
            if let Some(done) = self.lookup.poll()
                && done.key == key
            {
                self.autobake.looked_up = Some(key);
                match done.outcome {
                    Found::Hit(live) => {
                        self.stop_bake_unless_for(key);
                        let baked = (live, None);
                        self.autobake.remember(key, baked.clone());
                        self.show_baked(key, baked, "from the cache");
                        return;
                    }
                    Found::Rejected(reason) => events.push(JobEvent::Say(format!("{reason}: baking it again"))),
                    Found::Miss => {}
                }
            } else if let Some(cache) = self.autobake.cache.clone() {
                let settings = self.autobake.settings.clone();
                let flare = flare.clone();
                self.lookup.request(key, move || {
                    Job::spawn("reading the LUT cache", move |_, _| {
                        match cache.load(&flare.system.lens, &flare.config, &settings) {
                            Lookup::Hit(lut) => Found::Hit(Arc::new(LiveLut::new(*lut))),
                            Lookup::Rejected(reason) => Found::Rejected(reason),
                            Lookup::Miss => Found::Miss,
                        }
                    })
                });
                return;
            } else {
                self.autobake.looked_up = Some(key);
            }
        }
        if self.bakes(key) || self.autobake.declined == Some(key) {
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
