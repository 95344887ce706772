//! The plates a sequence shows, kept decoded for scrubbing and read ahead while it plays ([`PlateCache`]).
//!
//! # How it works
//! The cache holds the latest [`PLATE_CACHE`] plates by file, as read into the working space (another colour
//! setting empties it). [`PlateCache::prefetch`] reads the next [`PREFETCH`] files of a sequence on interactive
//! jobs' threads ([`super::jobs::job`]), never on rayon's global pool (the UI thread's frame runs there), one
//! read per file at a time; a file that cannot be read is left out, so that reading it when it is shown says
//! why.

use std::sync::Arc;

use flare_core::image::HdrImage;

use super::jobs::job::Job;

/// Plates kept decoded for scrubbing.
pub const PLATE_CACHE: usize = 6;
/// Frames of a plate sequence read ahead of the playhead.
pub const PREFETCH: i64 = 2;

/// A decoded plate and its file.
type NamedPlate = (String, Arc<HdrImage>);

/// Decoded plates by file, the latest [`PLATE_CACHE`] kept; [`Self::prefetch`] reads files on the jobs'
/// threads into it (a file that cannot be read is left out: reading it in turn reports why).
#[derive(Default)]
pub struct PlateCache {
    plates: Arc<std::sync::Mutex<Vec<NamedPlate>>>,
    loading: Arc<std::sync::Mutex<std::collections::BTreeSet<String>>>,
    /// The reads under way: watched until their threads end (at most [`PREFETCH`] per frame shown, and never
    /// two of one file).
    reads: Vec<Job<()>>,
    /// How the cached plates were read into the working space (the document's colour settings when it names
    /// an input space); another way empties the cache.
    color: Option<flare_core::view_transform::ColorDoc>,
}

impl PlateCache {
    /// The decoded plate of `path`, if it is kept.
    pub fn get(&self, path: &str) -> Option<Arc<HdrImage>> {
        let plates = self.plates.lock().ok()?;
        plates.iter().find(|(p, _)| p == path).map(|(_, img)| img.clone())
    }

    /// Keeps `plate` as `path`'s (the oldest plate goes when [`PLATE_CACHE`] are kept).
    pub fn put(&self, path: String, plate: Arc<HdrImage>) {
        Self::put_into(&self.plates, path, plate);
    }

    fn put_into(plates: &std::sync::Mutex<Vec<NamedPlate>>, path: String, plate: Arc<HdrImage>) {
        if let Ok(mut plates) = plates.lock() {
            plates.retain(|(p, _)| *p != path);
            plates.push((path, plate));
            let excess = plates.len().saturating_sub(PLATE_CACHE);
            plates.drain(..excess);
        }
    }

    /// Empties the cache when the plates are now read another way (`color`: see the field).
    pub fn read_as(&mut self, color: Option<flare_core::view_transform::ColorDoc>) -> bool {
        if self.color == color {
            return false;
        }
        self.color = color;
        if let Ok(mut plates) = self.plates.lock() {
            plates.clear();
        }
        true
    }

    /// Reads `paths` ahead (see the module documentation).
    pub fn prefetch(&mut self, paths: &[String]) {
        self.reads.retain(|read| !read.ended());
        for path in paths {
            let fresh = self.get(path).is_none() && self.loading.lock().is_ok_and(|mut l| l.insert(path.clone()));
            if !fresh {
                continue;
            }
            let (plates, loading, path) = (self.plates.clone(), self.loading.clone(), path.clone());
            let color = self.color.clone().unwrap_or_default();
            // An interactive job: never on rayon's global pool, which the UI thread's frame uses.
            self.reads.push(Job::spawn("reading a plate ahead", move |_, _| {
                if let Ok((plate, _)) = flare_core::shot::plate::read_plate_in(&color, std::path::Path::new(&path)) {
                    Self::put_into(&plates, path.clone(), Arc::new(plate));
                }
                if let Ok(mut l) = loading.lock() {
                    l.remove(&path);
                }
            }));
        }
    }
}
