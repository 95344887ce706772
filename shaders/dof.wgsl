// The live depth of field, one layer at a time, far first: split, gather, composite; then resolve.
// CPU twin, step for step: crates/flare_core/src/dof/live.rs (`LivePlan::split`, `gather`, `composite`,
// `super::over`, `super::resolve`). The plan (layers, taps, normalisation) is made on the CPU.

// Must be kept in sync with `LiveLayer` in crates/flare_core/src/dof/live.rs.
struct Layer {
    // frame width, height; layer width, height (texels)
    size: vec4<u32>,
    // first tap, tap count, factor (pixels per texel), first normalisation node
    taps: vec4<u32>,
    // texels the split can fill: x0, y0, x1, y1 (ends excluded)
    low: vec4<u32>,
    // texels the gathered light can reach
    out: vec4<u32>,
    // pixels the composite covers (from `live::composite_pixels`)
    pixels: vec4<u32>,
    // layer defocus, spacing, lowest and highest layer defocus
    shape: vec4<f32>,
    // the cat's eye: up to 4 clear apertures' circles, each centre at pixel (x, y) (c0x + cx x, c0y + cy y) as
    // c0x, cx, c0y, cy
    cat: array<vec4<f32>, 4>,
    // each circle's radius (pupil radii; 0: an empty slot)
    cat_radius: vec4<f32>,
    // each circle's x scale (1 for a lens of revolution; an anamorphic lens's regions are ellipses)
    cat_x_scale: vec4<f32>,
    // circles in use
    cat_count: u32,
    // the circles' soft edge (pupil radii)
    cat_edge: f32,
    // 1 when the cat's eye is on, else 0
    cat_on: u32,
    _pad0: u32,
    // pupil radii per pixel of offset along x and along y (2 / sigma of each axis, signed), unused, unused
    pupil: vec4<f32>,
}

const NORM_CELLS: u32 = 16u;

@group(0) @binding(0) var<uniform> layer: Layer;
@group(0) @binding(1) var<storage, read> plate: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> sigma: array<f32>;
@group(0) @binding(3) var<storage, read_write> low: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> gathered: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> composite_out: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read> taps: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read> norm: array<f32>;

// The hat weight of defocus s in this layer (twin: `live::hat`).
fn hat(s_in: f32) -> f32 {
    let s = clamp(s_in, layer.shape.z, layer.shape.w);
    if (layer.shape.y <= 0.0) {
        return 1.0;
    }
    return max(1.0 - abs(s - layer.shape.x) / layer.shape.y, 0.0);
}

// The tent weight of pixel p for texel t (twin: the `tent` closure of `LivePlan::split`).
fn tent(p: u32, t: u32, f: f32) -> f32 {
    return max(1.0 - abs((f32(p) + 0.5) - (f32(t) + 0.5) * f) / f, 0.0);
}

@compute @workgroup_size(8, 8, 1)
fn split(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = layer.size.x;
    let h = layer.size.y;
    let lw = layer.size.z;
    let id = vec2<u32>(gid.x + layer.low.x, gid.y + layer.low.y);
    if (id.x >= layer.low.z || id.y >= layer.low.w) {
        return;
    }
    let f = layer.taps.z;
    let ff = f32(f);
    var acc = vec4<f32>(0.0);
    let y0 = select(0u, id.y * f - f, id.y * f >= f);
    let x0 = select(0u, id.x * f - f, id.x * f >= f);
    let y1 = min((id.y + 2u) * f, h);
    let x1 = min((id.x + 2u) * f, w);
    for (var y = y0; y < y1; y++) {
        let wy = tent(y, id.y, ff);
        if (wy == 0.0) {
            continue;
        }
        for (var x = x0; x < x1; x++) {
            let i = y * w + x;
            let wgt = hat(sigma[i]) * wy * tent(x, id.x, ff);
            if (wgt > 0.0) {
                let p = plate[i];
                acc = vec4<f32>(acc.x + p.x * wgt, acc.y + p.y * wgt, acc.z + p.z * wgt, acc.w + wgt);
            }
        }
    }
    low[id.y * lw + id.x] = acc * (1.0 / (ff * ff));
}

// The cat's eye factor of a tap at pupil point q from a source at pixel (x, y) (twin: `live::cat_factor`).
fn cat_factor(q: vec2<f32>, x: f32, y: f32) -> f32 {
    if (layer.cat_on == 0u) {
        return 1.0;
    }
    var m = 1.0;
    for (var k = 0u; k < 4u; k = k + 1u) {
        let radius = layer.cat_radius[k];
        if (radius == 0.0) {
            continue;
        }
        let cat = layer.cat[k];
        let c = vec2<f32>(cat.x + cat.y * x, cat.z + cat.w * y);
        let qx = q.x * layer.cat_x_scale[k];
        let d = sqrt((qx - c.x) * (qx - c.x) + (q.y - c.y) * (q.y - c.y));
        m = m * clamp(0.5 + (radius - d) / layer.cat_edge, 0.0, 1.0);
    }
    return m;
}

// The normalisation at pixel (x, y) (twin: `live::norm_at`).
fn norm_at(x: f32, y: f32) -> f32 {
    if (layer.cat_on == 0u) {
        return norm[layer.taps.w];
    }
    let n = f32(NORM_CELLS);
    let gx = clamp(x / f32(layer.size.x) * n, 0.0, n);
    let gy = clamp(y / f32(layer.size.y) * n, 0.0, n);
    let ix = min(u32(gx), NORM_CELLS - 1u);
    let iy = min(u32(gy), NORM_CELLS - 1u);
    let fx = gx - f32(ix);
    let fy = gy - f32(iy);
    let base = layer.taps.w;
    let row = NORM_CELLS + 1u;
    let top = norm[base + iy * row + ix] * (1.0 - fx) + norm[base + iy * row + ix + 1u] * fx;
    let bottom = norm[base + (iy + 1u) * row + ix] * (1.0 - fx) + norm[base + (iy + 1u) * row + ix + 1u] * fx;
    return top * (1.0 - fy) + bottom * fy;
}

@compute @workgroup_size(8, 8, 1)
fn gather(@builtin(global_invocation_id) gid: vec3<u32>) {
    let lw = i32(layer.size.z);
    let id = vec2<u32>(gid.x + layer.out.x, gid.y + layer.out.y);
    if (id.x >= layer.out.z || id.y >= layer.out.w) {
        return;
    }
    let x = i32(id.x);
    let y = i32(id.y);
    let lo = vec4<i32>(layer.low);
    let f = f32(layer.taps.z);
    let kx = layer.pupil.x * f;
    let ky = layer.pupil.y * f;
    var acc = vec4<f32>(0.0);
    for (var t = 0u; t < layer.taps.y; t++) {
        let tap = taps[layer.taps.x + t];
        let sx = x - i32(tap.x);
        let sy = y - i32(tap.y);
        if (sx < lo.x || sy < lo.y || sx >= lo.z || sy >= lo.w) {
            continue;
        }
        let src = low[sy * lw + sx];
        if (src.w == 0.0) {
            continue;
        }
        let px = (f32(sx) + 0.5) * f;
        let py = (f32(sy) + 0.5) * f;
        let q = vec2<f32>(tap.x * kx, -tap.y * ky);
        let wgt = tap.z * cat_factor(q, px, py) * norm_at(px, py);
        acc = vec4<f32>(acc.x + src.x * wgt, acc.y + src.y * wgt, acc.z + src.z * wgt, acc.w + src.w * wgt);
    }
    gathered[id.y * layer.size.z + id.x] = acc;
}

// A gathered texel, zero outside the layer's `out` region.
fn gathered_at(i: u32, j: u32) -> vec4<f32> {
    if (i < layer.out.x || j < layer.out.y || i >= layer.out.z || j >= layer.out.w) {
        return vec4<f32>(0.0);
    }
    return gathered[j * layer.size.z + i];
}

// Bilinear sample of the gathered layer at texel coordinates (x, y), clamped (twin: `live::sample_bilinear`).
fn sample_gathered(x_in: f32, y_in: f32) -> vec4<f32> {
    let w = layer.size.z;
    let h = layer.size.w;
    let x = clamp(x_in, 0.0, f32(w - 1u));
    let y = clamp(y_in, 0.0, f32(h - 1u));
    let x0 = u32(x);
    let y0 = u32(y);
    let x1 = min(x0 + 1u, w - 1u);
    let y1 = min(y0 + 1u, h - 1u);
    let fx = x - f32(x0);
    let fy = y - f32(y0);
    let top = gathered_at(x0, y0) * (1.0 - fx) + gathered_at(x1, y0) * fx;
    let bottom = gathered_at(x0, y1) * (1.0 - fx) + gathered_at(x1, y1) * fx;
    return top * (1.0 - fy) + bottom * fy;
}

@compute @workgroup_size(8, 8, 1)
fn composite(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = layer.size.x;
    let id = vec2<u32>(gid.x + layer.pixels.x, gid.y + layer.pixels.y);
    if (id.x >= layer.pixels.z || id.y >= layer.pixels.w) {
        return;
    }
    let f = f32(layer.taps.z);
    let s = sample_gathered((f32(id.x) + 0.5) / f - 0.5, (f32(id.y) + 0.5) / f - 0.5);
    if (s.w > 0.0 || s.x != 0.0 || s.y != 0.0 || s.z != 0.0) {
        let i = id.y * w + id.x;
        let o = composite_out[i];
        let a = min(s.w, 1.0);
        let keep = 1.0 - a;
        composite_out[i] = vec4<f32>(s.x + keep * o.x, s.y + keep * o.y, s.z + keep * o.z, a + keep * o.w);
    }
}

@compute @workgroup_size(8, 8, 1)
fn resolve(@builtin(global_invocation_id) id: vec3<u32>) {
    let w = layer.size.x;
    if (id.x >= w || id.y >= layer.size.y) {
        return;
    }
    let i = id.y * w + id.x;
    let o = composite_out[i];
    if (o.w > 1e-6) {
        composite_out[i] = vec4<f32>(o.x / o.w, o.y / o.w, o.z / o.w, 1.0);
    } else {
        composite_out[i] = vec4<f32>(0.0, 0.0, 0.0, 1.0);
    }
}
