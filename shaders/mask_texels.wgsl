// The aperture mask looked up one word a bilinear footprint (a software rasteriser samples a texture several
// times slower), shared by the compute passes that look it up (prepended to ghosts_compute.wgsl and
// raygrid_box.wgsl when they are embedded). CPU twin: `ApertureMask::sample` in
// crates/flare_core/src/aperture.rs, the same steps. The words are `ApertureMask::quad_words`: each bilinear
// footprint's four u8 texels (clamped to the edge, row 0 at v = +1) in one word, so that a lookup is one load;
// the including shader defines `mask_quad(w: u32) -> u32`, the w-th word of what it binds (from a storage buffer
// or a texture of words, word_texels.wgsl), the footprints of a mask starting at its word `start`.

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
fn mask_bilinear(u: f32, v: f32, size: u32, start: u32) -> f32 {
    if (!(abs(u) <= 1.0 && abs(v) <= 1.0)) {
        return 0.0;
    }
    let s = mask_spot(u, v, size);
    // |u|, |v| <= 1 keeps x0 and y0 in -1..size; clamped all the same, as the CPU clamps each texel.
    let x = u32(clamp(s.x0, -1, i32(size) - 1) + 1);
    let y = u32(clamp(s.y0, -1, i32(size) - 1) + 1);
    let q = mask_quad(start + y * (size + 1u) + x);
    let t = vec4<f32>(vec4<u32>(q & 255u, (q >> 8u) & 255u, (q >> 16u) & 255u, q >> 24u));
    return mask_mix(t, s);
}
