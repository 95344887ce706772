// The OCIO view baked into a cube (crate::view_lut, which puts the shaper's three constants `VIEW_LUT_OFFSET`,
// `VIEW_LUT_LOG2_OFFSET` and `VIEW_LUT_INVERSE_RANGE` before this file): the tonemap's `ocio_display` for a
// software adapter's drafts. Each channel is shaped (log2 with a linear toe), the 8 nodes around the colour are
// read by textureLoad and blended trilinearly. CPU twin: `ViewLut::apply` in crates/flare_core/src/view_lut.rs.

@group(1) @binding(1) var view_lut: texture_3d<f32>;

fn ocio_display(inPixel: vec4<f32>) -> vec4<f32> {
    let last = f32(textureDimensions(view_lut).x - 1u);
    let shaped = (log2(max(inPixel.rgb, vec3<f32>(0.0)) + VIEW_LUT_OFFSET) - VIEW_LUT_LOG2_OFFSET) * VIEW_LUT_INVERSE_RANGE;
    let at = clamp(shaped, vec3<f32>(0.0), vec3<f32>(1.0)) * last;
    let base = min(floor(at), vec3<f32>(last - 1.0));
    let f = at - base;
    let i = vec3<i32>(base);
    let c000 = textureLoad(view_lut, i, 0);
    let c100 = textureLoad(view_lut, i + vec3<i32>(1, 0, 0), 0);
    let c010 = textureLoad(view_lut, i + vec3<i32>(0, 1, 0), 0);
    let c110 = textureLoad(view_lut, i + vec3<i32>(1, 1, 0), 0);
    let c001 = textureLoad(view_lut, i + vec3<i32>(0, 0, 1), 0);
    let c101 = textureLoad(view_lut, i + vec3<i32>(1, 0, 1), 0);
    let c011 = textureLoad(view_lut, i + vec3<i32>(0, 1, 1), 0);
    let c111 = textureLoad(view_lut, i + vec3<i32>(1, 1, 1), 0);
    let c00 = c000 + (c100 - c000) * f.x;
    let c10 = c010 + (c110 - c010) * f.x;
    let c01 = c001 + (c101 - c001) * f.x;
    let c11 = c011 + (c111 - c011) * f.x;
    let c0 = c00 + (c10 - c00) * f.y;
    let c1 = c01 + (c11 - c01) * f.y;
    return vec4<f32>((c0 + (c1 - c0) * f.z).rgb, inPixel.a);
}
