//! Whether a LUT belongs to a lens: the fingerprint of everything a ray-traced LUT depends on, and the check
//! that refuses a LUT baked for another lens, other settings or ghosts the lens does not have.
//!
//! # How it works
//! [`lut_fingerprint`] hashes ([`crate::fingerprint::of`]) the lens without its inert surfaces, the spectrum,
//! the stop and any coating override, and the curves of the catalogue glasses it names. A bake writes it into
//! the LUT; [`GhostLut::check_for`] recomputes it for the live lens and compares, then checks every ghost the
//! LUT names against the lens's ghost list. A photographed flare's LUT (no lens) always fits.

use crate::flare::FlareConfig;
use crate::lut::format::LutError;
use crate::lut::{GhostLut, LutKind, PHOTO_GHOST};
use crate::optics::Lens;

/// A stable fingerprint of everything a ray-traced LUT depends on: the lens (every surface, glass, coating,
/// aperture and the sensor distance), the spectrum, the stop's shape and f-number and any coating override.
/// A LUT whose fingerprint differs from the live lens's is refused on load.
/// It is a [`crate::fingerprint::of`] (canonical JSON, scheme `crate::fingerprint::SCHEME`).
///
/// A medium named as a catalogue glass takes its curve from the catalogue, which `--catalog` can replace, so
/// its indices at the spectrum's wavelengths are part of the fingerprint too; a lens with no such medium keeps
/// the fingerprint it had before this was added (its LUTs stay valid).
pub fn lut_fingerprint(lens: &Lens, config: &FlareConfig) -> u64 {
    // Inert surfaces (a dummy "+" adds) change no optics: the fingerprint is the lens's without them.
    fingerprint_without_inert(lens.without_inert().0.as_ref(), config)
}

/// [`lut_fingerprint`] of a lens already without its inert surfaces ([`Lens::without_inert`]).
fn fingerprint_without_inert(lens: &Lens, config: &FlareConfig) -> u64 {
    let wavelengths = &config.spectrum.wavelengths_nm;
    let base = (&lens.surfaces, wavelengths, &config.spectrum.weights_rgb, &config.aperture, &config.coating_override);
    let curves: Vec<(usize, Vec<f64>)> = lens
        .surfaces
        .iter()
        .enumerate()
        .filter_map(|(k, s)| {
            let d = s.medium.dispersion();
            matches!(d, crate::optics::glass::Dispersion::Sellmeier { .. })
                .then(|| (k, wavelengths.iter().map(|&w| d.index_at(w)).collect()))
        })
        .collect();
    if curves.is_empty() { crate::fingerprint::of(&base) } else { crate::fingerprint::of(&(base, curves)) }
}

impl GhostLut {
    /// Refuses a ray-traced LUT baked for another lens or other settings than `lens` with `config`.
    pub fn check_for(&self, lens: &Lens, config: &FlareConfig) -> Result<(), LutError> {
        if self.kind == LutKind::Photo {
            return Ok(());
        }
        if self.fingerprint_scheme != crate::fingerprint::SCHEME {
            return Err(LutError::OldFingerprint { lut_lens: self.lens_id.clone() });
        }
        let (canonical, kept) = lens.without_inert();
        let live = fingerprint_without_inert(&canonical, config);
        if live != self.lens_fingerprint {
            return Err(LutError::OtherLens {
                lut_lens: self.lens_id.clone(),
                lut: self.lens_fingerprint,
                lens: lens.id.clone(),
                live,
            });
        }
        // Every ghost it names must be one of this lens's, with the same two surfaces: the fingerprint covers
        // the optics, not the indices a damaged or forged file carries (they index the live ghost list). Inert
        // surfaces reflect nothing, so the ghost list is the same with or without them; a bake names a ghost's
        // surfaces as the lens without them numbers them (`bake`), so its LUT holds for the lens with or
        // without a dummy surface (a LUT from before that named them as its lens did is taken as it was).
        let pairs = lens.ghost_pairs();
        let canonical_pairs = canonical.ghost_pairs();
        let as_numbered = |(a, b): (usize, usize)| (kept.get(a).copied(), kept.get(b).copied());
        for (entry, g) in self.ghosts.iter().enumerate() {
            if g.ghost == PHOTO_GHOST {
                continue;
            }
            let [i, j] = g.surfaces;
            let same = |(a, b): (usize, usize)| (a as u32, b as u32) == (i, j);
            let reason = match pairs.get(g.ghost as usize) {
                None => format!("it has {} ghosts", pairs.len()),
                Some(&live) if same(live) => continue,
                Some(&live)
                    if canonical_pairs
                        .get(g.ghost as usize)
                        .is_some_and(|&c| same(c) && as_numbered(c) == (Some(live.0), Some(live.1))) =>
                {
                    continue;
                }
                Some(&(a, b)) => format!("its ghost {} is {a}-{b}", g.ghost),
            };
            return Err(LutError::NoSuchGhost { entry, ghost: g.ghost, i, j, lens: lens.id.clone(), reason });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A LUT of a lens that names a catalogue glass is refused once another catalogue file replaces that glass.
    #[test]
    fn a_replaced_catalogue_glass_changes_the_lut_fingerprint() {
        let glass = |k: &str| {
            format!(
                "NM FP-G1 2 517642 1.5168 64.17 0 1\nCD {k} 0.00600069867 0.231792344 0.0200179144 1.01046945 103.560653 0 0 0 0\n"
            )
        };
        crate::optics::glass::add_catalogue(&glass("1.03961212"), "FPTEST").unwrap();
        let mut lens = crate::optics::library::builtin_lens("pbrt_dgauss_50mm").unwrap();
        let config = FlareConfig::default();
        let unnamed = lut_fingerprint(&lens, &config);
        let k = lens.surfaces.iter().position(|s| !s.medium.is_air()).unwrap();
        lens.surfaces[k].medium.glass = Some("FPTEST:FP-G1".to_owned());
        let before = lut_fingerprint(&lens, &config);
        assert_ne!(before, unnamed);
        assert_eq!(lut_fingerprint(&lens, &config), before, "stable");
        crate::optics::glass::add_catalogue(&glass("1.05"), "FPTEST").unwrap();
        assert_ne!(lut_fingerprint(&lens, &config), before, "the glass's curve changed");
    }
}
