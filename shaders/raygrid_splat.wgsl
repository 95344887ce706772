// Ray grids on the GPU, pass 2: one draw per frame, instance = job, 6 vertices per grid cell (its two
// triangles), each carrying its flux over its footprint, the aperture mask looked up per pixel at every stop
// crossing, additive. CPU twin: `splat_triangle` in crates/flare_core/src/raytrace/splat.rs, which box-filters
// (clips each triangle to the pixels it covers) where this samples pixel centres. The declarations come from
// raygrid_common.wgsl.

@group(0) @binding(0) var<storage, read> grid: array<Vertex>;
@group(0) @binding(1) var<storage, read> raster_jobs: array<Job>;
@group(0) @binding(2) var aperture_texture: texture_2d<f32>;
@group(0) @binding(3) var aperture_sampler: sampler;

struct SplatOut {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(linear) stop0: vec2<f32>,
    @location(1) @interpolate(linear) stop1: vec2<f32>,
    @location(2) @interpolate(linear) stop2: vec2<f32>,
    @location(3) @interpolate(linear) ratio_weight: vec2<f32>,
    @location(4) @interpolate(flat) colour: vec4<f32>, // rgb x irradiance, stop crossings looked at
};

@vertex
fn vs_splat(@builtin(vertex_index) index: u32, @builtin(instance_index) job_index: u32) -> SplatOut {
    let job = raster_jobs[job_index];
    let n = job.steps.w;
    let cell = index / 6u;
    let corner = index % 6u;
    var out: SplatOut;
    out.position = vec4<f32>(2.0, 2.0, 2.0, 1.0); // off screen: the triangle is dropped
    if (cell >= n * n) {
        return out;
    }
    let ix = cell % n;
    let iy = cell / n;
    let row = n + 1u;
    let base = job.steps.z;
    let v00 = base + iy * row + ix;
    let v10 = v00 + 1u;
    let v01 = v00 + row;
    let v11 = v01 + 1u;
    // The CPU's triangles: (v00, v10, v11) and (v00, v11, v01).
    var second = v10;
    var third = v11;
    if (corner >= 3u) {
        second = v11;
        third = v01;
    }
    let a = grid[v00];
    let b = grid[second];
    let c = grid[third];
    if (a.valid == 0u || b.valid == 0u || c.valid == 0u || (a.ratio > 1.0 && b.ratio > 1.0 && c.ratio > 1.0)) {
        return out;
    }
    let area = 0.5 * abs((b.pixel.x - a.pixel.x) * (c.pixel.y - a.pixel.y) - (b.pixel.y - a.pixel.y) * (c.pixel.x - a.pixel.x));
    if (!(area > 1e-6)) {
        return out;
    }
    var me = a;
    let which = corner % 3u;
    if (which == 1u) {
        me = b;
    } else if (which == 2u) {
        me = c;
    }
    // Irradiance: the triangle's flux (frame.w is cos(theta) x its entrance area over the pixel area in mm^2)
    // over its footprint in pixels.
    let irradiance = job.frame.w / area;
    out.position = vec4<f32>(me.pixel.x / job.frame.x * 2.0 - 1.0, 1.0 - me.pixel.y / job.frame.y * 2.0, 0.0, 1.0);
    out.stop0 = me.stop0;
    out.stop1 = me.stop1;
    out.stop2 = me.stop2;
    out.ratio_weight = vec2<f32>(me.ratio, me.weight);
    out.colour = vec4<f32>(job.rgb.rgb * irradiance, job.frame.z);
    return out;
}

@fragment
fn fs_splat(in: SplatOut) -> @location(0) vec4<f32> {
    if (in.ratio_weight.x > 1.0) {
        discard;
    }
    var m = max(in.ratio_weight.y, 0.0);
    let crossings = u32(in.colour.w + 0.5);
    m = m * aperture_at(in.stop0);
    if (crossings > 1u) {
        m = m * aperture_at(in.stop1);
    }
    if (crossings > 2u) {
        m = m * aperture_at(in.stop2);
    }
    return vec4<f32>(in.colour.rgb * m, 0.0);
}
