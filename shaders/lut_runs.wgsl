// LUT ghosts composited through alpha where the LUT layer is rasterised (`lut_ghosts.wgsl`): one run of a LUT
// ghost's instances (its interpolated entries, and under motion blur its time samples) is first drawn into a scratch
// image of the accumulation's size, cleared to colour 0 and alpha 1: colour added (S) and each instance's coverage
// subtracted from the alpha, which leaves what the run lets through, 1 - a. This pass then lays it over the
// accumulation once (blend One, OneMinusSrcAlpha): `p = S + clamp(1 - a, 0, 1) p`. CPU twin:
// crates/flare_core/src/lut/blend.rs, `composite_runs`; the compute form: `lut_tiles` in `lut_compute.wgsl`.

@group(0) @binding(0) var run_sum: texture_2d<f32>;

struct VertexOut {
    @builtin(position) position: vec4<f32>,
};

// A triangle covering the target.
@vertex
fn vs_main(@builtin(vertex_index) vertex: u32) -> VertexOut {
    var out: VertexOut;
    out.position = fullscreen_clip(fullscreen_corner(vertex));
    return out;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    let s = textureLoad(run_sum, vec2<i32>(in.position.xy), 0);
    // The alpha the blend takes: what the run hides.
    return vec4<f32>(s.rgb, 1.0 - clamp(s.a, 0.0, 1.0));
}
