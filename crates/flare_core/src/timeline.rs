//! The shot's timeline: a frame range at a frame rate, and keyframes for the light's position (degrees), the
//! light's intensity (stops) and any ghost's gain.
//!
//! # How it works
//! Each animated value is a [`Track`]: keys sorted by frame, at most one per frame. [`Track::value_at`] holds
//! the first key's value before it and the last key's after it; between two keys it interpolates by the
//! timeline's [`Interpolation`]: `Linear`, or `Smooth`, a cubic Hermite curve through the keys whose tangents
//! are the Catmull-Rom ones (the slope between the two neighbouring keys; at an end key, the slope to its
//! only neighbour), so the motion has no corners at the keys. A smooth curve can overshoot between keys
//! whose values turn back; a gain evaluated below 0 is taken as 0. A track with no keys has no value: the
//! document's static value is used ([`crate::preset::Document::light_at`]). Frames are whole numbers; a
//! fractional frame (the app's playback between frames, an instant while the shutter is open) interpolates
//! the same way. [`Timeline::shutter_deg`] is the camera's shutter: each frame averages the light over that
//! share of the frame ([`crate::shutter`]).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// How values between keys are made.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Interpolation {
    Linear,
    /// Cubic Hermite with Catmull-Rom tangents (see the module documentation).
    #[default]
    Smooth,
}

/// One key: a value at a frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Key<T> {
    pub frame: i64,
    pub value: T,
}

/// Values that can be interpolated: a number or a pair of numbers.
pub trait Animatable: Copy {
    fn lerp(a: Self, b: Self, t: f64) -> Self;
    /// `a + (b - a) * s` component-wise with an arbitrary factor (for tangents).
    fn combine(terms: &[(Self, f64)]) -> Self;
}

impl Animatable for f64 {
    fn lerp(a: Self, b: Self, t: f64) -> Self {
        a + (b - a) * t
    }
    fn combine(terms: &[(Self, f64)]) -> Self {
        terms.iter().map(|(v, w)| v * w).sum()
    }
}

impl Animatable for [f64; 2] {
    fn lerp(a: Self, b: Self, t: f64) -> Self {
        [f64::lerp(a[0], b[0], t), f64::lerp(a[1], b[1], t)]
    }
    fn combine(terms: &[(Self, f64)]) -> Self {
        [terms.iter().map(|(v, w)| v[0] * w).sum(), terms.iter().map(|(v, w)| v[1] * w).sum()]
    }
}

/// Keys of one animated value, sorted by frame, one per frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Track<T> {
    pub keys: Vec<Key<T>>,
}

impl<T> Default for Track<T> {
    fn default() -> Self {
        Self { keys: Vec::new() }
    }
}

impl<T: Animatable> Track<T> {
    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    /// The key at `frame`, if there is one.
    pub fn key_at(&self, frame: i64) -> Option<&Key<T>> {
        self.keys.binary_search_by_key(&frame, |k| k.frame).ok().map(|i| &self.keys[i])
    }

    /// Sets (adds or replaces) the key at `frame`.
    pub fn set(&mut self, frame: i64, value: T) {
        match self.keys.binary_search_by_key(&frame, |k| k.frame) {
            Ok(i) => self.keys[i].value = value,
            Err(i) => self.keys.insert(i, Key { frame, value }),
        }
    }

    /// Deletes the key at `frame`; true when there was one.
    pub fn delete(&mut self, frame: i64) -> bool {
        match self.keys.binary_search_by_key(&frame, |k| k.frame) {
            Ok(i) => {
                self.keys.remove(i);
                true
            }
            Err(_) => false,
        }
    }

    /// The value at `frame` (see the module documentation); `None` when the track has no keys.
    pub fn value_at(&self, frame: f64, interpolation: Interpolation) -> Option<T> {
        let keys = &self.keys;
        let first = keys.first()?;
        let last = keys.last()?;
        if frame <= first.frame as f64 {
            return Some(first.value);
        }
        if frame >= last.frame as f64 {
            return Some(last.value);
        }
        // keys[i].frame <= frame < keys[i + 1].frame
        let i = keys.partition_point(|k| (k.frame as f64) <= frame) - 1;
        let (a, b) = (&keys[i], &keys[i + 1]);
        // In doubles: the span between two keys never overflows (checked keys are within `MAX_KEY_FRAME`).
        let span = b.frame as f64 - a.frame as f64;
        let t = (frame - a.frame as f64) / span;
        Some(match interpolation {
            Interpolation::Linear => T::lerp(a.value, b.value, t),
            Interpolation::Smooth => {
                // Tangents in value per frame, times the span: Catmull-Rom, one-sided at the ends.
                let slope = |p: &Key<T>, q: &Key<T>| (p.value, q.value, q.frame as f64 - p.frame as f64);
                let tangent = |before: Option<&Key<T>>, after: Option<&Key<T>>, here: &Key<T>| {
                    let (p, q, df) = slope(before.unwrap_or(here), after.unwrap_or(here));
                    T::combine(&[(q, span / df), (p, -span / df)])
                };
                let m0 = tangent(i.checked_sub(1).map(|j| &keys[j]), Some(b), a);
                let m1 = tangent(Some(a), keys.get(i + 2), b);
                let (t2, t3) = (t * t, t * t * t);
                T::combine(&[
                    (a.value, 2.0 * t3 - 3.0 * t2 + 1.0),
                    (m0, t3 - 2.0 * t2 + t),
                    (b.value, -2.0 * t3 + 3.0 * t2),
                    (m1, t3 - t2),
                ])
            }
        })
    }

    /// Problems with the keys, for [`Timeline::check`]: unsorted or repeated frames, frames beyond
    /// [`MAX_KEY_FRAME`], values not finite.
    /// `valid` says whether a value is within bounds, `bounds` says them in words.
    fn check(&self, field: &str, valid: impl Fn(&T) -> bool, bounds: &str) -> Result<(), String> {
        if let Some((n, k)) = self.keys.iter().enumerate().find(|(_, k)| k.frame.unsigned_abs() > MAX_KEY_FRAME as u64)
        {
            return Err(format!("{field}[{n}]: frame {} is beyond +-{MAX_KEY_FRAME}", k.frame));
        }
        for (n, pair) in self.keys.windows(2).enumerate() {
            if pair[1].frame <= pair[0].frame {
                return Err(format!("{field}[{}]: frame {} follows frame {}", n + 1, pair[1].frame, pair[0].frame));
            }
        }
        if let Some((n, k)) = self.keys.iter().enumerate().find(|(_, k)| !valid(&k.value)) {
            return Err(format!("{field}[{n}]: frame {} has a value that is not {bounds}", k.frame));
        }
        Ok(())
    }
}

/// The shot: its frames and the keys (see the module documentation).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Timeline {
    pub first_frame: i64,
    pub last_frame: i64,
    pub fps: f64,
    pub interpolation: Interpolation,
    /// Where the light appears in the frame (degrees, X right, Y up).
    pub light_deg: Track<[f64; 2]>,
    /// The light's intensity in stops relative to the document's (0: as set; -1: half).
    pub light_ev: Track<f64>,
    /// Ghost gains by the ghost's key `"I-J"` (they replace the ghost panel's gain; its on/off and solo still
    /// apply).
    pub ghost_gain: BTreeMap<String, Track<f64>>,
    /// The shutter in degrees (0: none, the sharp frame; 180: open half of each frame): a light that moves
    /// while it is open streaks its ghosts ([`crate::shutter`]).
    pub shutter_deg: f64,
}

impl Default for Timeline {
    fn default() -> Self {
        Self {
            first_frame: 1,
            last_frame: 100,
            fps: 24.0,
            interpolation: Interpolation::Smooth,
            light_deg: Track::default(),
            light_ev: Track::default(),
            ghost_gain: BTreeMap::new(),
            shutter_deg: 0.0,
        }
    }
}

/// The animated values at one frame (`None`: not animated, the document's static value holds).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Sample {
    pub light_deg: Option<[f64; 2]>,
    pub light_ev: f64,
    pub ghost_gain: BTreeMap<String, f64>,
}

impl Timeline {
    /// The frames of the shot, first to last.
    pub fn frames(&self) -> std::ops::RangeInclusive<i64> {
        self.first_frame..=self.last_frame
    }

    /// Every key frame of any track (for the app's ticks), sorted, once each.
    pub fn key_frames(&self) -> Vec<i64> {
        let mut frames: Vec<i64> = self.light_deg.keys.iter().map(|k| k.frame).collect();
        frames.extend(self.light_ev.keys.iter().map(|k| k.frame));
        frames.extend(self.ghost_gain.values().flat_map(|t| t.keys.iter().map(|k| k.frame)));
        frames.sort_unstable();
        frames.dedup();
        frames
    }

    /// True when any track has a key at `frame`.
    pub fn has_key_at(&self, frame: i64) -> bool {
        self.light_deg.key_at(frame).is_some()
            || self.light_ev.key_at(frame).is_some()
            || self.ghost_gain.values().any(|t| t.key_at(frame).is_some())
    }

    /// Deletes every key at `frame`; true when there was one.
    pub fn delete_keys_at(&mut self, frame: i64) -> bool {
        let mut any = self.light_deg.delete(frame);
        any |= self.light_ev.delete(frame);
        for track in self.ghost_gain.values_mut() {
            any |= track.delete(frame);
        }
        self.ghost_gain.retain(|_, t| !t.is_empty());
        any
    }

    /// The animated values at `frame`.
    pub fn sample(&self, frame: f64) -> Sample {
        let how = self.interpolation;
        Sample {
            light_deg: self.light_deg.value_at(frame, how),
            light_ev: self.light_ev.value_at(frame, how).unwrap_or(0.0),
            ghost_gain: self
                .ghost_gain
                .iter()
                .filter_map(|(k, t)| Some((k.clone(), t.value_at(frame, how)?.max(0.0))))
                .collect(),
        }
    }

    /// Why the timeline cannot be used, naming the field: an empty range, a frame rate that is not positive,
    /// keys out of order or not finite, a light angle of 90 degrees or more, a negative gain.
    pub fn check(&self) -> Result<(), (String, String)> {
        let field = |f: &str| format!("timeline.{f}");
        if self.last_frame < self.first_frame {
            return Err((
                field("last_frame"),
                format!("{} is before first_frame {}", self.last_frame, self.first_frame),
            ));
        }
        for (name, frame) in [("first_frame", self.first_frame), ("last_frame", self.last_frame)] {
            if frame.unsigned_abs() > MAX_KEY_FRAME as u64 {
                return Err((field(name), format!("{frame} is beyond +-{MAX_KEY_FRAME}")));
            }
        }
        if let Err(reason) = check_frame_count(self.first_frame, self.last_frame) {
            return Err((field("last_frame"), reason));
        }
        if !(self.fps.is_finite() && self.fps > 0.0) {
            return Err((field("fps"), format!("{} is not a positive frame rate", self.fps)));
        }
        crate::shutter::check_shutter(self.shutter_deg).map_err(|reason| (field("shutter_deg"), reason))?;
        let in_field = |r: Result<(), String>, f: &str| r.map_err(|reason| (field(f), reason));
        in_field(
            self.light_deg.check(
                "light_deg",
                |v| v.iter().all(|a| a.is_finite() && a.abs() < 90.0),
                "a finite angle under 90 degrees",
            ),
            "light_deg",
        )?;
        in_field(
            self.light_ev.check(
                "light_ev",
                |v| v.is_finite() && v.abs() <= 64.0,
                "a finite number of stops within +-64",
            ),
            "light_ev",
        )?;
        for (ghost, track) in &self.ghost_gain {
            let bounds = format!("a gain from 0 to {MAX_GHOST_GAIN}");
            in_field(
                track.check(ghost, |v| v.is_finite() && (0.0..=MAX_GHOST_GAIN).contains(v), &bounds),
                "ghost_gain",
            )?;
        }
        Ok(())
    }
}

/// The largest gain of one ghost, static or keyed, and of the LUT layer (+60 dB): more is no look, and 1e308
/// overflowed to a ghost that vanished (keyed at 1e39 every sprite was dropped, the LUT layer's 1e300 every LUT
/// image).
pub(crate) const MAX_GHOST_GAIN: f64 = 1e6;

/// The farthest key or range end from frame 0: 2^53 - 1, the integers a double holds exactly (a key's place
/// between two others is worked out in doubles). Keys near +-2^62 overflowed the span between them (`i64`)
/// and put the light at -1.48e21 degrees.
pub(crate) const MAX_KEY_FRAME: i64 = (1 << 53) - 1;

/// The most frames a timeline (and a rendered range) may span: 1,000,000, over 11 hours at 24 fps. A shot's plan
/// holds a record per frame; a range of a hundred million frames asked for gigabytes before the first frame.
pub(crate) const MAX_FRAMES: i64 = 1_000_000;

/// Refuses a range `first..=last` longer than `MAX_FRAMES` (or whose length overflows).
pub fn check_frame_count(first: i64, last: i64) -> Result<(), String> {
    match last.checked_sub(first).and_then(|d| d.checked_add(1)) {
        Some(n) if n <= MAX_FRAMES => Ok(()),
        _ => Err(format!(
            "frames {first} to {last} are more than {MAX_FRAMES} frames (over 11 hours at 24 fps): render the shot in parts"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 61: keys near +-2^62 overflowed the span between them (the light at -1.48e21 degrees, exit 0);
    /// keyed gains had no upper bound (at 1e39 every sprite was dropped).
    #[test]
    fn far_keys_and_huge_keyed_gains_are_refused_and_checked_keys_interpolate_exactly() {
        let far = 1_i64 << 62;
        let mut t = Timeline::default();
        t.light_deg.set(-far, [0.0, 0.0]);
        t.light_deg.set(far, [10.0, 0.0]);
        let (field, reason) = t.check().unwrap_err();
        assert_eq!(field, "timeline.light_deg");
        assert!(reason.contains("beyond"), "{reason}");
        // At the bound the keys are accepted and the light stays between them.
        let mut t = Timeline::default();
        t.light_deg.set(-MAX_KEY_FRAME, [0.0, 0.0]);
        t.light_deg.set(MAX_KEY_FRAME, [10.0, 0.0]);
        t.check().unwrap();
        for how in [Interpolation::Linear, Interpolation::Smooth] {
            let v = t.light_deg.value_at(0.0, how).unwrap();
            assert!((v[0] - 5.0).abs() < 1e-9, "{v:?}");
        }
        let mut t = Timeline { first_frame: -far, ..Timeline::default() };
        assert_eq!(t.check().unwrap_err().0, "timeline.first_frame");
        t.first_frame = 1;
        t.ghost_gain.entry("2-5".into()).or_default().set(1, 1e39);
        let (field, reason) = t.check().unwrap_err();
        assert_eq!(field, "timeline.ghost_gain");
        assert!(reason.contains("from 0 to 1000000"), "{reason}");
        t.ghost_gain.entry("2-5".into()).or_default().set(1, MAX_GHOST_GAIN);
        t.check().unwrap();
    }

    fn track(keys: &[(i64, f64)]) -> Track<f64> {
        let mut t = Track::default();
        for &(f, v) in keys {
            t.set(f, v);
        }
        t
    }

    #[test]
    fn linear_and_smooth_pass_through_the_keys_and_hold_outside() {
        let t = track(&[(10, 1.0), (20, 3.0), (30, 2.0)]);
        for how in [Interpolation::Linear, Interpolation::Smooth] {
            assert_eq!(t.value_at(10.0, how), Some(1.0));
            assert_eq!(t.value_at(20.0, how), Some(3.0));
            assert_eq!(t.value_at(30.0, how), Some(2.0));
            assert_eq!(t.value_at(-5.0, how), Some(1.0));
            assert_eq!(t.value_at(99.0, how), Some(2.0));
        }
        assert_eq!(t.value_at(15.0, Interpolation::Linear), Some(2.0));
        assert!(Track::<f64>::default().value_at(3.0, Interpolation::Smooth).is_none());
    }

    #[test]
    fn smooth_is_exact_on_a_straight_line_and_has_no_corner_at_a_key() {
        // Evenly spaced keys on a line: Catmull-Rom reproduces the line.
        let t = track(&[(0, 0.0), (10, 5.0), (20, 10.0), (30, 15.0)]);
        for f in 0..=30 {
            let v = t.value_at(f64::from(f), Interpolation::Smooth).unwrap();
            assert!((v - 0.5 * f64::from(f)).abs() < 1e-12, "frame {f}: {v}");
        }
        // The slope on both sides of an inner key agrees (C1).
        let t = track(&[(0, 0.0), (10, 4.0), (25, 1.0)]);
        let d = 1e-6;
        let left = (t.value_at(10.0, Interpolation::Smooth).unwrap()
            - t.value_at(10.0 - d, Interpolation::Smooth).unwrap())
            / d;
        let right = (t.value_at(10.0 + d, Interpolation::Smooth).unwrap()
            - t.value_at(10.0, Interpolation::Smooth).unwrap())
            / d;
        assert!((left - right).abs() < 1e-4, "{left} vs {right}");
    }

    #[test]
    fn keys_are_set_replaced_and_deleted_by_frame() {
        let mut tl = Timeline::default();
        tl.light_deg.set(5, [1.0, 2.0]);
        tl.light_deg.set(1, [0.0, 0.0]);
        tl.light_deg.set(5, [3.0, 2.0]);
        tl.light_ev.set(7, -1.0);
        tl.ghost_gain.entry("2-5".into()).or_default().set(5, 0.5);
        assert_eq!(tl.light_deg.keys.len(), 2);
        assert_eq!(tl.light_deg.key_at(5).unwrap().value, [3.0, 2.0]);
        assert_eq!(tl.key_frames(), vec![1, 5, 7]);
        assert!(tl.delete_keys_at(5));
        assert!(!tl.has_key_at(5));
        assert!(tl.ghost_gain.is_empty());
        assert_eq!(tl.key_frames(), vec![1, 7]);
        assert!(tl.check().is_ok());
    }

    #[test]
    fn a_bad_timeline_names_its_field() {
        let tl = Timeline { last_frame: 0, first_frame: 5, ..Timeline::default() };
        assert_eq!(tl.check().unwrap_err().0, "timeline.last_frame");
        let tl = Timeline { fps: 0.0, ..Timeline::default() };
        assert_eq!(tl.check().unwrap_err().0, "timeline.fps");
        let mut tl = Timeline::default();
        tl.light_deg.keys = vec![Key { frame: 3, value: [0.0, 0.0] }, Key { frame: 2, value: [1.0, 0.0] }];
        let (field, reason) = tl.check().unwrap_err();
        assert_eq!(field, "timeline.light_deg");
        assert!(reason.contains("frame 2 follows frame 3"), "{reason}");
        let mut tl = Timeline::default();
        tl.light_deg.set(1, [95.0, 0.0]);
        assert!(tl.check().is_err());
    }
}
