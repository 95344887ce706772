// 64-bit fixed point in two u32 words (low, high; two's complement), shared by the passes that sum light with
// integer atomics so that the order in which it lands does not matter (prepended to ghosts_compute.wgsl and
// raygrid_box.wgsl when they are embedded). CPU side: the unit is chosen per frame in
// crates/flare_core/src/render/gpu_ghosts.rs and raygrid.rs.

// v rounded to the nearest integer, as 64 bits: exact for every f32 (each step below is).
fn fixed(v: f32) -> vec2<u32> {
    let r = round(v);
    if (abs(r) < 2147483648.0) {
        let i = i32(r);
        return vec2<u32>(bitcast<u32>(i), select(0u, 0xffffffffu, i < 0));
    }
    // |r| >= 2^31: a multiple of 2^8 at least; both steps are exact.
    let hi = floor(r / 4294967296.0);
    return vec2<u32>(u32(r - hi * 4294967296.0), bitcast<u32>(i32(hi)));
}

fn add64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let lo = a.x + b.x;
    return vec2<u32>(lo, a.y + b.y + select(0u, 1u, lo < a.x));
}

fn sub64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    return vec2<u32>(a.x - b.x, a.y - b.y - select(0u, 1u, a.x < b.x));
}

// The 64-bit value as a float (rounded), before its unit is applied.
fn float64(v: vec2<u32>) -> f32 {
    return f32(bitcast<i32>(v.y)) * 4294967296.0 + f32(v.x);
}
