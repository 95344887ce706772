// The aperture mask read from a storage buffer (a software rasteriser samples a texture several times slower),
// shared by the compute passes that look it up (prepended to ghosts_compute.wgsl and raygrid_box.wgsl when they
// are embedded). CPU twin: `ApertureMask::sample` in crates/flare_core/src/aperture.rs, the same steps. The
// mask's u8 texels are packed four to a u32 word, row 0 at v = +1; the including shader defines
// `mask_word(w: u32) -> u32`, the w-th word of its packed texels.

// Texel (i, j) of a `size` x `size` mask, clamped to its edge, 0 to 255.
fn mask_texel(i: i32, j: i32, size: u32) -> f32 {
    let last = i32(size) - 1;
    let k = u32(clamp(j, 0, last)) * size + u32(clamp(i, 0, last));
    return f32((mask_word(k >> 2u) >> ((k & 3u) * 8u)) & 255u);
}

// Where a sample at (u, v) in [-1, 1]^2 falls between texel centres: the top-left texel of its four and the
// fractions towards the next column and row.
struct MaskSpot {
    x0: i32,
    y0: i32,
    fx: f32,
    fy: f32,
};

fn mask_spot(u: f32, v: f32, size: u32) -> MaskSpot {
    let n = f32(size);
    let x = (u * 0.5 + 0.5) * n - 0.5;
    let y = (0.5 - v * 0.5) * n - 0.5;
    // x, y >= -0.5: truncating x + 1 floors x.
    let x0 = i32(x + 1.0) - 1;
    let y0 = i32(y + 1.0) - 1;
    return MaskSpot(x0, y0, x - f32(x0), y - f32(y0));
}

// The bilinear mix at `s` of the four texels (0 to 255) top-left, top-right, bottom-left, bottom-right, 0 to 1.
fn mask_mix(t: vec4<f32>, s: MaskSpot) -> f32 {
    let top = t.x * (1.0 - s.fx) + t.y * s.fx;
    let bottom = t.z * (1.0 - s.fx) + t.w * s.fx;
    return (top * (1.0 - s.fy) + bottom * s.fy) / 255.0;
}

// The mask at (u, v) in [-1, 1]^2, 0 outside (and for a NaN): bilinear between texel centres.
fn mask_bilinear(u: f32, v: f32, size: u32) -> f32 {
    if (!(abs(u) <= 1.0 && abs(v) <= 1.0)) {
        return 0.0;
    }
    let s = mask_spot(u, v, size);
    let t = vec4<f32>(
        mask_texel(s.x0, s.y0, size),
        mask_texel(s.x0 + 1, s.y0, size),
        mask_texel(s.x0, s.y0 + 1, size),
        mask_texel(s.x0 + 1, s.y0 + 1, size),
    );
    return mask_mix(t, s);
}
