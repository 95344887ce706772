// The aperture mask, shared by the passes that look it up (prepended to ghosts.wgsl and raygrid_splat.wgsl when
// they are embedded; each declares `aperture_texture` and `aperture_sampler`). CPU twin:
// `ApertureMask::sample` in crates/flare_core/src/aperture.rs.

// The aperture mask at uv in [-1, 1]^2 (v up), 0 outside.
fn aperture_at(uv: vec2<f32>) -> f32 {
    return aperture_in(aperture_texture, uv);
}

// `aperture_at` in `mask`, a mask of any size (the ghosts' finer levels).
fn aperture_in(mask: texture_2d<f32>, uv: vec2<f32>) -> f32 {
    if (abs(uv.x) > 1.0 || abs(uv.y) > 1.0) {
        return 0.0;
    }
    let tex = vec2<f32>(uv.x * 0.5 + 0.5, 0.5 - uv.y * 0.5);
    return textureSampleLevel(mask, aperture_sampler, tex, 0.0).r;
}
