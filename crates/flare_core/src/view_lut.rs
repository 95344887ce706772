//! The OCIO view baked into a 3D LUT: what a software adapter's drafts are tonemapped through.
//!
//! # How it works
//! OCIO's shader of an ACES 2.0 view is long (a tone scale, a chroma compression and a gamut compression
//! that searches tables), and a software rasteriser such as lavapipe runs it at a cost of its own: about
//! 20 ms of a 640 x 360 draft while the light is dragged. [`ViewLut::bake`] evaluates the view's CPU
//! processor ([`ViewTransform::apply`], the exact view) once, on a cube of `size`^3 working-space colours;
//! the draft's tonemap then looks a colour up in that cube ([`ViewLut::shader`], the WGSL of
//! `shaders/ocio_lut.wgsl` as the tonemap's `ocio_display`) and never runs the view's code. Only drafts on a
//! software adapter use it (`render::gpu::FlareRenderer::sample_view_from_lut`); every full frame, and every
//! frame on a hardware GPU, goes through the exact view.
//!
//! Each channel goes through the same shaper before the lookup: `t = (log2(max(x, 0) + OFFSET) -
//! log2(OFFSET)) / (log2(MAX + OFFSET) - log2(OFFSET))`, clamped to [0, 1], i.e. log-spaced nodes from 0 to
//! [`MAX`] with a linear toe below `OFFSET`: a stop of light covers about the same number of nodes from
//! the darkest shadow to the brightest flare core. A channel below 0 (a plate colour outside the working
//! gamut) is looked up as 0, one above [`MAX`] as [`MAX`]. The lookup is trilinear between the 8 nodes
//! around the shaped colour: on the GPU one `textureSampleLevel` of an `Rgba16Float` 3D texture through a
//! linear sampler (filterable on every adapter; lavapipe samples it in a third less time than 8
//! `textureLoad`s of `Rgba32Float`), so the cube's texels are rounded to 16-bit floats when baked (at most
//! 1/2048 of a display value). [`ViewLut::apply`] is its CPU twin, in f32: the same texels and weights (a
//! GPU's sampler may round the weights to 8 bits of a cell; the tests bound the difference). The texel of
//! node (r, g, b) is at index `r + size * (g + size * b)`, the order of a 3D texture's x, y and z. How far
//! the cube is from the exact view is measured by the tests (in display code values, see `tests/colour.rs`).

use std::sync::{Arc, Mutex};

use crate::view_transform::{ViewTransform, WgslShader, WgslTexture};

/// The OCIO view baked into a cube (its shaper's constants are put before it, [`ViewLut::shader`]): the
/// tonemap's `ocio_display` for a software adapter's drafts.
pub(crate) const OCIO_LUT_WGSL: &str = include_str!("../../../shaders/ocio_lut.wgsl");

/// The cube's nodes per side.
pub const SIZE: usize = 65;
/// The shaper's linear toe: the offset added before the logarithm.
pub(crate) const OFFSET: f32 = 1.0 / 4096.0;
/// The brightest channel value with its own nodes (a brighter channel is looked up as this).
pub const MAX: f32 = 65504.0;
/// The cube's binding in the tonemap's view group ([`crate::view_transform::WGSL_GROUP`]).
pub(crate) const BINDING: u32 = 1;
/// Its sampler's binding (linear, clamped to the edge).
pub(crate) const SAMPLER_BINDING: u32 = 2;

/// `log2(OFFSET)` and `1 / (log2(MAX + OFFSET) - log2(OFFSET))`: the shaper's two constants.
fn shaper_constants() -> (f32, f32) {
    let low = OFFSET.log2();
    (low, 1.0 / ((MAX + OFFSET).log2() - low))
}

/// A channel's place in the cube, from 0 (no light) to 1 ([`MAX`]).
pub fn shape(x: f32) -> f32 {
    let (low, inverse_range) = shaper_constants();
    ((x.max(0.0) + OFFSET).log2() - low) * inverse_range
}

/// The channel value of node `i` of `size` (the shaper's inverse at `i / (size - 1)`).
fn node_value(i: usize, size: usize) -> f32 {
    let (low, inverse_range) = shaper_constants();
    let t = i as f32 / (size - 1) as f32;
    ((low + t / inverse_range).exp2() - OFFSET).max(0.0)
}

/// The last few cubes baked, and the keys of the views whose bake has started.
struct Cache {
    cubes: Vec<Arc<ViewLut>>,
    baking: Vec<u64>,
}

impl Cache {
    fn find(&self, key: u64) -> Option<Arc<ViewLut>> {
        self.cubes.iter().find(|l| l.key == key).cloned()
    }
}

static CACHE: Mutex<Cache> = Mutex::new(Cache { cubes: Vec::new(), baking: Vec::new() });

/// Puts a cube just baked among the kept ones (at most 4, the oldest dropped) and returns it (or the one of
/// its view kept meanwhile).
fn keep(cube: Arc<ViewLut>) -> Arc<ViewLut> {
    if let Ok(mut cache) = CACHE.lock() {
        cache.baking.retain(|k| *k != cube.key);
        if let Some(kept) = cache.find(cube.key) {
            return kept;
        }
        if cache.cubes.len() >= 4 {
            cache.cubes.remove(0);
        }
        cache.cubes.push(cube.clone());
    }
    cube
}

/// An OCIO view baked into a cube (see the module documentation).
pub struct ViewLut {
    /// The view's key ([`ViewTransform::key`]).
    pub key: u64,
    /// Nodes per side (at least 2).
    pub size: usize,
    /// `size`^3 display values (display-encoded, not clamped, rounded to 16-bit floats), red fastest.
    pub texels: Vec<[f32; 4]>,
}

impl ViewLut {
    /// Evaluates `view` at every node of a cube of `size` nodes a side (`size` is raised to 2 at least).
    pub fn bake(view: &ViewTransform, size: usize) -> Self {
        let size = size.max(2);
        let values: Vec<f32> = (0..size).map(|i| node_value(i, size)).collect();
        let mut texels: Vec<[f32; 4]> = Vec::with_capacity(size * size * size);
        for b in &values {
            for g in &values {
                for r in &values {
                    texels.push([*r, *g, *b, 1.0]);
                }
            }
        }
        view.apply_rgba(&mut texels);
        for t in &mut texels {
            // What the GPU's texture holds: a 16-bit float, finite (a value beyond f16's range, from a view of
            // some config that leaves light unbounded, clamped to it).
            *t = t.map(|v| crate::image::finite_half(v).to_f32());
            t[3] = 1.0;
        }
        Self { key: view.key, size, texels }
    }

    /// The cube of `view` at [`SIZE`], baked once and kept among the last few views (baked here, without
    /// waiting, when a bake [`Self::ready_or_bake`] started has not finished).
    pub fn cached(view: &ViewTransform) -> Arc<Self> {
        if let Some(hit) = CACHE.lock().ok().and_then(|c| c.find(view.key)) {
            return hit;
        }
        keep(Arc::new(Self::bake(view, SIZE)))
    }

    /// The cube of `view` if it is baked; if not, `None` at once, and the bake starts on a thread of its own
    /// (one per view): what a draft asks for, so that no draft waits on a bake.
    pub fn ready_or_bake(view: &Arc<ViewTransform>) -> Option<Arc<Self>> {
        let mut cache = CACHE.lock().ok()?;
        if let Some(hit) = cache.find(view.key) {
            return Some(hit);
        }
        if !cache.baking.contains(&view.key) {
            cache.baking.push(view.key);
            let view = view.clone();
            std::thread::spawn(move || keep(Arc::new(Self::bake(&view, SIZE))));
        }
        None
    }

    fn texel(&self, r: usize, g: usize, b: usize) -> [f32; 4] {
        self.texels[r + self.size * (g + self.size * b)]
    }

    /// The display value of one working-space colour looked up in the cube: the CPU twin of `ocio_display`
    /// in `shaders/ocio_lut.wgsl` (the same shaper, and the trilinear filter its sampler applies, in f32).
    pub fn apply(&self, rgb: [f32; 3]) -> [f32; 3] {
        let last = (self.size - 1) as f32;
        let mut base = [0usize; 3];
        let mut frac = [0f32; 3];
        for c in 0..3 {
            let at = shape(rgb[c]).clamp(0.0, 1.0) * last;
            let i = at.floor().min(last - 1.0);
            base[c] = i as usize;
            frac[c] = at - i;
        }
        let [r, g, b] = base;
        let [fr, fg, fb] = frac;
        let lerp = |a: [f32; 4], b: [f32; 4], t: f32| -> [f32; 4] { std::array::from_fn(|k| a[k] + (b[k] - a[k]) * t) };
        let c00 = lerp(self.texel(r, g, b), self.texel(r + 1, g, b), fr);
        let c10 = lerp(self.texel(r, g + 1, b), self.texel(r + 1, g + 1, b), fr);
        let c01 = lerp(self.texel(r, g, b + 1), self.texel(r + 1, g, b + 1), fr);
        let c11 = lerp(self.texel(r, g + 1, b + 1), self.texel(r + 1, g + 1, b + 1), fr);
        let c = lerp(lerp(c00, c10, fg), lerp(c01, c11, fg), fb);
        [c[0], c[1], c[2]]
    }

    /// The cube as the tonemap's `ocio_display`: `shaders/ocio_lut.wgsl` after its shaper's constants, the
    /// cube a filtered (`Rgba16Float`) 3D texture at `BINDING`, its sampler at `SAMPLER_BINDING`.
    pub fn shader(&self) -> WgslShader {
        let (low, inverse_range) = shaper_constants();
        let text = format!(
            "const VIEW_LUT_OFFSET: f32 = {OFFSET:?};\nconst VIEW_LUT_LOG2_OFFSET: f32 = {low:?};\n\
             const VIEW_LUT_INVERSE_RANGE: f32 = {inverse_range:?};\n{}",
            OCIO_LUT_WGSL
        );
        let side = self.size as u32;
        WgslShader {
            text,
            textures: vec![WgslTexture {
                binding: BINDING,
                dimensions: 3,
                size: [side; 3],
                rgba: true,
                bytes: bytemuck::cast_slice(&self.texels).to_vec(),
                filtered: true,
            }],
            uniforms: None,
            sampler: Some(SAMPLER_BINDING),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shaper_puts_its_nodes_at_their_values() {
        assert_eq!(shape(0.0), 0.0);
        assert!((shape(MAX) - 1.0).abs() < 1e-6, "{}", shape(MAX));
        assert_eq!(shape(-3.0), 0.0);
        for i in [0, 1, 7, 32, 63, 64] {
            let t = shape(node_value(i, 65)) * 64.0;
            assert!((t - i as f32).abs() < 1e-3, "node {i}: {t}");
        }
    }

    #[test]
    fn the_cube_returns_its_nodes_exactly() {
        // A cube of 3 nodes whose texels are their own indices: a node reads back its texel, a point halfway
        // between two nodes the mean of theirs.
        let size = 3;
        let mut texels = Vec::new();
        for b in 0..size {
            for g in 0..size {
                for r in 0..size {
                    texels.push([r as f32, g as f32, b as f32, 1.0]);
                }
            }
        }
        let lut = ViewLut { key: 0, size, texels };
        let node = |i| node_value(i, size);
        assert_eq!(lut.apply([node(0), node(1), node(2)]), [0.0, 1.0, 2.0]);
        assert_eq!(lut.apply([-1.0, f32::MAX, node(2)]), [0.0, 2.0, 2.0]);
        let between =
            lut.apply([0.0, 0.0, ((node(0) + OFFSET).log2() * 0.5 + (node(1) + OFFSET).log2() * 0.5).exp2() - OFFSET]);
        assert!((between[2] - 0.5).abs() < 1e-4, "{between:?}");
    }
}
