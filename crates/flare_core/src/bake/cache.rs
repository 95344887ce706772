//! The on-disk LUT cache: a lens (with its stop, coatings and spectrum) baked once is never baked again, by the
//! app or the command line.
//!
//! # How it works
//! A cached LUT is an ordinary `.flut` file named by [`LutCache::key`]: a [`crate::fingerprint::of`] the
//! LUT's own fingerprint ([`super::lut_fingerprint`]: every surface, glass, coating, the stop and the
//! spectrum), the [`BakeSettings`] and `CACHE_VERSION`, so a change to any of them is a new entry
//! and never a stale hit. [`LutCache::load`] reads the file through the same checked decoder as any LUT
//! ([`crate::lut::format::read_lut_near`]) and checks it against the live lens ([`GhostLut::check_for`]); a file
//! that fails either (truncated, damaged, another lens's) is never trusted: it is removed and reported as
//! [`Lookup::Rejected`], and the caller bakes again. [`LutCache::store`] writes through a temporary file and
//! a rename, so a crash mid-write leaves no half file under the key.
//!
//! The folder is `$FLARELAB_CACHE_DIR` when set, else `$XDG_CACHE_HOME/flarelab/luts`, else
//! `~/.cache/flarelab/luts`.

use std::path::{Path, PathBuf};

use super::lut_fingerprint;
use crate::bake::BakeSettings;
use crate::flare::FlareConfig;
use crate::lut::GhostLut;
use crate::lut::format::{read_lut_near, write_lut};
use crate::optics::Lens;

/// Bumped when the baker changes what it writes for the same settings: every older entry becomes a miss. 2:
/// every clear aperture cuts the paraxial sprites, so the classification against them (which ghosts a LUT
/// carries) changed. 3: a ghost whose sprite carries the wrong light is non-linear too. 4: ghosts are judged
/// visible at the lens's own auto exposure as well (a dim lens has more of them), and a finer entry is traced on
/// a finer grid.
pub(crate) const CACHE_VERSION: u32 = 4;

/// What a lookup found.
#[derive(Debug)]
pub enum Lookup {
    Hit(Box<GhostLut>),
    Miss,
    /// A file was under the key but could not be trusted (the reason); it has been removed.
    Rejected(String),
}

/// The cache folder.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LutCache {
    pub dir: PathBuf,
}

impl LutCache {
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }

    /// The user's cache folder (see the module documentation); `None` when no home folder is known.
    pub fn user() -> Option<Self> {
        let from_env = |name: &str| std::env::var_os(name).filter(|v| !v.is_empty()).map(PathBuf::from);
        if let Some(dir) = from_env("FLARELAB_CACHE_DIR") {
            return Some(Self::new(dir));
        }
        let base = from_env("XDG_CACHE_HOME").or_else(|| from_env("HOME").map(|h| h.join(".cache")))?;
        Some(Self::new(base.join("flarelab").join("luts")))
    }

    /// The key of the LUT baked with `settings` for `lens` with `config`.
    pub fn key(lens: &Lens, config: &FlareConfig, settings: &BakeSettings) -> u64 {
        crate::fingerprint::of(&(CACHE_VERSION, lut_fingerprint(lens, config), settings))
    }

    /// The file of `key`.
    pub fn path(&self, key: u64) -> PathBuf {
        self.dir.join(format!("{key:016x}.flut"))
    }

    /// The cached LUT of `lens` with `config` baked with `settings`, checked (see the module documentation).
    pub fn load(&self, lens: &Lens, config: &FlareConfig, settings: &BakeSettings) -> Lookup {
        self.load_near(lens, config, settings, None)
    }

    /// [`Self::load`], with only the images drawn at `near_theta_deg` when it is given
    /// ([`crate::lut::format::read_lut_near`]).
    pub fn load_near(
        &self,
        lens: &Lens,
        config: &FlareConfig,
        settings: &BakeSettings,
        near_theta_deg: Option<f64>,
    ) -> Lookup {
        // What a killed bake's write left behind (our temporary files, over an hour old) goes first.
        crate::files::remove_stale_temps(&self.dir, std::time::Duration::from_secs(3600));
        let path = self.path(Self::key(lens, config, settings));
        if !path.exists() {
            return Lookup::Miss;
        }
        let reason = match read_lut_near(&path, near_theta_deg) {
            Ok(lut) => match crate::timing::span("check the LUT against the lens", || lut.check_for(lens, config)) {
                Ok(()) => return Lookup::Hit(Box::new(lut)),
                Err(e) => e.to_string(),
            },
            Err(e) => e.to_string(),
        };
        let removed = match std::fs::remove_file(&path) {
            Ok(()) => "removed".to_owned(),
            Err(e) => format!("could not be removed: {e}"),
        };
        Lookup::Rejected(format!("cached LUT {} ignored ({reason}); {removed}", display(&path)))
    }

    /// Stores `lut`, baked with `settings` for `lens` with `config`; the file written.
    pub fn store(
        &self,
        lens: &Lens,
        config: &FlareConfig,
        settings: &BakeSettings,
        lut: &GhostLut,
    ) -> std::io::Result<PathBuf> {
        std::fs::create_dir_all(&self.dir)?;
        let path = self.path(Self::key(lens, config, settings));
        write_lut(&path, lut)?;
        Ok(path)
    }
}

fn display(path: &Path) -> String {
    path.display().to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bake::bake;
    use crate::flare::PreparedFlare;
    use crate::optics::library::builtin_lens;

    #[test]
    fn a_stored_lut_is_a_hit_and_a_damaged_one_is_removed_never_trusted() {
        let dir = tempfile::tempdir().unwrap();
        let cache = LutCache::new(dir.path().join("luts"));
        let lens = builtin_lens("heliar").unwrap();
        let config = FlareConfig::default();
        // A small real bake: two ghosts, coarse.
        let settings = BakeSettings { res: 16, grid: 8, initial_steps: 2, tolerance: 1.0, ..BakeSettings::default() };
        assert!(matches!(cache.load(&lens, &config, &settings), Lookup::Miss));
        let flare = PreparedFlare::new(&lens, &config).unwrap();
        let lut =
            bake(&flare, &flare.ray_grid_renderer(), &[0, 1], &settings, None, &|_| {}, &Default::default()).unwrap();
        let path = cache.store(&lens, &config, &settings, &lut).unwrap();
        match cache.load(&lens, &config, &settings) {
            Lookup::Hit(hit) => assert_eq!(*hit, lut),
            other => panic!("{other:?}"),
        }
        // Other bake settings are another key.
        assert_ne!(LutCache::key(&lens, &config, &BakeSettings::default()), LutCache::key(&lens, &config, &settings));
        // Another stop is another key: a miss, not the f/3.4 LUT.
        let mut stopped = config.clone();
        stopped.aperture.f_number = Some(8.0);
        assert_ne!(LutCache::key(&lens, &stopped, &settings), LutCache::key(&lens, &config, &settings));
        assert!(matches!(cache.load(&lens, &stopped, &settings), Lookup::Miss));
        // A damaged file is rejected with the reason, removed, and the next lookup is a miss.
        let mut bytes = std::fs::read(&path).unwrap();
        let n = bytes.len();
        bytes[n / 2] ^= 0x5a;
        std::fs::write(&path, &bytes).unwrap();
        match cache.load(&lens, &config, &settings) {
            Lookup::Rejected(reason) => assert!(reason.contains("ignored") && reason.contains("removed"), "{reason}"),
            other => panic!("{other:?}"),
        }
        assert!(!path.exists());
        assert!(matches!(cache.load(&lens, &config, &settings), Lookup::Miss));
        // A truncated file and another lens's LUT under the key are rejected too.
        std::fs::write(&path, b"FLUT").unwrap();
        assert!(matches!(cache.load(&lens, &config, &settings), Lookup::Rejected(_)));
        let other = builtin_lens("tessar").unwrap();
        cache.store(&lens, &config, &settings, &lut).unwrap();
        std::fs::rename(&path, cache.path(LutCache::key(&other, &config, &settings))).unwrap();
        assert!(matches!(cache.load(&other, &config, &settings), Lookup::Rejected(r) if r.contains("ignored")));
    }
}
