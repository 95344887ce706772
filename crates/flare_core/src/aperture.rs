//! The aperture: the shape of the stop's opening, rasterised into the mask every ghost sprite is textured with.
//!
//! # How it works
//! An [`Aperture`] is a circle, N blades (3 to [`MAX_BLADES`]) with a rotation and a roundness (0 = straight blades,
//! 1 = a circle; between, the blades bow outwards as curved blades do), or any grayscale image. Its size is
//! set by the f-number: the lens's own (widest) f-number opens the stop fully, a larger one shrinks the stop
//! radius in proportion (`scale = nominal / chosen`, never above 1).
//! [`Aperture::rasterise`] draws it into an n x n mask covering [-1, 1]^2, where radius 1 is the stop's
//! semi-aperture at this f-number. Edges are anti-aliased analytically: each texel takes the coverage
//! `clamp(0.5 + d / texel, 0, 1)` of its signed distance d to the edge along the radius. A polygon of unit
//! circumradius has the edge distance `r(phi) = cos(pi / N) / cos(((phi - rotation) mod 2 pi / N) - pi / N)`;
//! roundness mixes it towards the circle, `r = r_poly + roundness (1 - r_poly)`.

use std::f64::consts::PI;

use rayon::prelude::*;

/// The most blades a stop may have, for every command, file and panel alike.
pub const MAX_BLADES: u32 = 32;

/// The largest f-number a stop may be set to, for every command, file and panel alike: a pinhole camera's
/// f/200 to f/500 is within; beyond it the stop's radius underflows what the tracer resolves (issue 61: `bake
/// --f-number 1e300` was accepted and baked for minutes).
pub(crate) const MAX_F_NUMBER: f64 = 1024.0;

/// The largest edge radius the raster draws (a stop touching [-1, 1]^2's sides would be cut by its square).
const EDGE_LIMIT: f64 = 0.999;

/// Default mask resolution (texels across).
pub const DEFAULT_MASK_SIZE: usize = 256;

/// The shape of the stop.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub enum ApertureShape {
    Circle,
    Blades {
        count: u32,
        rotation_deg: f64,
        roundness: f64,
    },
    /// A user image: row-major luminance in [0, 1], `size` x `size`, covering [-1, 1]^2.
    Image {
        size: usize,
        luminance: Vec<f32>,
    },
}

/// The aperture: shape and f-number.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Aperture {
    pub shape: ApertureShape,
    /// The f-number the user chose; `None` keeps the lens wide open.
    pub f_number: Option<f64>,
}

impl Default for Aperture {
    fn default() -> Self {
        Self { shape: ApertureShape::Blades { count: 6, rotation_deg: 0.0, roundness: 0.0 }, f_number: None }
    }
}

/// Why an aperture is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ApertureError {
    #[error("{0} blades: between 3 and {MAX_BLADES}")]
    BladeCount(u32),
    #[error("roundness {0} is outside [0, 1]")]
    Roundness(f64),
    #[error("f-number {0} must be finite and positive")]
    FNumber(f64),
    #[error("rotation {0} is not finite")]
    Rotation(f64),
    #[error("aperture image: {0}")]
    Image(String),
}

/// A blade stop's edges, for [`Aperture::rasterise`]'s quick test ([`Aperture::blade_edges`]).
struct BladeEdges {
    normals: Vec<(f64, f64)>,
    inscribed: f64,
    roundness: f64,
}

/// A rasterised mask: `size` x `size` texels over [-1, 1]^2, row 0 at y = +1.
#[derive(Clone, Debug, PartialEq)]
pub struct ApertureMask {
    pub size: usize,
    pub texels: Vec<u8>,
}

impl ApertureMask {
    /// Bilinear sample at (u, v) in [-1, 1]^2 (0 outside), the way a GPU samples the texture.
    #[inline(always)]
    pub fn sample(&self, u: f32, v: f32) -> f32 {
        if !(-1.0..=1.0).contains(&u) || !(-1.0..=1.0).contains(&v) {
            return 0.0;
        }
        let n = self.size as f32;
        // Texel centres at (i + 0.5) / n in texture coordinates; v = +1 is row 0.
        let x = (u * 0.5 + 0.5) * n - 0.5;
        let y = (0.5 - v * 0.5) * n - 0.5;
        // x, y >= -0.5, so truncating x + 1 floors x (without a call to libm's floorf on baseline x86-64).
        let (x0, y0) = ((x + 1.0) as i32 - 1, (y + 1.0) as i32 - 1);
        let (fx, fy) = (x - x0 as f32, y - y0 as f32);
        let last = self.size as i32 - 1;
        let texel = |i: i32, j: i32| {
            let (i, j) = (i.clamp(0, last) as usize, j.clamp(0, last) as usize);
            f32::from(self.texels[j * self.size + i])
        };
        let top = texel(x0, y0) * (1.0 - fx) + texel(x0 + 1, y0) * fx;
        let bottom = texel(x0, y0 + 1) * (1.0 - fx) + texel(x0 + 1, y0 + 1) * fx;
        (top * (1.0 - fy) + bottom * fy) / 255.0
    }

    /// Each bilinear footprint's four texels in one word, for the GPU passes that read the mask from a storage
    /// buffer (a software rasteriser loads a storage word lane by lane, so one load a lookup instead of four
    /// took the Nikon zoom's 480x320 paraxial frame on lavapipe from 300 to ~200 ms): the word of the footprint
    /// whose top-left texel is (x0, y0), for x0 and y0 in -1..size, is at `(y0 + 1) (size + 1) + x0 + 1` and holds
    /// texels (x0, y0), (x0 + 1, y0), (x0, y0 + 1), (x0 + 1, y0 + 1), clamped to the edge as [`Self::sample`]
    /// clamps them, in its bytes from the lowest.
    pub fn quad_words(&self) -> Vec<u32> {
        let (n, last) = (self.size as i32, self.size as i32 - 1);
        let texel = |i: i32, j: i32| self.texels[(j.clamp(0, last) * n + i.clamp(0, last)) as usize];
        // Rows of footprints in parallel (the finest mask level has a million), collected in order.
        (-1..n)
            .into_par_iter()
            .flat_map_iter(|y0| {
                (-1..n).map(move |x0| {
                    u32::from_le_bytes([texel(x0, y0), texel(x0 + 1, y0), texel(x0, y0 + 1), texel(x0 + 1, y0 + 1)])
                })
            })
            .collect()
    }

    /// The radius of the nearest texel centre (in [-1, 1]^2 coordinates) whose value passes `nearest_if`, and of
    /// the farthest whose value passes `farthest_if` (`None` where no texel does). Rows go to rayon's threads;
    /// texels are compared by their squared radius in f64 (exact for these f32 coordinates but for the sum's
    /// rounding) and the radius is the winner's `f32::hypot`, the value a scan of every texel's `hypot` finds.
    fn extreme_radii(
        &self,
        nearest_if: impl Fn(u8) -> bool + Sync,
        farthest_if: impl Fn(u8) -> bool + Sync,
    ) -> [Option<f32>; 2] {
        type Best = Option<(f64, f32)>;
        let n = self.size as f32;
        let coordinate = |k: usize| (k as f32 + 0.5) / n * 2.0 - 1.0;
        // The nearer (or farther) of two by squared radius, then by the radius itself.
        let keep = |a: Best, b: Best, nearer: bool| match (a, b) {
            (Some(x), Some(y)) => {
                let y_wins = if nearer { y < x } else { y > x };
                Some(if y_wins { y } else { x })
            }
            (x, None) | (None, x) => x,
        };
        let (near, far) = self
            .texels
            .par_chunks(self.size.max(1))
            .enumerate()
            .map(|(j, row)| {
                let v = 1.0 - (j as f32 + 0.5) / n * 2.0;
                // Along one row equal squared radii are equal |u|, so the radius is worked out once a row.
                let (mut near, mut far) = ((f64::INFINITY, 0.0f32), (f64::NEG_INFINITY, 0.0f32));
                for (i, &t) in row.iter().enumerate() {
                    let u = coordinate(i);
                    let r2 = f64::from(u).powi(2) + f64::from(v).powi(2);
                    if nearest_if(t) && r2 < near.0 {
                        near = (r2, u);
                    }
                    if farthest_if(t) && r2 > far.0 {
                        far = (r2, u);
                    }
                }
                let radius = |(r2, u): (f64, f32)| r2.is_finite().then(|| (r2, u.hypot(v)));
                (radius(near), radius(far))
            })
            .reduce(|| (None, None), |a, b| (keep(a.0, b.0, true), keep(a.1, b.1, false)));
        [near.map(|b| b.1), far.map(|b| b.1)]
    }

    /// How far a bilinear sample reads: the texel diagonal, in [-1, 1]^2 coordinates.
    fn sample_reach(&self) -> f32 {
        2.0 * std::f32::consts::SQRT_2 / self.size as f32
    }

    /// The radius within which [`Self::sample`] is fully open (every texel it can read is 255): the nearest
    /// centre of a texel below 255, less the reach of a bilinear sample (the texel diagonal). 0 when none.
    pub fn open_radius(&self) -> f32 {
        let [nearest, _] = self.extreme_radii(|t| t < 255, |_| false);
        // Beyond [-1, 1]^2 the mask is 0: the open disc never reaches past radius 1.
        (nearest.unwrap_or(f32::INFINITY).min(1.0) - self.sample_reach()).max(0.0)
    }

    /// The radius beyond which [`Self::sample`] is 0 (every texel it can read is 0): the farthest centre of a
    /// texel above 0, plus the reach of a bilinear sample (the texel diagonal). 0 for a closed mask.
    pub fn support_radius(&self) -> f32 {
        let [_, farthest] = self.extreme_radii(|_| false, |t| t > 0);
        farthest.map_or(0.0, |r| r + self.sample_reach())
    }

    /// Fraction of the [-1, 1]^2 square that is open (a unit circle is pi / 4).
    pub fn open_fraction(&self) -> f64 {
        self.texels.iter().map(|&t| t as f64 / 255.0).sum::<f64>() / self.texels.len() as f64
    }
}

impl Aperture {
    pub fn validate(&self) -> Result<(), ApertureError> {
        if let Some(f) = self.f_number
            && !(f.is_finite() && f > 0.0)
        {
            return Err(ApertureError::FNumber(f));
        }
        match &self.shape {
            ApertureShape::Circle => Ok(()),
            ApertureShape::Blades { count, rotation_deg, roundness } => {
                if !(3..=MAX_BLADES).contains(count) {
                    return Err(ApertureError::BladeCount(*count));
                }
                if !rotation_deg.is_finite() {
                    return Err(ApertureError::Rotation(*rotation_deg));
                }
                if !(0.0..=1.0).contains(roundness) {
                    return Err(ApertureError::Roundness(*roundness));
                }
                Ok(())
            }
            ApertureShape::Image { size, luminance } => {
                if *size < 2 || luminance.len() != size * size {
                    return Err(ApertureError::Image(format!(
                        "{} values for a {size} x {size} image",
                        luminance.len()
                    )));
                }
                if luminance.iter().any(|v| !v.is_finite()) {
                    return Err(ApertureError::Image("non-finite values".into()));
                }
                Ok(())
            }
        }
    }

    /// Stop radius relative to wide open, for a lens whose widest f-number is `nominal_f_number`.
    pub fn stop_scale(&self, nominal_f_number: f64) -> f64 {
        match self.f_number {
            Some(f) if f.is_finite() && f > 0.0 => (nominal_f_number / f).clamp(1e-3, 1.0),
            _ => 1.0,
        }
    }

    /// Loads a grayscale aperture image (PNG, EXR or HDR, 1 to [`crate::output::MAX_IMAGE_SIDE_PX`] pixels a
    /// side), resampled to `size`. An image with no light in it (black everywhere) is refused: it would draw
    /// no flare at all.
    pub fn image_shape_from_file(path: &std::path::Path, size: usize) -> Result<ApertureShape, ApertureError> {
        let luminance = crate::output::read_grey_square(path, "aperture image", size).map_err(ApertureError::Image)?;
        if luminance.iter().all(|&v| v < 1.0 / 255.0) {
            return Err(ApertureError::Image(format!(
                "{}: the aperture image is black everywhere: no light would pass (white is open, black is blade)",
                path.display()
            )));
        }
        Ok(ApertureShape::Image { size, luminance })
    }

    /// The edge radius in direction `phi` (radians), in units of the circumradius.
    pub fn edge_radius(&self, phi: f64) -> f64 {
        match &self.shape {
            ApertureShape::Blades { count, rotation_deg, roundness } => {
                let n = *count as f64;
                let sector = 2.0 * PI / n;
                let local = (phi - rotation_deg.to_radians()).rem_euclid(sector) - sector / 2.0;
                let polygon = (PI / n).cos() / local.cos();
                polygon + roundness * (1.0 - polygon)
            }
            _ => 1.0,
        }
    }

    /// The least edge radius over every direction ([`Self::edge_radius`], capped as the raster caps it): the
    /// inscribed circle's radius of a polygon, mixed towards 1 by the roundness.
    fn inner_radius(&self) -> f64 {
        let radius = match &self.shape {
            ApertureShape::Blades { count, roundness, .. } => {
                let polygon = (PI / f64::from(*count)).cos();
                polygon + roundness * (1.0 - polygon)
            }
            _ => 1.0,
        };
        radius.min(EDGE_LIMIT)
    }

    /// What the raster's quick test needs of a blade stop: its edges' unit normals (x, y), edge `k`'s pointing
    /// at `rotation + (k + 1/2) 2 pi / N`, the middle of the sector [`Self::edge_radius`] measures `local` from;
    /// the inscribed radius `cos(pi / N)` of the unit polygon; and the roundness. `None` for a circle or an
    /// image.
    fn blade_edges(&self) -> Option<BladeEdges> {
        let ApertureShape::Blades { count, rotation_deg, roundness } = &self.shape else { return None };
        let sector = 2.0 * PI / f64::from(*count);
        let normals = (0..*count)
            .map(|k| {
                let angle = rotation_deg.to_radians() + (f64::from(k) + 0.5) * sector;
                (angle.cos(), angle.sin())
            })
            .collect();
        Some(BladeEdges { normals, inscribed: (PI / f64::from(*count)).cos(), roundness: *roundness })
    }

    /// The edge radius at (u, v), `r` from the centre, without the angle: the nearest edge's normal has the
    /// largest dot product `d` with the point, `d = r cos(local)`, so the polygon's radius
    /// `cos(pi / N) / cos(local)` is `cos(pi / N) r / d`. Equal to [`Self::edge_radius`] up to rounding (about
    /// 1e-15); `None` at the centre, or for an image.
    fn edge_radius_at(&self, u: f64, v: f64, r: f64, blades: Option<&BladeEdges>) -> Option<f64> {
        match (&self.shape, blades) {
            (ApertureShape::Circle, _) => Some(1.0),
            (ApertureShape::Blades { .. }, Some(b)) => {
                let d = b.normals.iter().map(|&(x, y)| u * x + v * y).fold(f64::NEG_INFINITY, f64::max);
                (d > 0.0).then(|| {
                    let polygon = b.inscribed * r / d;
                    polygon + b.roundness * (1.0 - polygon)
                })
            }
            _ => None,
        }
    }

    /// Rasterises the shape into a `size` x `size` mask.
    ///
    /// Each texel of a blade or round stop takes the coverage formula of the module documentation, with the
    /// angle's edge radius ([`Self::edge_radius`]). Most texels are 0 or 1 and need no angle: those a whole
    /// texel inside the inscribed circle or beyond the circumradius are decided by their squared radius, and
    /// the rest first by the edge radius found without the angle (`edge_radius_at`), which differs
    /// from the angle's by rounding only; a texel is given 0 or 1 from it only when its coverage there is a
    /// millionth of a texel clear of (0, 1), so every texel gets the formula's byte (a test checks each).
    pub fn rasterise(&self, size: usize) -> ApertureMask {
        let size = size.max(2);
        let texel = 2.0 / size as f64;
        let inner = self.inner_radius();
        // Squared radii within which a texel is 1 and beyond which it is 0 (none within when the inscribed
        // circle is under a texel).
        let inside2 = if inner > texel { (inner - texel).powi(2) } else { -1.0 };
        let outside2 = (EDGE_LIMIT + texel).powi(2);
        let blades = self.blade_edges();
        let byte = |coverage: f64| (coverage * 255.0).round() as u8;
        let formula = |edge: f64, r: f64| byte((0.5 + (edge.min(EDGE_LIMIT) - r) / texel).clamp(0.0, 1.0));
        const CLEAR: f64 = 1e-6;
        let mut texels = vec![0u8; size * size];
        // Rows in parallel (the ghost passes' finest level is 1024^2 texels).
        texels.par_chunks_mut(size).enumerate().for_each(|(j, row)| {
            for (i, out) in row.iter_mut().enumerate() {
                let u = -1.0 + texel * (i as f64 + 0.5);
                let v = 1.0 - texel * (j as f64 + 0.5);
                *out = match &self.shape {
                    ApertureShape::Image { size: n, luminance } => {
                        let x = ((i as f64 + 0.5) / size as f64 * *n as f64) as usize;
                        let y = ((j as f64 + 0.5) / size as f64 * *n as f64) as usize;
                        byte(luminance[y.min(n - 1) * n + x.min(n - 1)] as f64)
                    }
                    _ => {
                        let r2 = u * u + v * v;
                        if r2 <= inside2 {
                            255
                        } else if r2 >= outside2 {
                            0
                        } else {
                            let r = r2.sqrt();
                            let quick = self.edge_radius_at(u, v, r, blades.as_ref());
                            match quick.map(|edge| 0.5 + (edge.min(EDGE_LIMIT) - r) / texel) {
                                Some(c) if c >= 1.0 + CLEAR => 255,
                                Some(c) if c <= -CLEAR => 0,
                                _ => formula(self.edge_radius(v.atan2(u)), u.hypot(v)),
                            }
                        }
                    }
                };
            }
        });
        ApertureMask { size, texels }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn circle_and_polygons_have_the_right_area() {
        let circle = Aperture { shape: ApertureShape::Circle, f_number: None }.rasterise(512);
        assert!((circle.open_fraction() - PI / 4.0 * 0.999f64.powi(2)).abs() < 2e-3, "{}", circle.open_fraction());
        for n in [3u32, 5, 6, 8, 16] {
            let a = Aperture {
                shape: ApertureShape::Blades { count: n, rotation_deg: 10.0, roundness: 0.0 },
                f_number: None,
            };
            let area = a.rasterise(512).open_fraction() * 4.0;
            let exact = 0.5 * n as f64 * (2.0 * PI / n as f64).sin() * 0.999f64.powi(2);
            assert!((area - exact).abs() < 0.01 * exact, "{n} blades: {area} vs {exact}");
        }
        let round =
            Aperture { shape: ApertureShape::Blades { count: 6, rotation_deg: 0.0, roundness: 1.0 }, f_number: None };
        assert!((round.rasterise(256).open_fraction() - circle.open_fraction()).abs() < 3e-3);
    }

    /// The raster's shortcuts (texels well inside the inscribed circle or beyond the circumradius, and texels
    /// decided by the edge radius found without the angle) give the bytes of the edge formula at every texel,
    /// for polygons, rounded blades and the circle, at odd and even sizes up to the finest mask level.
    #[test]
    fn the_raster_shortcuts_give_the_formulas_bytes() {
        let blades = |count, rotation_deg, roundness| ApertureShape::Blades { count, rotation_deg, roundness };
        let shapes = [
            (ApertureShape::Circle, 256),
            (blades(3, 0.0, 0.0), 256),
            (blades(5, -33.3, 0.0), 1024),
            (blades(6, 17.0, 0.4), 1024),
            (blades(7, 200.0, 0.7), 256),
            (blades(32, 5.0, 1.0), 256),
        ];
        for (shape, largest) in shapes {
            let aperture = Aperture { shape, f_number: None };
            for size in [2, 3, 16, 97, largest] {
                let mask = aperture.rasterise(size);
                let texel = 2.0 / size as f64;
                for (k, &t) in mask.texels.iter().enumerate() {
                    let (i, j) = ((k % size) as f64, (k / size) as f64);
                    let (u, v) = (-1.0 + texel * (i + 0.5), 1.0 - texel * (j + 0.5));
                    let edge = aperture.edge_radius(v.atan2(u)).min(EDGE_LIMIT);
                    let coverage = (0.5 + (edge - u.hypot(v)) / texel).clamp(0.0, 1.0);
                    assert_eq!(t, (coverage * 255.0).round() as u8, "{:?} at {size}: texel {k}", aperture.shape);
                }
            }
        }
    }

    /// The open and support radii found row by row in parallel are those of a scan of every texel's radius,
    /// for stops at every mask level, an image, a closed mask and a fully open one.
    #[test]
    fn the_open_and_support_radii_are_the_scans() {
        let scan = |mask: &ApertureMask| {
            let n = mask.size as f32;
            let radii = mask.texels.iter().enumerate().map(|(k, &t)| {
                let (i, j) = ((k % mask.size) as f32, (k / mask.size) as f32);
                (t, ((i + 0.5) / n * 2.0 - 1.0).hypot(1.0 - (j + 0.5) / n * 2.0))
            });
            let nearest = radii.clone().filter(|&(t, _)| t < 255).map(|(_, r)| r).fold(f32::INFINITY, f32::min);
            let farthest = radii.filter(|&(t, _)| t > 0).map(|(_, r)| r).fold(f32::NEG_INFINITY, f32::max);
            let open = (nearest.min(1.0) - mask.sample_reach()).max(0.0);
            let support = if farthest < 0.0 { 0.0 } else { farthest + mask.sample_reach() };
            (open.to_bits(), support.to_bits())
        };
        let blades = |count, rotation_deg, roundness| ApertureShape::Blades { count, rotation_deg, roundness };
        let mut masks: Vec<ApertureMask> = [256, 512, 1024, 97]
            .into_iter()
            .flat_map(|size| {
                [ApertureShape::Circle, blades(6, 0.0, 0.0), blades(7, 13.0, 0.3)]
                    .map(|shape| Aperture { shape, f_number: None }.rasterise(size))
            })
            .collect();
        let luminance = (0..64 * 64).map(|k| ((k * 37) % 101) as f32 / 100.0).collect();
        masks.push(Aperture { shape: ApertureShape::Image { size: 64, luminance }, f_number: None }.rasterise(128));
        masks.push(ApertureMask { size: 8, texels: vec![0; 64] });
        masks.push(ApertureMask { size: 8, texels: vec![255; 64] });
        for mask in &masks {
            assert_eq!(
                (mask.open_radius().to_bits(), mask.support_radius().to_bits()),
                scan(mask),
                "size {}",
                mask.size
            );
        }
    }

    #[test]
    fn sampling_matches_the_shape_and_is_zero_outside() {
        let mask = Aperture::default().rasterise(256);
        assert!((mask.sample(0.0, 0.0) - 1.0).abs() < 1e-6);
        assert_eq!(mask.sample(0.0, 0.99), 0.0, "a hexagon with a vertex on +x has a flat top at 0.866");
        assert!(mask.sample(0.95, 0.0) > 0.99, "vertex direction is open to the circumradius");
        assert_eq!(mask.sample(1.2, 0.0), 0.0);
    }

    /// The GPU passes' lookup from `quad_words` (mask_texels.wgsl's steps, here in Rust) gives `sample`'s value
    /// to the bit everywhere: inside, on the edges and at the corners, where the texels are clamped.
    #[test]
    fn the_quad_words_give_the_samples() {
        let uneven = ApertureMask { size: 5, texels: (0..25u32).map(|k| (k * 37 % 256) as u8).collect() };
        for mask in [uneven, Aperture::default().rasterise(64)] {
            let quads = mask.quad_words();
            let n = mask.size as i32;
            assert_eq!(quads.len(), ((n + 1) * (n + 1)) as usize);
            let lookup = |u: f32, v: f32| {
                if !(-1.0..=1.0).contains(&u) || !(-1.0..=1.0).contains(&v) {
                    return 0.0;
                }
                let x = (u * 0.5 + 0.5) * n as f32 - 0.5;
                let y = (0.5 - v * 0.5) * n as f32 - 0.5;
                let (x0, y0) = ((x + 1.0) as i32 - 1, (y + 1.0) as i32 - 1);
                let (fx, fy) = (x - x0 as f32, y - y0 as f32);
                let at = (y0.clamp(-1, n - 1) + 1) * (n + 1) + x0.clamp(-1, n - 1) + 1;
                let t = quads[at as usize].to_le_bytes().map(f32::from);
                let top = t[0] * (1.0 - fx) + t[1] * fx;
                let bottom = t[2] * (1.0 - fx) + t[3] * fx;
                (top * (1.0 - fy) + bottom * fy) / 255.0
            };
            for j in 0..=300 {
                for i in 0..=300 {
                    let (u, v) = (i as f32 / 150.0 - 1.0, 1.0 - j as f32 / 150.0);
                    assert_eq!(lookup(u, v).to_bits(), mask.sample(u, v).to_bits(), "size {n} at ({u}, {v})");
                }
            }
        }
    }

    #[test]
    fn bad_settings_are_refused_and_f_number_scales_the_stop() {
        let bad =
            Aperture { shape: ApertureShape::Blades { count: 2, rotation_deg: 0.0, roundness: 0.0 }, f_number: None };
        assert_eq!(bad.validate(), Err(ApertureError::BladeCount(2)));
        let bad = Aperture { shape: ApertureShape::Circle, f_number: Some(-2.0) };
        assert!(bad.validate().is_err());
        let a = Aperture { shape: ApertureShape::Circle, f_number: Some(8.0) };
        assert!((a.stop_scale(4.0) - 0.5).abs() < 1e-15);
        assert_eq!(
            Aperture { shape: ApertureShape::Circle, f_number: Some(2.0) }.stop_scale(4.0),
            1.0,
            "cannot open past wide open"
        );
    }
}
