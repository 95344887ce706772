// Ray grids on the GPU (Hullin et al. 2011), the declarations both passes share (prepended to
// raygrid_trace.wgsl and raygrid_splat.wgsl when they are embedded): a compute pass traces every grid ray of
// every job (ghost x wavelength) exactly, in f32, along the ghost's path; a raster pass draws each grid cell
// as two triangles, energy conserved, additively.
// CPU twin: crates/flare_core/src/raytrace/ (`RayGridRenderer`, f64, box-filtered splatting); the
// comparison test is in crates/flare_core/tests/raygrid_gpu.rs.
// Must be kept in sync with `GpuStep`, `GpuJob` and `GpuVertex` in crates/flare_core/src/render/raygrid.rs.

struct Step {
    surface: vec4<f32>,    // vertex z (mm), curvature (1/mm), conic, 1 / semi-aperture^2 (0 at the stop)
    optics: vec4<u32>,     // eta = n_in / n_out (f32 bits), offset of the reflectance table in `tables`, flags
                           // (STEP_*), a toroid's x-z curvature (f32 bits)
    terms_lo: vec4<f32>,   // r^2 term, A4, A6, A8 (aspheres and toroids only)
    terms_hi: vec4<f32>,   // A10, A12, A14, A16
};

// `Step.optics.z`: a reflection (else a refraction), the stop, the sphere formulas alone (a sphere or a plane),
// a toroid, arriving backwards (towards -z).
const STEP_REFLECT: u32 = 1u;
const STEP_STOP: u32 = 2u;
const STEP_SPHERE: u32 = 4u;
const STEP_TOROID: u32 = 8u;
const STEP_BACKWARD: u32 = 16u;

struct Job {
    steps: vec4<u32>,      // first step, step count, first vertex, cells across (n)
    region: vec4<f32>,     // x0, y0 of the grid on the entrance plane (mm), cell size x, y (mm)
    direction: vec4<f32>,  // the light's unit direction, sensor plane z (mm)
    view: vec4<f32>,       // window centre x, y (sensor mm), pixels per mm, stop radius (mm)
    frame: vec4<f32>,      // width, height (pixels), stop crossings looked at, irradiance per unit area ratio
    rgb: vec4<f32>,        // the wavelength's RGB weight, the view's turn about the axis (radians, counter-clockwise)
    lit: vec4<f32>,        // the pre-pass grid whose lit cells are traced: corner x, y (mm), cell size x, y (mm)
    lit_cells: vec4<u32>,  // its first entry of lit bits in the tables, cells across (0: no pre-pass, trace every ray), unused x2
};

struct Vertex {
    pixel: vec2<f32>,      // landing point (image pixels)
    ratio: f32,            // largest h / semi-aperture over the surfaces other than the stop
    weight: f32,           // Fresnel and coating reflectance and transmittance along the path
    stop0: vec2<f32>,      // coordinates at each stop crossing (stop radii)
    stop1: vec2<f32>,
    stop2: vec2<f32>,
    valid: u32,            // 1 when the ray reached the sensor, else 0
    pad: f32,
};


// The jobs, and the traced vertices for the box filter, are also laid out as rows of Rgba32Uint texels
// (word_texels.wgsl's `texel_at`).

// Job j of a texture of jobs (8 texels each).
fn job_at(words: texture_2d<u32>, j: u32) -> Job {
    let t = 8u * j;
    return Job(
        texel_at(words, t),
        bitcast<vec4<f32>>(texel_at(words, t + 1u)),
        bitcast<vec4<f32>>(texel_at(words, t + 2u)),
        bitcast<vec4<f32>>(texel_at(words, t + 3u)),
        bitcast<vec4<f32>>(texel_at(words, t + 4u)),
        bitcast<vec4<f32>>(texel_at(words, t + 5u)),
        bitcast<vec4<f32>>(texel_at(words, t + 6u)),
        texel_at(words, t + 7u),
    );
}

// Vertex i of a texture of traced vertices (3 texels each).
fn vertex_at(words: texture_2d<u32>, i: u32) -> Vertex {
    let a = bitcast<vec4<f32>>(texel_at(words, 3u * i));
    let b = bitcast<vec4<f32>>(texel_at(words, 3u * i + 1u));
    let c = bitcast<vec4<f32>>(texel_at(words, 3u * i + 2u));
    return Vertex(a.xy, a.z, a.w, b.xy, b.zw, c.xy, bitcast<u32>(c.z), c.w);
}
