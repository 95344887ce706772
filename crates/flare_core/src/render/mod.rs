//! Rendering a flare: the scene description shared by the wgpu renderer and its CPU twin.
//!
//! # How it works
//! [`FlareScene::build`] turns one frame of ghost sprites ([`crate::ghost`]) into what both renderers draw:
//! one [`GhostInstance`] per drawn sprite (pixel centre and signed half-size, colour, the affine maps into
//! the aperture mask at every stop crossing and into each clear-aperture disc that cuts it), the starburst's placement, and
//! the display settings in [`Globals`]. The GPU path ([`gpu`]) and the CPU twin ([`cpu`]) read exactly these
//! structs, so a test can compare their images pixel by pixel. [`raygrid`] is the other GPU renderer: the
//! ray-traced ghosts of [`crate::raytrace`] (its f64 CPU twin) traced and splatted on the GPU; [`dof_gpu`]
//! the live depth of field of the plate ([`crate::dof::live`] its CPU twin).
//!
//! Frame convention: the sensor image is rotated by 180 degrees for display (as a camera does), so the
//! displayed point of sensor coordinate (x, y) mm is (-x, -y); pixels run right and down from the top-left
//! corner, `k = width_px / sensor_width_mm`. A light seen at the frame position given by the field angles
//! (X right, Y up) has rays of slope `(-tan X, -tan Y)` ([`light_slopes_for_frame_position`]).
//!
//! Every float that reaches a GPU buffer passes [`GhostInstance::is_finite`]; a sprite that is not finite is
//! dropped and counted, never uploaded.

mod buffers;
pub mod cpu;
pub mod dof_gpu;
pub mod gpu;
pub mod gpu_ghosts;
mod gpu_ghosts_raster;
mod gpu_lut;
mod gpu_lut_raster;
mod gpu_sprites;
mod gpu_view;
pub mod raygrid;
pub mod shaders;

use bytemuck::{Pod, Zeroable};

pub use crate::color::Tonemap;
use crate::color::gain_from_ev;
use crate::dirt::{PreparedDirt, henyey_greenstein, henyey_greenstein_g};
use crate::ghost::{FrameSettings, GhostFrame, GhostSystem, MAX_DISCS, map_reach};
pub use crate::ghost::{light_slopes_for_frame_position, sensor_to_pixel};
pub use crate::image::{DisplayImage, HdrImage};
use crate::optics::sensor::Sensor;
use crate::starburst::Starburst;

/// How the frame is shown: the exposures, the tonemap and the starburst. None of these changes the optics, so
/// none of them rebuilds the ghost system, the starburst's FFT or a GPU texture.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DisplaySettings {
    /// The flare's exposure in stops: its relative irradiance (the light's is 1) is multiplied by `2^flare_ev`.
    pub flare_ev: f64,
    /// The background plate's exposure in stops (0: as shot).
    pub plate_ev: f64,
    pub tonemap: Tonemap,
    /// Draw the starburst at the light's image.
    pub starburst: bool,
    /// Multiplies the starburst's physical brightness (1: the light's own image as the lens makes it, see
    /// [`crate::starburst`]; the light's gain is folded in per frame).
    pub starburst_intensity: f32,
    /// Ghosts and starburst accumulate at 1 / this resolution (1, 2 or 4), then the tonemap pass upsamples
    /// bilinearly: 4x or 16x fewer fragments for a little softness. Worth it on software adapters, where
    /// frame-filling ghosts cost the most.
    pub accumulation_divisor: u32,
    /// The front dirt's share where it is densest ([`crate::dirt`]; 0: a clean lens), the light's gain folded in
    /// per frame for the glow.
    pub dirt_amount: f64,
    /// The dirt's scattering lobe, half width at half peak (degrees).
    pub dirt_spread_deg: f64,
}

impl Default for DisplaySettings {
    fn default() -> Self {
        Self {
            flare_ev: crate::exposure::DEFAULT_FLARE_EV,
            plate_ev: 0.0,
            tonemap: Tonemap::View,
            starburst: true,
            starburst_intensity: 1.0,
            accumulation_divisor: 1,
            dirt_amount: 0.0,
            dirt_spread_deg: crate::dirt::DEFAULT_DIRT_SPREAD_DEG,
        }
    }
}

impl DisplaySettings {
    /// The flare's linear gain, `2^flare_ev`.
    pub fn flare_gain(&self) -> f32 {
        gain_from_ev(self.flare_ev)
    }

    /// The plate's linear gain, `2^plate_ev`.
    pub fn plate_gain(&self) -> f32 {
        gain_from_ev(self.plate_ev)
    }
}

/// Uniforms shared by every shader: the Rust side of `struct Globals` in `shaders/common.wgsl` (the one WGSL
/// declaration; a test checks every member's name and offset with naga). Codes are `u32`s, never floats.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Globals {
    /// The frame's width and height (pixels).
    pub viewport_px: [f32; 2],
    /// 1 / width and 1 / height.
    pub inv_viewport_px: [f32; 2],
    /// The starburst's centre: the light's image (pixels).
    pub starburst_centre_px: [f32; 2],
    /// How far the starburst is drawn (pixels; 0: no starburst).
    pub starburst_reach_px: f32,
    /// The blown-out core's radius (pixels).
    pub starburst_core_px: f32,
    /// The flare's linear gain, `2^flare_ev`.
    pub flare_gain: f32,
    /// The operator ([`Tonemap::code`]: `TONEMAP_*` in the shader).
    pub tonemap_operator: u32,
    /// 1 when the shader encodes sRGB (a target that does not encode it itself; set by the renderer), else 0.
    pub encode_srgb: u32,
    /// 1 when a background plate is bound (set by the renderer), else 0.
    pub plate_present: u32,
    /// 1 / width and 1 / height of the delivered image (the tonemap's pixels: the frame's own, or a desqueezed
    /// frame's fewer rows or columns).
    pub inv_output_px: [f32; 2],
    /// The plate's linear gain, `2^plate_ev`.
    pub plate_gain: f32,
    pub _pad0: u32,
    /// The starburst's far field: `K` per channel (`I = K c(phi) / r_mm^3`).
    pub starburst_far_k: [f32; 3],
    /// mm per pixel on the sensor.
    pub starburst_mm_per_px: f32,
    /// The starburst's core: relative irradiance per channel inside the core radius.
    pub starburst_core_rgb: [f32; 3],
    /// The far field's stretch along x, `N_x / N_y` of an anamorphic lens (0 stands for 1: a lens of revolution).
    pub starburst_stretch_x: f32,
    /// The front dirt's glow ([`crate::dirt`]): the light's image (pixels).
    pub dirt_light_px: [f32; 2],
    /// The light's slopes `u_s`.
    pub dirt_light_slopes: [f32; 2],
    /// The slopes per image pixel about the light, row-major 2x2 (`u = u_s + A (pixel - light)`): the inverse of
    /// the lens's own mapping's derivative there.
    pub dirt_slopes_per_px: [f32; 4],
    /// The footprint's centre, in map texels, per unit slope about the light, row-major 2x2 (the derivative of
    /// the chief ray's entrance point there).
    pub dirt_footprint: [f32; 4],
    /// The footprint's centre for the light itself, in map texels (x, y).
    pub dirt_centre_texels: [f32; 2],
    /// The glow's lobe: the Henyey-Greenstein `g`.
    pub dirt_g: f32,
    /// `|det A|` in mm^-2 per unit slope^2 (`1 / |det dx/du|`).
    pub dirt_per_mm2: f32,
    /// The glow's power per channel (`amount A_EP cos(theta_s) T` x the light's gain; 0: no glow).
    pub dirt_power_rgb: [f32; 3],
    /// `(1 - g^2) / (4 pi)`.
    pub dirt_hg_norm: f32,
    /// `1 / sqrt(1 + |u_s|^2)`.
    pub dirt_inv_ns: f32,
    pub _pad1: u32,
    pub _pad2: u32,
    pub _pad3: u32,
}
const _: () = assert!(std::mem::size_of::<Globals>() == 192);

impl Globals {
    /// The tonemap operator.
    pub fn operator(&self) -> Tonemap {
        Tonemap::from_code(self.tonemap_operator)
    }
}

/// One ghost sprite for the GPU. Must be kept in sync with `struct GhostInstance` in `shaders/ghosts.wgsl` and
/// `shaders/ghosts_compute.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct GhostInstance {
    /// centre x, y (pixels); half-size x, y (pixels, signed: quad coordinate q -> pixel).
    pub centre_half: [f32; 4],
    /// Linear RGB irradiance; alpha unused.
    pub colour: [f32; 4],
    /// Aperture maps of up to three stop crossings: scale, offset x, offset y, and the level of the mask it
    /// reads (0: not enabled; 1 the base mask, as [`FlareScene::build`] leaves it, 2 and 3 the finer ones
    /// that [`cpu::ghosts::GhostMasks::assign_levels`] picks for large sprites).
    pub stops: [[f32; 4]; 3],
    /// The y scales of the three stop maps (`stops[k][0]` are the x scales): equal to them for a lens of
    /// revolution, the y-z section's for an anamorphic lens; the fourth unused.
    pub scale_y: [f32; 4],
    /// The clear-aperture discs that cut the sprite ([`crate::ghost::SpriteMasks::discs`], the front lens's among
    /// them when it cuts), each an anti-aliased unit circle in its map: x scale, offset x, offset y, anti-alias
    /// width (in its units per pixel; 0: no disc in this slot). A disc that holds the whole quad is left out.
    pub discs: [[f32; 4]; MAX_DISCS],
    /// The y scales of the disc maps.
    pub disc_scale_y: [f32; MAX_DISCS],
}
const _: () = assert!(std::mem::size_of::<GhostInstance>() == 16 * (6 + 5 * MAX_DISCS / 4));

impl GhostInstance {
    /// True when every field is finite (the only instances ever uploaded).
    pub fn is_finite(&self) -> bool {
        bytemuck::cast_slice::<_, f32>(std::slice::from_ref(self)).iter().all(|v| v.is_finite())
    }
}

/// Everything one frame draws.
#[derive(Clone, Debug, PartialEq)]
pub struct FlareScene {
    pub width: u32,
    pub height: u32,
    /// Size of the HDR accumulation (the image size divided by the accumulation divisor, rounded up).
    pub hdr_width: u32,
    pub hdr_height: u32,
    pub globals: Globals,
    pub instances: Vec<GhostInstance>,
    /// The ghost each instance belongs to (not uploaded; for per-ghost measurements).
    pub instance_ghosts: Vec<u32>,
    /// Sprites dropped because a value was not finite (expected: always 0).
    pub dropped_non_finite: usize,
    /// Clear-aperture discs that cut a drawn sprite but were left out, beyond `MAX_DISCS` a sprite.
    pub discs_left_out: usize,
    /// The OCIO display transform of [`Tonemap::View`] (`None`: the built-in default,
    /// [`crate::view_transform::ViewTransform::builtin`]).
    pub view: Option<std::sync::Arc<crate::view_transform::ViewTransform>>,
    /// The size of the image the tonemap and the layers deliver: `(width, height)`, or fewer rows (columns
    /// below 1) for a desqueezed frame ([`crate::frame::FrameRequest::desqueeze`]), sampled bilinearly from the
    /// sensor's pixels (exactly the mean of two for a desqueeze of 2 or 1/2).
    pub output_size: (u32, u32),
}

impl FlareScene {
    /// The OCIO display transform the tonemap pass runs for [`Tonemap::View`].
    pub fn view_transform(&self) -> std::sync::Arc<crate::view_transform::ViewTransform> {
        self.view.clone().unwrap_or_else(crate::view_transform::ViewTransform::builtin)
    }

    /// The instances and uniforms for light slopes `u`, with the frame already computed by the caller
    /// (so the app can reuse it for its ghost list). `gains[g]` multiplies every sprite of lens ghost `g`
    /// (missing entries are 1); a ghost at gain 0 (off, or not the solo one) makes no instance.
    #[allow(clippy::too_many_arguments)]
    pub fn build(
        system: &GhostSystem,
        frame: &GhostFrame,
        u: [f64; 2],
        frame_settings: &FrameSettings,
        display: &DisplaySettings,
        width: u32,
        height: u32,
        gains: &[f32],
    ) -> Self {
        let sensor = &frame_settings.sensor;
        let k = width as f64 / sensor.width_mm;
        let divisor = display.accumulation_divisor.clamp(1, 4);
        let (hdr_width, hdr_height) = (width.div_ceil(divisor), height.div_ceil(divisor));
        let mut instances = Vec::with_capacity(frame.stats.drawn);
        let mut instance_ghosts = Vec::with_capacity(frame.stats.drawn);
        let mut dropped_non_finite = 0;
        let mut discs_left_out = 0;
        for (index, sprite) in frame.sprites.iter().enumerate().filter(|(_, s)| s.culled.is_none()) {
            let gain = gains.get(sprite.ghost).copied().unwrap_or(1.0);
            if gain.is_nan() || gain <= 0.0 {
                continue;
            }
            let masks = system.sprite_masks(index, u);
            let c = sensor_to_pixel(sprite.centre_mm, sensor, width, height);
            let half_px = sprite.half_size_mm.map(|h| h * k);
            let mut stops = [[0.0f32; 4]; 3];
            let mut scale_y = [0.0f32; 4];
            for ((slot, y), map) in stops.iter_mut().zip(&mut scale_y).zip(masks.stops()) {
                *slot = [map.scale[0] as f32, map.offset[0] as f32, map.offset[1] as f32, 1.0];
                *y = map.scale[1] as f32;
            }
            // Each disc's coordinate changes by |scale| / |half_px| per pixel: its anti-alias width (the faster of
            // the two axes). A disc whose soft edge stays outside the quad is 1 there: left out.
            let mut discs = [[0.0f32; 4]; MAX_DISCS];
            let mut disc_scale_y = [0.0f32; MAX_DISCS];
            let mut n = 0;
            for map in masks.discs() {
                let aa = (map.scale[0].abs() / half_px[0].abs()).max(map.scale[1].abs() / half_px[1].abs()).max(1e-6);
                if map_reach(map) <= 1.0 - 0.5 * aa {
                    continue;
                }
                discs[n] = [map.scale[0] as f32, map.offset[0] as f32, map.offset[1] as f32, aa as f32];
                disc_scale_y[n] = map.scale[1] as f32;
                n += 1;
            }
            discs_left_out += masks.discs_left_out;
            let instance = GhostInstance {
                centre_half: [c[0] as f32, c[1] as f32, -half_px[0] as f32, half_px[1] as f32],
                colour: [sprite.rgb[0] as f32 * gain, sprite.rgb[1] as f32 * gain, sprite.rgb[2] as f32 * gain, 0.0],
                stops,
                scale_y,
                discs,
                disc_scale_y,
            };
            if instance.is_finite() {
                instances.push(instance);
                instance_ghosts.push(sprite.ghost as u32);
            } else {
                dropped_non_finite += 1;
            }
        }
        let inv_px = [1.0 / width as f32, 1.0 / height as f32];
        let globals = Globals {
            viewport_px: [width as f32, height as f32],
            inv_viewport_px: inv_px,
            flare_gain: display.flare_gain(),
            tonemap_operator: display.tonemap.code(),
            encode_srgb: 1,
            inv_output_px: inv_px,
            plate_gain: display.plate_gain(),
            ..Globals::zeroed()
        };
        Self {
            width,
            height,
            hdr_width,
            hdr_height,
            globals,
            instances,
            instance_ghosts,
            dropped_non_finite,
            discs_left_out,
            view: None,
            output_size: (width, height),
        }
    }

    /// Delivers the frame at `size` (a desqueezed frame's fewer rows or columns): the tonemap samples the accumulation at
    /// the delivered pixels ([`Globals::inv_output_px`]).
    pub fn set_output_size(&mut self, size: (u32, u32)) {
        self.output_size = (size.0.max(1), size.1.max(1));
        self.globals.inv_output_px = [1.0 / self.output_size.0 as f32, 1.0 / self.output_size.1 as f32];
    }

    /// The accumulation fragments `inst` covers: its quad clipped to the accumulation (what a sprite costs a
    /// rasteriser, whatever its brightness).
    pub fn fragments(&self, inst: &GhostInstance) -> u64 {
        let (sx, sy) = (self.width as f32 / self.hdr_width as f32, self.height as f32 / self.hdr_height as f32);
        let [cx, cy, hx, hy] = inst.centre_half;
        let span = |c: f32, h: f32, scale: f32, size: u32| {
            let (lo, hi) = (((c - h.abs()) / scale).max(0.0), ((c + h.abs()) / scale).min(size as f32));
            f64::from((hi - lo).max(0.0))
        };
        (span(cx, hx, sx, self.hdr_width) * span(cy, hy, sy, self.hdr_height)).ceil() as u64
    }

    /// Keeps, of the instances, the brightest (by their brightest channel) whose fragments together fit in
    /// `budget`, in their order; a sprite that does not fit is skipped and fainter ones may still fit. Returns
    /// how many were dropped.
    pub fn keep_brightest(&mut self, budget: u64) -> usize {
        let peak = |i: &GhostInstance| i.colour[0].max(i.colour[1]).max(i.colour[2]);
        let mut order: Vec<usize> = (0..self.instances.len()).collect();
        order.sort_by(|&a, &b| peak(&self.instances[b]).total_cmp(&peak(&self.instances[a])).then(a.cmp(&b)));
        let mut keep = vec![false; self.instances.len()];
        let mut used = 0u64;
        for k in order {
            let cost = self.fragments(&self.instances[k]);
            if used + cost <= budget {
                used += cost;
                keep[k] = true;
            }
        }
        let before = self.instances.len();
        self.instances = self.instances.iter().zip(&keep).filter(|(_, k)| **k).map(|(i, _)| *i).collect();
        self.instance_ghosts = self.instance_ghosts.iter().zip(&keep).filter(|(_, k)| **k).map(|(g, _)| *g).collect();
        before - self.instances.len()
    }

    /// Places the starburst of `starburst` at the image of a light of slopes `u` (see [`crate::starburst`]):
    /// its physical brightness for the lens's entrance pupil at the working f-number, times
    /// `display.starburst_intensity`, drawn out to where it falls below a quarter of an 8-bit step at the
    /// flare's exposure (at most the frame's diagonal). Nothing when the display leaves it out.
    pub fn place_starburst(
        &mut self,
        system: &GhostSystem,
        starburst: &Starburst,
        u: [f64; 2],
        sensor: &Sensor,
        display: &DisplaySettings,
    ) {
        let (g, width, height) = (&mut self.globals, self.width, self.height);
        (g.starburst_centre_px, g.starburst_reach_px, g.starburst_core_px) = ([0.0; 2], 0.0, 0.0);
        (g.starburst_far_k, g.starburst_mm_per_px) = ([0.0; 3], 0.0);
        (g.starburst_core_rgb, g.starburst_stretch_x) = ([0.0; 3], 0.0);
        let intensity = f64::from(display.starburst_intensity);
        let lit = display.starburst && intensity.is_finite() && intensity > 0.0 && starburst.profile_peak > 0.0;
        if !lit {
            return;
        }
        let fo = &system.first_order;
        let stop_scale = system.settings.stop_scale.clamp(1e-3, 1.0);
        let f_number = fo.f_number.abs() / stop_scale;
        let pupil_mm = fo.entrance_pupil_diameter_mm.abs() * stop_scale;
        let cos_theta = 1.0 / (1.0 + u[0] * u[0] + u[1] * u[1]).sqrt();
        // The light's power through the pupil, in relative irradiance x mm^2.
        let power = intensity * std::f64::consts::FRAC_PI_4 * pupil_mm * pupil_mm * cos_theta;
        let mm_per_px = sensor.width_mm / f64::from(width.max(1));
        let spectrum = &system.settings.spectrum;
        let core_radius_mm = STARBURST_CORE_PX * mm_per_px;
        let core_area = std::f64::consts::PI * core_radius_mm * core_radius_mm;
        let (mut far, mut core) = ([0.0f64; 3], [0.0f64; 3]);
        for (w, weight) in spectrum.weights_rgb.iter().enumerate() {
            let lambda_n_mm = spectrum.wavelengths_nm[w] * 1e-6 * f_number;
            // The share beyond the core radius is C lambda N / r_core; the rest is the blown-out core.
            let far_share = (starburst.far_total * lambda_n_mm / core_radius_mm).min(1.0);
            for c in 0..3 {
                far[c] += power * weight[c] * starburst.profile_peak * lambda_n_mm;
                core[c] += power * weight[c] * (1.0 - far_share) / core_area;
            }
        }
        let level = 0.25 / 255.0 / f64::from(display.flare_gain()).max(1e-30);
        let brightest = far.iter().copied().fold(0.0, f64::max);
        let reach_px = ((brightest / level).cbrt() / mm_per_px).min(f64::from(width).hypot(f64::from(height)));
        let light = sensor_to_pixel(system.light_image_mm(u), sensor, width, height);
        let finite = |v: f64| if v.is_finite() { v.clamp(-1e30, 1e30) as f32 } else { 0.0 };
        if !(reach_px.is_finite() && reach_px > STARBURST_CORE_PX) {
            return;
        }
        (g.starburst_centre_px, g.starburst_reach_px) = ([finite(light[0]), finite(light[1])], finite(reach_px));
        g.starburst_core_px = STARBURST_CORE_PX as f32;
        (g.starburst_far_k, g.starburst_mm_per_px) = (far.map(finite), finite(mm_per_px));
        let core = core.map(|v| v.min(STARBURST_MAX));
        // An anamorphic lens diffracts with a working f-number per section: the far field (scaled by lambda N)
        // is stretched along x by N_x / N_y, its energy kept (the uniform 0 means 1, a lens of revolution).
        let stretch = match &fo.sections {
            Some(both) => (both[0].f_number / both[1].f_number).abs(),
            None => 0.0,
        };
        (g.starburst_core_rgb, g.starburst_stretch_x) = (core.map(finite), finite(stretch));
    }
}

impl FlareScene {
    /// Places the glow of the front dirt `dirt` for a light of slopes `u` (see [`crate::dirt`]), at
    /// `display.dirt_amount` (the light's gain folded in) and `display.dirt_spread_deg`. Nothing (every dirt
    /// uniform 0) for a clean lens, an amount of 0, a light without finite slopes, or a glow whose brightest
    /// pixel would fall below a quarter of an 8-bit step at the flare's exposure.
    pub fn place_dirt(
        &mut self,
        system: &GhostSystem,
        dirt: Option<&PreparedDirt>,
        u: [f64; 2],
        sensor: &Sensor,
        display: &DisplaySettings,
    ) {
        let (width, height) = (self.width, self.height);
        let g = &mut self.globals;
        (g.dirt_light_px, g.dirt_light_slopes, g.dirt_slopes_per_px) = ([0.0; 2], [0.0; 2], [0.0; 4]);
        (g.dirt_footprint, g.dirt_centre_texels, g.dirt_g, g.dirt_per_mm2) = ([0.0; 4], [0.0; 2], 0.0, 0.0);
        (g.dirt_power_rgb, g.dirt_hg_norm, g.dirt_inv_ns) = ([0.0; 3], 0.0, 0.0);
        let amount = display.dirt_amount;
        let Some(dirt) = dirt.filter(|_| amount.is_finite() && amount > 0.0 && u.iter().all(|v| v.is_finite())) else {
            return;
        };
        // The lens's own mapping and the chief ray's entrance point, linearised about the light: exact at the
        // light, where the lobe puts the glow.
        let step = 1e-4 * (1.0 + u[0].hypot(u[1]));
        let derivative = |f: &dyn Fn([f64; 2]) -> [f64; 2]| -> [[f64; 2]; 2] {
            let (x0, x1) = (f([u[0] - step, u[1]]), f([u[0] + step, u[1]]));
            let (y0, y1) = (f([u[0], u[1] - step]), f([u[0], u[1] + step]));
            let d = 2.0 * step;
            [[(x1[0] - x0[0]) / d, (y1[0] - y0[0]) / d], [(x1[1] - x0[1]) / d, (y1[1] - y0[1]) / d]]
        };
        let m = derivative(&|v| system.light_image_mm(v));
        let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
        if !(det.is_finite() && det.abs() > 1e-12) {
            return;
        }
        // Pixels: x right is sensor -x, y down is sensor +y ([`sensor_to_pixel`]), k pixels per mm.
        let k = f64::from(width.max(1)) / sensor.width_mm;
        let inverse = [[m[1][1] / det, -m[0][1] / det], [-m[1][0] / det, m[0][0] / det]];
        let per_pixel = [[-inverse[0][0] / k, inverse[0][1] / k], [-inverse[1][0] / k, inverse[1][1] / k]];
        let texels_per_mm = dirt.size as f64 / (2.0 * dirt.half_extent_mm);
        let middle = 0.5 * dirt.size as f64 - 0.5;
        let c = system.light_entrance_mm(u);
        let j = derivative(&|v| system.light_entrance_mm(v));
        let n_s = (1.0 + u[0] * u[0] + u[1] * u[1]).sqrt();
        let colour = dirt.colour_rgb.map(|c| amount * c * dirt.pupil_area_mm2 / n_s);
        let spread = henyey_greenstein_g(display.dirt_spread_deg);
        let per_mm2 = 1.0 / det.abs();
        let brightest = colour.iter().copied().fold(0.0, f64::max)
            * henyey_greenstein(spread, 1.0)
            * per_mm2
            * f64::from(dirt.map_peak);
        let level = 0.25 / 255.0 / f64::from(display.flare_gain()).max(1e-30);
        if !(brightest.is_finite() && brightest > level) {
            return;
        }
        let light = sensor_to_pixel(system.light_image_mm(u), sensor, width, height);
        let t = texels_per_mm;
        let values = [
            [light[0], light[1], u[0], u[1]],
            [per_pixel[0][0], per_pixel[0][1], per_pixel[1][0], per_pixel[1][1]],
            // Texel rows run down the map: -y.
            [t * j[0][0], t * j[0][1], -t * j[1][0], -t * j[1][1]],
            [c[0] * t + middle, -c[1] * t + middle, 0.0, 0.0],
            [spread, per_mm2, 1.0 / n_s, 0.0],
            [colour[0], colour[1], colour[2], (1.0 - spread * spread) / (4.0 * std::f64::consts::PI)],
        ];
        if !values.iter().flatten().all(|v| v.is_finite() && v.abs() < 1e30) {
            return;
        }
        let f = |v: [f64; 4]| v.map(|x| x as f32);
        let [light, geom, footprint, centre, lobe, colour] = values.map(f);
        (g.dirt_light_px, g.dirt_light_slopes) = ([light[0], light[1]], [light[2], light[3]]);
        (g.dirt_slopes_per_px, g.dirt_footprint, g.dirt_centre_texels) = (geom, footprint, [centre[0], centre[1]]);
        (g.dirt_g, g.dirt_per_mm2, g.dirt_inv_ns) = (lobe[0], lobe[1], lobe[2]);
        (g.dirt_power_rgb, g.dirt_hg_norm) = ([colour[0], colour[1], colour[2]], colour[3]);
    }

    /// True when the frame draws a dirt glow.
    pub fn has_dirt_glow(&self) -> bool {
        self.globals.dirt_power_rgb.iter().any(|&c| c > 0.0)
    }

    /// True when the frame draws a starburst (its reach is positive; off, or a light too dim, it has none).
    pub fn draws_starburst(&self) -> bool {
        self.globals.starburst_reach_px > 0.0
    }
}

/// The starburst's core radius in pixels: the light's blown-out image.
pub(crate) const STARBURST_CORE_PX: f64 = 1.0;
/// The most relative irradiance the starburst adds to a pixel (before the flare's gain): the half-float
/// accumulation holds it, and the light's image is white long before it.
pub(crate) const STARBURST_MAX: f64 = 3.0e4;

#[cfg(test)]
mod layouts {
    //! Every struct the GPU reads, named on both sides: the Rust struct's fields against the WGSL's members.
    use super::shaders::{self, layout::*};
    use super::*;

    #[test]
    fn every_gpu_struct_has_its_wgsl_layout() {
        assert_same_layout(
            shaders::COMMON_WGSL,
            "Globals",
            fields!(Globals: viewport_px, inv_viewport_px, starburst_centre_px, starburst_reach_px, starburst_core_px,
                flare_gain, tonemap_operator, encode_srgb, plate_present, inv_output_px, plate_gain, _pad0,
                starburst_far_k, starburst_mm_per_px, starburst_core_rgb, starburst_stretch_x, dirt_light_px,
                dirt_light_slopes, dirt_slopes_per_px, dirt_footprint, dirt_centre_texels, dirt_g, dirt_per_mm2,
                dirt_power_rgb, dirt_hg_norm, dirt_inv_ns, _pad1, _pad2, _pad3),
        );
        // Both forms of a ghost instance: the compute pass's storage struct and the raster pass's vertex
        // attributes (read in the struct's order, one `vec4` each: arrays spelled out).
        for source in [shaders::GHOSTS_COMPUTE_WGSL, shaders::GHOSTS_WGSL] {
            assert_same_layout(
                source,
                "GhostInstance",
                fields!(GhostInstance: centre_half, colour, stops, scale_y, discs, disc_scale_y),
            );
        }
        // The LUT's raster instance (its compute form is inside `TiledInstance`, checked by `gpu_lut`).
        use crate::lut::blend::LutInstance;
        assert_same_layout(
            shaders::LUT_GHOSTS_WGSL,
            "LutInstance",
            fields!(LutInstance: centre_axis_x, axis_y, page, _pad0, rect, colour),
        );
        use super::gpu_ghosts::ComputeStrip;
        assert_same_layout(
            shaders::GHOSTS_COMPUTE_WGSL,
            "ComputeStrip",
            fields!(ComputeStrip: width, height, first_row, rows, instances, items, groups_x, mask_size, scale_x,
                scale_y, fixed_per_unit, unit_per_fixed, lut, split_bits, pieces, spread, mask_levels, level_starts),
        );
        super::gpu_lut::assert_layouts();
        super::raygrid::assert_layouts();
        use crate::dof::live::LiveLayer;
        assert_same_layout(
            shaders::DOF_WGSL,
            "Layer",
            fields!(LiveLayer: size, taps, low, out, pixels, shape, cat, cat_radius, cat_x_scale, cat_count, cat_edge,
                cat_on, _pad0, pupil),
        );
    }
}
