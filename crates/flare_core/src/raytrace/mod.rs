//! Ray-traced ghosts: the ground-truth reference renderer and Hullin et al. 2011's ray grids.
//!
//! # How it works
//! Nothing here is paraxial. Per ghost and wavelength (one job; jobs are traced in parallel with rayon, a batch
//! of at most 2^18 vertices at a time, then seen in each view in turn, their lit triangles sorted by the bands of
//! 16 rows they reach, and splatted into one f64 frame band by band, each band drawing the jobs in order, so
//! that the image is the same whatever the threads) a regular grid of (N+1) x (N+1) rays leaves the entrance
//! plane (z = 0, the first vertex) in the light's direction and is traced exactly, in f64, along the ghost's
//! path ([`crate::optics::Tracer::trace_vertices`]: 16 rays at a time as columns, vectorised with AVX2 or AVX-512
//! where the processor has them, each bit for bit what one ray traced alone gives). Each ray records:
//! - where it lands on the sensor (the same plane and pixel mapping as the paraxial renderer);
//! - its **weight**: the reflectance R at both reflections times the transmittance 1 - R at every refraction,
//!   each at the ray's own angle of incidence and wavelength, with the surface's coating (dense tables of
//!   `DENSE_TABLE_SAMPLES` samples over sin^2 i from [`crate::coating`]);
//! - its coordinates at every stop crossing (1 or 3), in units of the stop radius at the chosen f-number;
//! - its largest relative height `h / semi-aperture` over every other surface it meets (Hullin's "relative
//!   radius").
//!
//! A ray that misses a surface, is totally internally reflected, or turns back for good is invalid; every
//! triangle touching it is dropped (its light really is lost). Each grid cell is split into two triangles and
//! **splatted with energy conserved**: a triangle carries `cos(theta) x (entrance area) x (mean weight)` of
//! the light (the irradiance on the entrance plane of a unit light is cos theta), spread over its footprint on
//! the sensor, so irradiance = that energy / sensor area: where rays bunch into a caustic, the image
//! brightens exactly as much as the footprint shrinks. The footprint is **box filtered**, as a sensor pixel
//! integrates: each pixel the triangle touches gets the irradiance times the area of the triangle's part in it
//! (in closed form from its edges, `splat::Band`). The stop coordinates, relative radius and weight are interpolated
//! barycentrically at the centroid of each covered part; the aperture mask is looked up at every stop crossing
//! and multiplied (the stop's blade shape, anti-aliased; skipped when the triangle's corners all lie in the
//! disc where the mask is fully open), and a part whose interpolated relative radius exceeds 1 is vignetted.
//! Sampling at pixel centres instead aliases the grid into moire wherever triangles are a pixel or two across
//! (the folds of a caustic most), differently at every grid; the box filter does not. A triangle inside one
//! pixel, or collapsed to a line or a point (a ghost focused there), puts all of its light in that pixel: it
//! keeps its energy and stays finite.
//!
//! Where the grid lies: a pre-pass of a coarse grid over the whole front lens (a square of half-side the front
//! clear aperture plus the obliquity of its sag) finds the cells where some ray passes everything and lands in
//! the frame; the dense grid covers their bounding box grown by one coarse cell (light that lands off the frame
//! is not traced twice). When no coarse ray passes at all, it covers 1.25 x the paraxial entrance region instead
//! (only a hint of where to look, never a result), so a ghost smaller than a coarse cell is not missed. Inside
//! that box a dense ray is traced only in the lit cells of the pre-pass grown by one cell (`LitCells`): a
//! ghost's light is often a disc, a crescent or a ring, and the rays far from it carry none. A LUT bake first
//! **scouts** a ghost ([`RayGridRenderer::scout`]: a 32-cell pre-pass over the front lens, then 48 cells over
//! where light passed) to size its windows, and that scout grid, much finer than one over the whole front
//! lens, is then the render's pre-pass ([`Ghosts::Scouted`]).
//!
//! The tracer depends only on the optics, the coatings and the aperture: [`RayGridSetup`] is all it takes of
//! a lens and its settings (made from a ghost system by `crate::flare::ray_grid_setup`, whose paraxial
//! entrance regions are its hint of where to look). Every image comes from one entry point, [`RayGridRenderer::render_request`] (a [`RayGridRequest`]: the light,
//! the views, the grid and which ghosts); [`RayGridRenderer::render`] is its whole-frame shorthand. The module
//! is in three parts: [`grid`] (grid sizes, windows, the traced vertex), `tracer` (planning the jobs, the
//! pre-pass, the scout, tracing) and `splat` (the box-filtered splatting and the accumulation).
//!
//! The two methods are this one algorithm at two densities ([`Grid`]):
//! - **reference** (adaptive, up to [`REFERENCE_GRID`] cells across, about two per pixel of the ghost's extent
//!   in the frame): the ground truth, converged (a test and `flarelab bench` show the image change falling as
//!   the grid doubles);
//! - **raygrid-N** (N = 16..128): Hullin et al. 2011's interactive method: a coarse grid of traced rays
//!   rasterised as triangles with the aperture looked up per pixel.

pub mod grid;
mod splat;
mod tracer;

pub(crate) use grid::DENSE_TABLE_SAMPLES;
pub use grid::{GRID_RANGE, Grid, REFERENCE_GRID, View, Window};
pub use splat::RayGridImage;
pub use splat::RayGridStats;
pub use tracer::{ColumnTracer, Dim, LitCells, PlannedJob, RayGridSetup, Scout, TracedGhost};
pub(crate) use tracer::{CpuTracing, EntranceHint};
pub use tracer::{Ghosts, RayGridError, RayGridRenderer, RayGridRequest, faintest};

#[cfg(test)]
mod tests {
    use super::grid::Vertex;
    use super::splat::{FrameAcc, JobFrame, carries_light, splat_triangle};
    use super::*;
    use crate::flare::FlareConfig;
    use crate::optics::library::builtin_lens;

    fn renderer(id: &str) -> RayGridRenderer {
        let flare = crate::flare::PreparedFlare::new(&builtin_lens(id).unwrap(), &FlareConfig::default()).unwrap();
        flare.ray_grid_renderer()
    }

    #[test]
    fn refuses_bad_requests() {
        let r = renderer("tessar");
        assert_eq!(r.render([0.0, 0.0], 32, 32, Grid::Fixed(1)).unwrap_err(), RayGridError::Grid(1));
        assert_eq!(r.render([0.0, 0.0], 0, 32, Grid::Adaptive(16)).unwrap_err(), RayGridError::Size(0, 32));
        assert!(matches!(r.render([f64::NAN, 0.0], 32, 32, Grid::Fixed(16)), Err(RayGridError::Angle(_))));
    }

    #[test]
    fn images_are_finite_and_non_negative_at_0_and_89_degrees() {
        let r = renderer("dgauss");
        for light in [[0.0, 0.0], [0.0, 89.0], [89.0, -89.0], [3.0, 12.0]] {
            let image = r.render(light, 48, 32, Grid::Fixed(16)).unwrap();
            assert!(image.hdr.pixels.iter().flatten().all(|v| v.is_finite() && *v >= 0.0), "{light:?}");
            assert!(image.moments.iter().all(|m| m.energy.is_finite() && m.energy >= 0.0));
            assert_eq!(image.stats.jobs, r.ghost_count() * 3);
        }
    }

    #[test]
    fn a_point_focused_triangle_keeps_its_energy() {
        let mask = crate::aperture::Aperture::default().rasterise(64);
        let frame = JobFrame {
            ghost: 0,
            rgb: [1.0, 1.0, 1.0],
            luma: 1.0,
            stop_count: 1,
            mask: &mask,
            open_radius2: 0.0,
            triangle_flux: 2.0,
        };
        let v = Vertex { valid: true, pixel: [10.3, 7.6], stops: [[0.0; 2]; 3], ratio: 0.5, weight: 0.25 };
        let mut acc = FrameAcc::new(20, 20, 1);
        assert!(carries_light([&v, &v, &v], &frame));
        splat_triangle([&v, &v, &v], &frame, &mut acc.whole());
        let total: f64 = acc.energy().iter().map(|p| p[0]).sum();
        assert!((total - 0.5).abs() < 1e-12, "{total}");
        // A large triangle: irradiance = flux / area, times the area it covers of each pixel.
        let tri = [[2.0, 2.0], [18.0, 2.0], [2.0, 18.0]].map(|pixel| Vertex { pixel, ..v });
        let mut acc = FrameAcc::new(20, 20, 1);
        splat_triangle([&tri[0], &tri[1], &tri[2]], &frame, &mut acc.whole());
        let total: f64 = acc.energy().iter().map(|p| p[0]).sum();
        assert!((total / 0.5 - 1.0).abs() < 1e-9, "box-filtered energy {total} vs 0.5");
        // Partly off the frame: what lands in it is its share by area (x >= 0: a quarter of this one).
        let tri = [[-8.0, 2.0], [8.0, 2.0], [-8.0, 18.0]].map(|pixel| Vertex { pixel, ..v });
        let mut acc = FrameAcc::new(20, 20, 1);
        splat_triangle([&tri[0], &tri[1], &tri[2]], &frame, &mut acc.whole());
        let total: f64 = acc.energy().iter().map(|p| p[0]).sum();
        assert!((total / 0.125 - 1.0).abs() < 1e-9, "{total} vs 1/4 of 0.5");
    }

    /// A mesh of triangles a pixel or so across, of one irradiance, tiles a region: every pixel inside it gets
    /// exactly that irradiance (no moire from the grid), whatever the mesh's scale, skew and offset.
    #[test]
    fn a_uniform_mesh_splats_a_uniform_image() {
        let mask = crate::aperture::Aperture::default().rasterise(64);
        let v = Vertex { valid: true, pixel: [0.0; 2], stops: [[0.0; 2]; 3], ratio: 0.5, weight: 1.0 };
        for (step, skew, offset) in [(1.37, 0.21, [3.3, 2.9]), (0.71, -0.4, [4.05, 3.5]), (2.3, 0.0, [2.5, 2.5])] {
            // Cells are parallelograms of area step^2, each two triangles of half that.
            let frame = JobFrame {
                ghost: 0,
                rgb: [1.0; 3],
                luma: 1.0,
                stop_count: 1,
                mask: &mask,
                open_radius2: f64::from(mask.open_radius()).powi(2),
                triangle_flux: 0.5 * step * step,
            };
            let n = (24.0 / step) as usize;
            let at = |i: usize, j: usize| {
                let (x, y) = (i as f64 * step, j as f64 * step);
                Vertex { pixel: [offset[0] + x + skew * y, offset[1] + y], ..v }
            };
            let mut acc = FrameAcc::new(32, 32, 1);
            for j in 0..n {
                for i in 0..n {
                    let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
                    for tri in [[&a, &b, &d], [&a, &d, &c]] {
                        assert!(carries_light(tri, &frame));
                        splat_triangle(tri, &frame, &mut acc.whole());
                    }
                }
            }
            // Pixels well inside the mesh: irradiance 1 (energy per unit area; a pixel is 1 x 1).
            let inside = (0..32 * 32).filter(|k| {
                let (x, y) = ((k % 32) as f64, (k / 32) as f64);
                let (y0, y1) = (offset[1] + 1.0, offset[1] + n as f64 * step - 2.0);
                let x_at = |y: f64| offset[0] + skew * (y - offset[1]);
                y > y0
                    && y + 1.0 < y1
                    && x > x_at(y).max(x_at(y + 1.0)) + 1.0
                    && x + 2.0 < x_at(y).min(x_at(y + 1.0)) + n as f64 * step
            });
            let (mut count, energy) = (0, acc.energy());
            for k in inside {
                assert!((energy[k][0] - 1.0).abs() < 1e-9, "step {step}: pixel {k} got {}", energy[k][0]);
                count += 1;
            }
            assert!(count > 100, "step {step}: only {count} pixels inside");
        }
    }
    /// Jobs too dim to see ([`Dim::Below`]) are left out, and only they: the image loses at most the threshold
    /// at any pixel and is otherwise the whole frame's; the choice is the same whether the jobs fit one batch
    /// (grid 32) or not (grid 160: 80 of the 84 jobs a batch, the peaks found by a trace of their own), and
    /// passing it back ([`Dim::Skip`], as a ghost's own layer does) draws the same bytes.
    #[test]
    fn a_ray_grid_leaves_out_only_the_light_below_its_threshold() {
        let r = renderer("heliar");
        for grid in [32, 160] {
            let frame = || RayGridRequest::frame([10.0, 0.0], 240, 160, Grid::Fixed(grid));
            let all = r.render_request(&frame()).unwrap().remove(0);
            let peak = all.hdr.pixels.iter().flat_map(|p| [p[0], p[1], p[2]]).fold(0.0f32, f32::max);
            let threshold = 1e-3 * f64::from(peak);
            let request = frame().dim(Dim::Below(threshold));
            let dim = r.render_request(&request).unwrap().remove(0);
            let chosen = r.dim_jobs(&request).unwrap();
            let left_out = chosen.iter().filter(|d| **d).count();
            assert!(dim.stats.dim_jobs > 0 && dim.stats.dim_jobs <= left_out, "grid {grid}: {:?}", dim.stats);
            assert_eq!(dim.stats.jobs, all.stats.jobs);
            assert!(dim.stats.triangles < all.stats.triangles);
            // What is left out: at most the threshold at any pixel (and f32 rounding), never light added.
            let (mut lost, mut gained) = (0.0f64, 0.0f64);
            for (a, d) in all.hdr.pixels.iter().zip(&dim.hdr.pixels) {
                for c in 0..3 {
                    let diff = f64::from(a[c]) - f64::from(d[c]);
                    (lost, gained) = (lost.max(diff), gained.max(-diff));
                }
            }
            let rounding = 1e-6 * f64::from(peak);
            eprintln!("grid {grid}: {left_out} jobs left out, largest loss {lost:e} of {threshold:e} allowed");
            assert!(
                lost > 0.0 && lost <= threshold + rounding && gained <= rounding,
                "grid {grid}: {lost:e} {gained:e}"
            );
            // The same choice passed back: the same bytes.
            let skipped = r.render_request(&frame().dim(Dim::Skip(&chosen))).unwrap().remove(0);
            assert!(skipped.hdr.pixels == dim.hdr.pixels, "grid {grid}: the choice passed back draws another image");
            // Nothing is left out at a threshold of 0.
            let none = r.render_request(&frame().dim(Dim::Below(0.0))).unwrap().remove(0);
            assert!(none.hdr.pixels == all.hdr.pixels && none.stats.dim_jobs == 0, "grid {grid}");
        }
    }

    /// The band splatter's images against those the tiled, per-thread splatter of the build before drew
    /// (stored as f32 RGB): the same light to rounding (a run's and a cut pixel's light are now summed in
    /// another form and order), and the same bytes on one thread and on three. The bytes themselves are held
    /// by their FNV-1a hash: those of the splatter before its rows held their channels side by side (d64b723),
    /// to the bit.
    #[test]
    fn ray_grid_images_match_the_previous_splatter_and_do_not_depend_on_threads() {
        let r = renderer("heliar");
        let stored: [(&str, [f64; 2], &[u8], u64); 2] = [
            (
                "10, 0",
                [10.0, 0.0],
                include_bytes!("../../tests/data/raygrid/heliar_10_0_144x96_grid32.f32"),
                0xfd67_85a0_2027_d82e,
            ),
            (
                "14, 9",
                [14.0, 9.0],
                include_bytes!("../../tests/data/raygrid/heliar_14_9_144x96_grid32.f32"),
                0x3a04_7e19_2a7e_90d8,
            ),
        ];
        for (name, light, bytes, hash) in stored {
            let pool = |n| rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap();
            let one = pool(1).install(|| r.render(light, 144, 96, Grid::Fixed(32)).unwrap());
            let three = pool(3).install(|| r.render(light, 144, 96, Grid::Fixed(32)).unwrap());
            assert!(one.hdr.pixels == three.hdr.pixels, "{name}: the image depends on the threads");
            assert_eq!(format!("{:?}", one.moments), format!("{:?}", three.moments), "{name}");
            let before: Vec<f32> =
                bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
            let now: Vec<f32> = one.hdr.pixels.iter().flat_map(|p| [p[0], p[1], p[2]]).collect();
            let fnv = now
                .iter()
                .flat_map(|v| v.to_le_bytes())
                .fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3));
            assert_eq!(fnv, hash, "{name}: the bytes changed (FNV-1a {fnv:#018x})");
            assert_eq!(before.len(), now.len());
            let peak = before.iter().fold(0.0f64, |m, v| m.max(f64::from(*v)));
            let worst = before.iter().zip(&now).map(|(a, b)| (f64::from(*a) - f64::from(*b)).abs()).fold(0.0, f64::max);
            let mse = before.iter().zip(&now).map(|(a, b)| (f64::from(*a) - f64::from(*b)).powi(2)).sum::<f64>()
                / now.len() as f64;
            let psnr = 10.0 * (peak * peak / mse.max(1e-300)).log10();
            eprintln!("{name}: peak {peak:e}, largest difference {worst:e}, PSNR {psnr:.1} dB");
            assert!(peak > 0.0 && psnr > 120.0 && worst <= 1e-5 * peak, "{name}: {worst:e} of {peak:e}, {psnr:.1} dB");
        }
    }
}
