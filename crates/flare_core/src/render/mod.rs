//! Rendering a flare: the scene description shared by the wgpu renderer and its CPU twin.
//!
//! # How it works
//! [`FlareScene::build`] turns one frame of ghost sprites ([`crate::ghost`]) into what both renderers draw:
//! one [`GhostInstance`] per drawn sprite (pixel centre and signed half-size, colour, the affine maps into
//! the aperture mask at every stop crossing and into the front-lens disc), the starburst's placement, and
//! the display settings in [`Globals`]. The GPU path ([`gpu`]) and the CPU twin ([`cpu`]) read exactly these
//! structs, so a test can compare their images pixel by pixel.
//!
//! Frame convention: the sensor image is rotated by 180 degrees for display (as a camera does), so the
//! displayed point of sensor coordinate (x, y) mm is (-x, -y); pixels run right and down from the top-left
//! corner, `k = width_px / sensor_width_mm`. A light seen at the frame position given by the field angles
//! (X right, Y up) has rays of slope `(-tan X, -tan Y)` ([`light_slopes_for_frame_position`]).
//!
//! Every float that reaches a GPU buffer passes [`GhostInstance::is_finite`]; a sprite that is not finite is
//! dropped and counted, never uploaded.

pub mod cpu;
pub mod gpu;
pub mod output;
pub mod shaders;

use bytemuck::{Pod, Zeroable};

use crate::ghost::{FrameSettings, GhostFrame, GhostSystem, Sensor};

/// Tonemapping operator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tonemap {
    /// Clamp only.
    None,
    /// `c / (1 + c)` per channel.
    Reinhard,
    /// Narkowicz's fit of the ACES filmic curve.
    Aces,
}

impl Tonemap {
    fn code(self) -> f32 {
        match self {
            Self::None => 0.0,
            Self::Reinhard => 1.0,
            Self::Aces => 2.0,
        }
    }
}

/// How the frame is shown.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DisplaySettings {
    /// Linear multiplier before tonemapping.
    pub exposure: f32,
    pub tonemap: Tonemap,
    /// Draw the starburst at the light's image.
    pub starburst: bool,
    /// Starburst half-size as a fraction of the frame height.
    pub starburst_size: f32,
    /// Starburst peak brightness (relative irradiance).
    pub starburst_intensity: f32,
    /// Ghosts and starburst accumulate at 1 / this resolution (1, 2 or 4), then the tonemap pass upsamples
    /// bilinearly: 4x or 16x fewer fragments for a little softness. Worth it on software adapters, where
    /// frame-filling ghosts cost the most.
    pub accumulation_divisor: u32,
}

impl Default for DisplaySettings {
    fn default() -> Self {
        Self {
            exposure: 100.0,
            tonemap: Tonemap::Aces,
            starburst: true,
            starburst_size: 0.35,
            starburst_intensity: 0.3,
            accumulation_divisor: 1,
        }
    }
}

/// Uniforms shared by every shader. Must be kept in sync with `struct Globals` in `shaders/*.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Globals {
    /// width, height, 1 / width, 1 / height (pixels).
    pub viewport: [f32; 4],
    /// centre x, centre y, half-size (pixels), intensity.
    pub starburst: [f32; 4],
    /// exposure, operator (0 none, 1 Reinhard, 2 ACES), encode sRGB (0/1), background (0/1).
    pub tonemap: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<Globals>() == 48);

/// One ghost sprite for the GPU. Must be kept in sync with `struct GhostInstance` in `shaders/ghosts.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct GhostInstance {
    /// centre x, y (pixels); half-size x, y (pixels, signed: quad coordinate q -> pixel).
    pub centre_half: [f32; 4],
    /// Linear RGB irradiance; alpha unused.
    pub colour: [f32; 4],
    /// Aperture maps of up to three stop crossings: scale, offset x, offset y, enabled (0/1).
    pub stops: [[f32; 4]; 3],
    /// Front-lens disc map: scale, offset x, offset y, anti-alias width (in its units per pixel).
    pub front: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<GhostInstance>() == 96);

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
}

/// The light slopes of a light seen at the frame position given by field angles (degrees, X right, Y up).
pub fn light_slopes_for_frame_position(x_deg: f64, y_deg: f64) -> [f64; 2] {
    [-x_deg.to_radians().tan(), -y_deg.to_radians().tan()]
}

/// Pixel position of the sensor point `p_mm` (display rotated by 180 degrees).
pub fn sensor_to_pixel(p_mm: [f64; 2], sensor: &Sensor, width: u32, height: u32) -> [f64; 2] {
    let k = width as f64 / sensor.width_mm;
    [0.5 * width as f64 - p_mm[0] * k, 0.5 * height as f64 + p_mm[1] * k]
}

impl FlareScene {
    /// The instances and uniforms for light slopes `u`, with the frame already computed by the caller
    /// (so the app can reuse it for its ghost list).
    pub fn build(
        system: &GhostSystem,
        frame: &GhostFrame,
        u: [f64; 2],
        frame_settings: &FrameSettings,
        display: &DisplaySettings,
        width: u32,
        height: u32,
    ) -> Self {
        let sensor = &frame_settings.sensor;
        let k = width as f64 / sensor.width_mm;
        let divisor = display.accumulation_divisor.clamp(1, 4);
        let (hdr_width, hdr_height) = (width.div_ceil(divisor), height.div_ceil(divisor));
        let mut instances = Vec::with_capacity(frame.stats.drawn);
        let mut instance_ghosts = Vec::with_capacity(frame.stats.drawn);
        let mut dropped_non_finite = 0;
        for (index, sprite) in frame.sprites.iter().enumerate().filter(|(_, s)| s.culled.is_none()) {
            let masks = system.sprite_masks(index, u);
            let c = sensor_to_pixel(sprite.centre_mm, sensor, width, height);
            let half_px = sprite.half_size_mm * k;
            let mut stops = [[0.0f32; 4]; 3];
            for (slot, map) in stops.iter_mut().zip(masks.stops()) {
                *slot = [map.scale as f32, map.offset[0] as f32, map.offset[1] as f32, 1.0];
            }
            // The front disc's coordinate changes by |scale| / |half_px| per pixel: the anti-alias width.
            let front = masks.front_map;
            let aa = (front.scale.abs() / half_px.abs()).max(1e-6);
            let instance = GhostInstance {
                centre_half: [c[0] as f32, c[1] as f32, -half_px as f32, half_px as f32],
                colour: [sprite.rgb[0] as f32, sprite.rgb[1] as f32, sprite.rgb[2] as f32, 0.0],
                stops,
                front: [front.scale as f32, front.offset[0] as f32, front.offset[1] as f32, aa as f32],
            };
            if instance.is_finite() {
                instances.push(instance);
                instance_ghosts.push(sprite.ghost as u32);
            } else {
                dropped_non_finite += 1;
            }
        }
        let light = sensor_to_pixel(system.light_image_mm(u), sensor, width, height);
        let starburst = if display.starburst {
            [light[0] as f32, light[1] as f32, display.starburst_size * height as f32, display.starburst_intensity]
        } else {
            [0.0, 0.0, 0.0, 0.0]
        };
        let globals = Globals {
            viewport: [width as f32, height as f32, 1.0 / width as f32, 1.0 / height as f32],
            starburst: starburst.map(|v| if v.is_finite() { v } else { 0.0 }),
            tonemap: [display.exposure, display.tonemap.code(), 1.0, 0.0],
        };
        Self { width, height, hdr_width, hdr_height, globals, instances, instance_ghosts, dropped_non_finite }
    }
}

/// A linear HDR image: `width` x `height` RGBA f32, row-major from the top.
#[derive(Clone, Debug, PartialEq)]
pub struct HdrImage {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<[f32; 4]>,
}

impl HdrImage {
    /// Nearest sample at texture coordinates (s, t) in [0, 1]^2: what `textureLoad` at the scaled pixel reads.
    pub fn sample_nearest(&self, s: f32, t: f32) -> [f32; 4] {
        let x = ((s * self.width as f32) as usize).min(self.width as usize - 1);
        let y = ((t * self.height as f32) as usize).min(self.height as usize - 1);
        self.pixels[y * self.width as usize + x]
    }

    /// Bilinear sample at texture coordinates (s, t) in [0, 1]^2, clamped to the edge: what a GPU's linear
    /// sampler returns.
    pub fn sample_bilinear(&self, s: f32, t: f32) -> [f32; 4] {
        let (w, h) = (self.width as usize, self.height as usize);
        let (x, y) = (s * w as f32 - 0.5, t * h as f32 - 0.5);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let at = |i: f32, j: f32| {
            let i = (i.max(0.0) as usize).min(w - 1);
            let j = (j.max(0.0) as usize).min(h - 1);
            self.pixels[j * w + i]
        };
        let mut out = [0.0; 4];
        for (c, o) in out.iter_mut().enumerate() {
            let top = at(x0, y0)[c] * (1.0 - fx) + at(x0 + 1.0, y0)[c] * fx;
            let bottom = at(x0, y0 + 1.0)[c] * (1.0 - fx) + at(x0 + 1.0, y0 + 1.0)[c] * fx;
            *o = top * (1.0 - fy) + bottom * fy;
        }
        out
    }
}

/// A display image: 8-bit sRGB RGBA.
#[derive(Clone, Debug, PartialEq)]
pub struct DisplayImage {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<[u8; 4]>,
}
