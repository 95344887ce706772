// The OCIO view baked into a cube (crate::view_lut, which puts the shaper's three constants `VIEW_LUT_OFFSET`,
// `VIEW_LUT_LOG2_OFFSET` and `VIEW_LUT_INVERSE_RANGE` before this file): the tonemap's `ocio_display` for a
// software adapter's drafts. Each channel is shaped (log2 with a linear toe) to its place among the nodes, and
// the cube (Rgba16Float) sampled there through a linear sampler: trilinear between the 8 nodes around the
// colour. CPU twin: `ViewLut::apply` in crates/flare_core/src/view_lut.rs.

@group(1) @binding(1) var view_lut: texture_3d<f32>;
@group(1) @binding(2) var view_lut_sampler: sampler;

fn ocio_display(inPixel: vec4<f32>) -> vec4<f32> {
    let size = f32(textureDimensions(view_lut).x);
    let shaped = (log2(max(inPixel.rgb, vec3<f32>(0.0)) + VIEW_LUT_OFFSET) - VIEW_LUT_LOG2_OFFSET) * VIEW_LUT_INVERSE_RANGE;
    // Node i's texel centre is at (i + 0.5) / size.
    let at = clamp(shaped, vec3<f32>(0.0), vec3<f32>(1.0)) * (size - 1.0);
    return vec4<f32>(textureSampleLevel(view_lut, view_lut_sampler, (at + 0.5) / size, 0.0).rgb, inPixel.a);
}
