//! Photo LUTs: a real flare photographed (or filmed) against black while the light sweeps over theta, one image
//! per angle, played back as a 1D LUT (the patent's second kind of LUT).
//!
//! # How it works
//! [`import_folder`] reads a folder of PNG (sRGB, linearised) or EXR (linear) images. Each image's angle comes
//! from `flare.json` in the folder (`{"azimuth_deg": A, "images": [{"file": "x.png", "theta_deg": 5.0}, ...]}`)
//! or, without it, from the first number in its file name (`flare_12.5deg.png`). Every image is one whole frame
//! whose centre is the optical axis and whose width maps to the 36 mm sensor width; `azimuth_deg` (default 0:
//! the light moved to the right of the frame) is the direction of the sweep, so at run time the image turns
//! about the axis by the live light's azimuth minus it. Images wider or taller than 2046 pixels are
//! downscaled to fit an atlas page. The LUT has one pseudo-ghost (`super::PHOTO_GHOST`) whose entries are the
//! images; alpha is the coverage, luminance over 5% of the brightest texel of its image.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::{GhostLut, LutEntry, LutGhost, LutKind, PHOTO_GHOST, Symmetry};
use crate::ghost::ParaxialFrame;

/// Largest image side kept (an atlas page less its border).
pub(crate) const MAX_PHOTO_SIDE: u32 = super::blend::ATLAS_PAGE - 2;

/// Why a photo folder cannot be imported.
#[derive(Debug, thiserror::Error)]
pub enum PhotoError {
    #[error("{path}: {message}")]
    File { path: PathBuf, message: String },
    #[error("{0}: no PNG or EXR images")]
    Empty(PathBuf),
    #[error("{path}: no angle: name it with the angle (`flare_12.5deg.png`) or list it in flare.json")]
    NoAngle { path: PathBuf },
    #[error("two images at theta {0} deg")]
    Duplicate(f64),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Sidecar {
    #[serde(default)]
    azimuth_deg: f64,
    images: Vec<SidecarImage>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SidecarImage {
    file: String,
    theta_deg: f64,
}

/// The most photos one photo LUT is made of (each is decoded; a sidecar may list any number).
pub(crate) const MAX_PHOTOS: usize = 1024;

/// The first decimal number in a file name (`flare_12.5deg.png` -> 12.5).
pub(crate) fn angle_from_name(name: &str) -> Option<f64> {
    let start = name.find(|c: char| c.is_ascii_digit())?;
    let text: String = name[start..].chars().take_while(|c| c.is_ascii_digit() || *c == '.').collect();
    text.trim_end_matches('.').parse().ok()
}

/// One image as linear RGB (PNG decoded from sRGB), downscaled to [`MAX_PHOTO_SIDE`].
fn load_linear(path: &Path) -> Result<image::Rgb32FImage, PhotoError> {
    let err = |message: String| PhotoError::File { path: path.to_owned(), message };
    let decoded = crate::output::open_image(path, "flare photo").map_err(err)?;
    let exr = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    let mut rgb = decoded.to_rgb32f();
    if !exr {
        for p in rgb.pixels_mut() {
            p.0 = p.0.map(crate::color::srgb_decode);
        }
    }
    let (w, h) = rgb.dimensions();
    let (nw, nh) = kept_size(w, h);
    if (nw, nh) != (w, h) {
        rgb = image::imageops::resize(&rgb, nw, nh, image::imageops::FilterType::Triangle);
    }
    Ok(rgb)
}

/// The size a photo of `w` x `h` is kept at: downscaled to fit [`MAX_PHOTO_SIDE`].
fn kept_size(w: u32, h: u32) -> (u32, u32) {
    if w.max(h) <= MAX_PHOTO_SIDE {
        return (w, h);
    }
    let k = f64::from(MAX_PHOTO_SIDE) / f64::from(w.max(h));
    (((f64::from(w) * k).round() as u32).max(1), ((f64::from(h) * k).round() as u32).max(1))
}

/// Imports a folder of swept flare images as a photo LUT.
pub fn import_folder(folder: &Path) -> Result<GhostLut, PhotoError> {
    let err = |path: &Path, message: String| PhotoError::File { path: path.to_owned(), message };
    let sidecar_path = folder.join("flare.json");
    let (azimuth_deg, mut images): (f64, Vec<(f64, PathBuf)>) = if sidecar_path.exists() {
        let text = crate::files::read_text_bounded(&sidecar_path, crate::files::MAX_TEXT_BYTES)
            .map_err(|e| err(&sidecar_path, e))?;
        let sidecar: Sidecar =
            serde_json::from_str(&text).map_err(|e| err(&sidecar_path, crate::files::one_line(&e.to_string())))?;
        if !sidecar.azimuth_deg.is_finite() {
            return Err(err(&sidecar_path, "azimuth_deg must be finite".into()));
        }
        (sidecar.azimuth_deg, sidecar.images.into_iter().map(|i| (i.theta_deg, folder.join(i.file))).collect())
    } else {
        let mut found = Vec::new();
        let listing = std::fs::read_dir(folder).map_err(|e| err(folder, e.to_string()))?;
        for item in listing {
            let path = item.map_err(|e| err(folder, e.to_string()))?.path();
            let image = path
                .extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| e.eq_ignore_ascii_case("png") || e.eq_ignore_ascii_case("exr"));
            if !image {
                continue;
            }
            let name = path.file_stem().and_then(|s| s.to_str()).unwrap_or_default().to_owned();
            let theta = angle_from_name(&name).ok_or_else(|| PhotoError::NoAngle { path: path.clone() })?;
            found.push((theta, path));
        }
        (0.0, found)
    };
    if images.is_empty() {
        return Err(PhotoError::Empty(folder.to_owned()));
    }
    if images.len() > MAX_PHOTOS {
        return Err(err(
            folder,
            format!("{} photos; a photo LUT takes at most {MAX_PHOTOS} (one a light angle)", images.len()),
        ));
    }
    for (theta, path) in &images {
        if !(theta.is_finite() && (0.0..=89.0).contains(theta)) {
            return Err(err(path, format!("theta {theta} deg: 0 to 89")));
        }
    }
    images.sort_by(|a, b| a.0.total_cmp(&b.0));
    if let Some(w) = images.windows(2).find(|w| w[0].0 == w[1].0) {
        return Err(PhotoError::Duplicate(w[0].0));
    }
    // The texels every photo will keep, from the headers alone, before any is decoded: a LUT holds at most
    // `MAX_TEXELS` (the reader's bound; 2 GiB of half floats while they are made). Issue 61: 200 photos of
    // 2046x2046 aborted at 5.7 GB, and 70 made a file the reader refused.
    let mut texels: u64 = 0;
    for (_, path) in &images {
        let (w, h) = crate::output::image_size(path, "flare photo").map_err(|e| err(path, e))?;
        let (w, h) = kept_size(w, h);
        texels += u64::from(w) * u64::from(h);
    }
    if texels > super::format::MAX_TEXELS {
        return Err(err(
            folder,
            format!(
                "{} photos make {texels} texels, more than the {} a LUT holds: use fewer or smaller photos",
                images.len(),
                super::format::MAX_TEXELS
            ),
        ));
    }
    let mut entries = Vec::with_capacity(images.len());
    for (theta, path) in &images {
        let rgb = load_linear(path)?;
        let (width, height) = rgb.dimensions();
        let texels = super::texels_with_coverage(rgb.pixels().map(|p| p.0));
        entries.push(LutEntry {
            theta_deg: *theta,
            phi_deg: 0.0,
            paraxial: ParaxialFrame { centre_mm: [0.0; 2], half_mm: 1.0, energy: 0.0 },
            centre_mm: [0.0; 2],
            texel_mm: 36.0 / f64::from(width),
            width,
            height,
            texels,
        });
    }
    let thetas_deg: Vec<f64> = images.iter().map(|i| i.0).collect();
    Ok(GhostLut {
        kind: LutKind::Photo,
        lens_id: folder.file_name().and_then(|n| n.to_str()).unwrap_or("photo").to_owned(),
        lens_fingerprint: 0,
        fingerprint_scheme: crate::fingerprint::SCHEME,
        wavelengths_nm: vec![650.0, 510.0, 475.0],
        f_number: 0.0,
        // The light at frame azimuth A has slopes at azimuth A + 180 degrees.
        symmetry: Symmetry { order: 0, axis_deg: (azimuth_deg + 180.0).rem_euclid(360.0) },
        theta_max_deg: *thetas_deg.last().expect("at least one image"),
        ghosts: vec![LutGhost {
            ghost: PHOTO_GHOST,
            surfaces: [0, 0],
            key: 0,
            thetas_deg,
            // Whole frames are never fitted.
            fitted: Vec::new(),
            phis_deg: vec![0.0],
            entries,
        }],
    })
}
