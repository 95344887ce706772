// A triangle covering the whole target, for the passes that draw every pixel (`dirt.wgsl`, `lut_runs.wgsl`):
// corner `vertex` (0, 1, 2) in units of the target's size, (0, 0), (2, 0) and (0, 2), so that the triangle's inside
// holds the target (0..1 on each axis), and its clip-space position (y down in the target, up in clip space).

fn fullscreen_corner(vertex: u32) -> vec2<f32> {
    var corners = array<vec2<f32>, 3>(vec2<f32>(0.0, 0.0), vec2<f32>(2.0, 0.0), vec2<f32>(0.0, 2.0));
    return corners[vertex];
}

fn fullscreen_clip(q: vec2<f32>) -> vec4<f32> {
    return vec4<f32>(q.x * 2.0 - 1.0, 1.0 - q.y * 2.0, 0.0, 1.0);
}
