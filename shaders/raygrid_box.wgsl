// Ray grids on the GPU, pass 2 as compute: each grid triangle box-filtered as the CPU twin does it
// (`splat_triangle` in crates/flare_core/src/raytrace/splat.rs): each pixel the triangle touches gets the
// triangle's irradiance x the area it covers of the pixel, shaded at the centroid of that part; the pixels a row
// covers whole are shaded at their centres. Each part's area and centroid come in closed form from the
// triangle's edges (`band_part`; the CPU's `Band::part`, the same steps in f64), without per-invocation arrays
// or data-dependent loops over vertices. No supersampling: the box filter is exact.
// Per row, the span where the shading can be non-zero and the span where it is surely the weight alone (not
// vignetted, every stop crossing where the mask is fully open) come in closed form (`row_spans`): pixels outside
// the first get nothing and no work; in the second no mask is looked up, and a run of whole pixels there, whose
// shading is linear in x, goes in as four second differences per channel (`add_linear`) whatever its length.
// Energy goes into per-pixel 64-bit fixed-point sums (two u32 words added with carry by atomics), direct and
// second differences apart, so the image does not depend on the order in which triangles land: the same bytes
// on every run. `resolve_box` sums each row's second differences twice, adds the direct sums, turns them into
// floats and clears them. Optional work is written as loops of zero or more passes rather than branches
// (`shade_with`, `add`, `add_linear`, `row_spans`): a software rasteriser (lavapipe) runs both sides of every
// branch for all lanes, but skips a loop that no lane enters. The declarations come from raygrid_common.wgsl,
// the fixed-point helpers from fixed64.wgsl, the mask lookup (a storage buffer, filtered as
// `ApertureMask::sample` does) from mask_texels.wgsl. Must be kept in sync with `BoxParams` in
// crates/flare_core/src/render/raygrid.rs.

struct BoxParams {
    width: u32,           // the frame (pixels)
    height: u32,
    jobs: u32,            // jobs in this batch
    first_row: u32,       // the strip of rows this dispatch adds into and resolves
    rows: u32,
    groups_x: u32,        // workgroups along x of `resolve_box`
    mask_size: u32,       // texels across the aperture mask
    job_stride: u32,      // workgroup x draws job (x * job_stride) mod jobs (`spread_stride` in buffers.rs)
    fixed_per_unit: f32,  // fixed-point units per unit of irradiance, and its inverse
    unit_per_fixed: f32,
    open_radius2: f32,    // the square of the radius (stop radii) within which the mask is fully open
    support_radius2: f32, // the square of the radius beyond which the mask is 0
};

// The traced vertices and the jobs as texels (`vertex_at`, `job_at`).
@group(0) @binding(0) var grid: texture_2d<u32>;
@group(0) @binding(1) var box_jobs: texture_2d<u32>;
// The aperture mask's bilinear footprints, four u8 texels a word (`ApertureMask::quad_words`, mask_texels.wgsl),
// as texels of four words (`texel_at`).
@group(0) @binding(2) var mask_texels: texture_2d<u32>;
@group(0) @binding(3) var<uniform> box_params: BoxParams;
// Per pixel of the strip, 12 words: R, G, B as 64-bit sums (low word, high word), then R, G, B as 64-bit second
// differences along the row (the linear runs); all zero between strips.
@group(0) @binding(4) var<storage, read_write> sums: array<atomic<u32>>;
@group(0) @binding(5) var resolved: texture_storage_2d<rgba32float, write>;

// ---- the shading planes (Interpolator, TriangleShader) ----

struct Plane {
    a0: f32,
    ax: f32,
    ay: f32,
};

fn at_plane(p: Plane, x: vec2<f32>) -> f32 {
    return p.a0 + p.ax * x.x + p.ay * x.y;
}

struct Shader {
    ratio: Plane,
    weight: Plane,
    s0u: Plane,
    s0v: Plane,
    s1u: Plane,
    s1v: Plane,
    s2u: Plane,
    s2v: Plane,
    open: bool,
    crossings: u32,
};

fn mask_quad(w: u32) -> u32 {
    return texel_at(mask_texels, w / 4u)[w % 4u];
}

fn mask_at(u: f32, v: f32) -> f32 {
    return mask_bilinear(u, v, box_params.mask_size, 0u);
}

// The planes of crossing k's stop point: u in the first, v in the second.
struct StopPlanes {
    u: Plane,
    v: Plane,
};

fn stop_planes(s: Shader, k: u32) -> StopPlanes {
    if (k == 1u) {
        return StopPlanes(s.s1u, s.s1v);
    }
    if (k == 2u) {
        return StopPlanes(s.s2u, s.s2v);
    }
    return StopPlanes(s.s0u, s.s0v);
}

// The stop point of crossing k at the pixel position p.
fn stop_at(s: Shader, k: u32, p: vec2<f32>) -> vec2<f32> {
    let st = stop_planes(s, k);
    return vec2<f32>(at_plane(st.u, p), at_plane(st.v, p));
}

// Weight x the masks of the first `masks` stop crossings at the pixel position p; 0 where vignetted. The masks
// are a loop, not a branch: a software rasteriser runs both sides of a branch but leaves a loop as soon as no
// lane is in it, so pixels that need no lookup (open triangles, sure spans) skip them.
fn shade_with(s: Shader, p: vec2<f32>, masks: u32) -> f32 {
    if (at_plane(s.ratio, p) > 1.0) {
        return 0.0;
    }
    var m = max(at_plane(s.weight, p), 0.0);
    for (var k = 0u; k < masks && m > 0.0; k = k + 1u) {
        let uv = stop_at(s, k, p);
        m = m * mask_at(uv.x, uv.y);
    }
    return m;
}

fn shade(s: Shader, p: vec2<f32>) -> f32 {
    return shade_with(s, p, select(s.crossings, 0u, s.open));
}

// ---- the part of a triangle in one pixel, in closed form ----
//
// The area and centroid of the triangle's part in a pixel come from its three edges by Green's theorem, without
// cutting (the CPU twin's `Band` in splat.rs, in f64): with G(x) = clamp(x, 0, 1) in the pixel's own unit square,
//   area         = sum over edges of  integral G(x_e(y)) dy
//   area x cx    = sum over edges of  integral G(x_e(y))^2 / 2 dy
//   area x cy    = sum over edges of  integral y G(x_e(y)) dy
// each integral over the edge's y clamped to the row, signed by its direction (the sum is the signed area). On
// an edge, G is linear in y between the points where x crosses 0 and 1, so each integral is three trapezoids.
// The three edges go side by side in vec3s; what does not depend on the pixel (the edges cut to the row) is
// done once a row (`band_of`), the rest per pixel (`band_part`). No loop and no array, the same steps in every
// pixel: what a SIMD software rasteriser (lavapipe) and a GPU both run well.

// The triangle's three edges cut to the band of rows [y, y + 1] (edge i in component i): the ends' heights
// relative to the row (clamped to [0, 1]), the x at the first end (frame pixels), the x run to the second and
// its inverse (0 for a vertical part).
struct Band {
    ya: vec3<f32>,
    yb: vec3<f32>,
    xa: vec3<f32>,
    dx: vec3<f32>,
    inv: vec3<f32>,
};

fn band_of(a: vec2<f32>, b: vec2<f32>, c: vec2<f32>, y: f32) -> Band {
    let px = vec3<f32>(a.x, b.x, c.x);
    let py = vec3<f32>(a.y, b.y, c.y) - y;
    let qx = vec3<f32>(b.x, c.x, a.x);
    let qy = vec3<f32>(b.y, c.y, a.y) - y;
    let dy = qy - py;
    let k = select((qx - px) / dy, vec3<f32>(0.0), dy == vec3<f32>(0.0));
    var band: Band;
    band.ya = clamp(py, vec3<f32>(0.0), vec3<f32>(1.0));
    band.yb = clamp(qy, vec3<f32>(0.0), vec3<f32>(1.0));
    band.xa = px + (band.ya - py) * k;
    band.dx = px + (band.yb - py) * k - band.xa;
    band.inv = select(1.0 / band.dx, vec3<f32>(0.0), band.dx == vec3<f32>(0.0));
    return band;
}

// Area (px^2) in x and the centroid (frame pixels) in yz of the triangle's part in pixel (x, y) of the band's
// row; `sign` makes the area positive for the triangle's winding.
fn band_part(band: Band, x: f32, y: f32, sign: f32) -> vec3<f32> {
    let zero = vec3<f32>(0.0);
    let one = vec3<f32>(1.0);
    let xa = band.xa - x;
    let t0 = clamp(-xa * band.inv, zero, one);
    let t1 = clamp((one - xa) * band.inv, zero, one);
    let tl = min(t0, t1);
    let th = max(t0, t1);
    let y1 = band.ya + tl * (band.yb - band.ya);
    let y2 = band.ya + th * (band.yb - band.ya);
    let g0 = clamp(xa, zero, one);
    let g1 = clamp(xa + tl * band.dx, zero, one);
    let g2 = clamp(xa + th * band.dx, zero, one);
    let g3 = clamp(xa + band.dx, zero, one);
    // Per edge, its three segments (y_i, g_i) -> (y_i+1, g_i+1) at t = 0, tl, th, 1, each a trapezoid.
    let d0 = y1 - band.ya;
    let d1 = y2 - y1;
    let d2 = band.yb - y2;
    let area = d0 * (g0 + g1) + d1 * (g1 + g2) + d2 * (g2 + g3);
    let mx = d0 * (g0 * g0 + g0 * g1 + g1 * g1) + d1 * (g1 * g1 + g1 * g2 + g2 * g2) + d2 * (g2 * g2 + g2 * g3 + g3 * g3);
    let my = d0 * (band.ya * (2.0 * g0 + g1) + y1 * (g0 + 2.0 * g1)) + d1 * (y1 * (2.0 * g1 + g2) + y2 * (g1 + 2.0 * g2))
        + d2 * (y2 * (2.0 * g2 + g3) + band.yb * (g2 + 2.0 * g3));
    let m = sign * vec3<f32>(0.5 * dot(area, one), dot(mx, one) / 6.0, dot(my, one) / 6.0);
    if (!(m.x > 0.0)) {
        return vec3<f32>(0.0);
    }
    let o = vec2<f32>(x, y);
    return vec3<f32>(m.x, o + m.yz / m.x);
}

// The x extent of the triangle's section by the line at height h: (min, max), empty (min > max) when the line
// misses it.
fn section(a: vec2<f32>, b: vec2<f32>, c: vec2<f32>, h: f32) -> vec2<f32> {
    var s = vec2<f32>(3.0e38, -3.0e38);
    let p = array<vec2<f32>, 3>(a, b, c);
    for (var i = 0u; i < 3u; i = i + 1u) {
        let u = p[i];
        let v = p[(i + 1u) % 3u];
        let crosses = min(u.y, v.y) <= h && h <= max(u.y, v.y) && u.y != v.y;
        let x = u.x + (h - u.y) * (v.x - u.x) / select(1.0, v.y - u.y, u.y != v.y);
        s = select(s, vec2<f32>(min(s.x, x), max(s.y, x)), crosses);
    }
    return s;
}

// ---- 64-bit fixed point (fixed64.wgsl): the atomic sum ----

fn atomic_add64(word: u32, v: vec2<u32>) {
    let old = atomicAdd(&sums[word], v.x);
    // The high word only when it changes: most values fit the low word and carry nothing.
    let high = v.y + select(0u, 1u, old + v.x < old);
    if (high != 0u) {
        atomicAdd(&sums[word + 1u], high);
    }
}

// Adds `energy` (irradiance x pixel area, before the colour) at pixel (x, y) when it lies in the frame.
// Only the strip's rows are kept: a frame whose sums do not fit one buffer is drawn a strip at a time.
// (The channels are a loop of 0 or 3, not a branch: see `shade_with`.)
fn add(x: f32, y: f32, energy: f32, rgb: vec3<f32>) {
    let first = f32(box_params.first_row);
    let inside = x >= 0.0 && y >= first && x < f32(box_params.width) && y < first + f32(box_params.rows) && energy > 0.0;
    let word = select(0u, ((u32(max(y, first)) - box_params.first_row) * box_params.width + u32(max(x, 0.0))) * WORDS_PER_PIXEL, inside);
    let value = rgb * (energy * box_params.fixed_per_unit);
    for (var c = 0u; c < select(0u, 3u, inside); c = c + 1u) {
        let f = fixed(value[c]);
        if (f.x != 0u || f.y != 0u) {
            atomic_add64(word + 2u * c, f);
        }
    }
}

// Words a pixel of the strip holds: the direct sums (6), then the second differences (6).
const WORDS_PER_PIXEL: u32 = 12u;
// Beyond any pixel coordinate: the ends of an unbounded interval.
const FAR: f32 = 1.0e30;

// v x n modulo 2^64, for 0 <= n < 2^16 (two's complement: right for negative v too).
fn mul64_small(v: vec2<u32>, n: u32) -> vec2<u32> {
    let p0 = (v.x & 0xffffu) * n;
    let p1 = (v.x >> 16u) * n;
    let lo = p0 + (p1 << 16u);
    return vec2<u32>(lo, v.y * n + (p1 >> 16u) + select(0u, 1u, lo < p0));
}

fn neg64(v: vec2<u32>) -> vec2<u32> {
    return sub64(vec2<u32>(0u), v);
}

// Adds the 64-bit `v` to the second differences of channel `c` at pixel `x` of row `y`, when `x` is in the row.
fn add_difference(x: u32, y: f32, c: u32, v: vec2<u32>) {
    if (x >= box_params.width || (v.x == 0u && v.y == 0u)) {
        return;
    }
    atomic_add64(((u32(y) - box_params.first_row) * box_params.width + x) * WORDS_PER_PIXEL + 6u + 2u * c, v);
}

// The pixels x .. x + n - 1 of row y get energy + slope x (x - first) each (before the colour), as four second
// differences per channel: the same sums, whatever the run's length, as adding the pixels one by one (up to the
// rounding of the slope to the fixed-point unit). Nothing when `n` is 0.
fn add_linear(x: f32, n: u32, y: f32, energy: f32, slope: f32, rgb: vec3<f32>) {
    let first = u32(x);
    let value = rgb * (energy * box_params.fixed_per_unit);
    let step = rgb * (slope * box_params.fixed_per_unit);
    for (var c = 0u; c < select(3u, 0u, n == 0u); c = c + 1u) {
        let f = fixed(value[c]);
        let b = select(fixed(step[c]), neg64(fixed(-step[c])), step[c] < 0.0);
        let g = add64(f, mul64_small(b, n - 1u));
        add_difference(first, y, c, f);
        add_difference(first + 1u, y, c, sub64(b, f));
        add_difference(first + n, y, c, neg64(add64(g, b)));
        add_difference(first + n + 1u, y, c, g);
    }
}

// The interval of pixel-centre x (relative to `xm`) where `c0 + cx t < 0`; (FAR, -FAR) when empty.
fn below_zero(c0: f32, cx: f32) -> vec2<f32> {
    if (cx == 0.0) {
        return select(vec2<f32>(FAR, -FAR), vec2<f32>(-FAR, FAR), c0 < 0.0);
    }
    let t = -c0 / cx;
    return select(vec2<f32>(t, FAR), vec2<f32>(-FAR, t), cx > 0.0);
}

// The interval of t where the stop point (u0 + ux t, v0 + vx t) lies within radius^2 `r2`; (FAR, -FAR) when
// empty. The stable root pair of the quadratic.
fn within_radius(u0: f32, ux: f32, v0: f32, vx: f32, r2: f32) -> vec2<f32> {
    let a = ux * ux + vx * vx;
    let b = u0 * ux + v0 * vx;
    let c = u0 * u0 + v0 * v0 - r2;
    if (a < 1.0e-30) {
        return select(vec2<f32>(FAR, -FAR), vec2<f32>(-FAR, FAR), c < 0.0);
    }
    let d = b * b - a * c;
    if (d < 0.0) {
        return vec2<f32>(FAR, -FAR);
    }
    let q = -(b + select(-1.0, 1.0, b >= 0.0) * sqrt(d));
    let t0 = q / a;
    let t1 = select(-t0, c / q, q != 0.0);
    return vec2<f32>(min(t0, t1), max(t0, t1));
}

fn meet(a: vec2<f32>, b: vec2<f32>) -> vec2<f32> {
    return vec2<f32>(max(a.x, b.x), min(a.y, b.y));
}


// Where along row y the triangle's shading can be non-zero (`maybe`) and where it is surely the weight alone
// (`sure`: not vignetted, weighted, every stop crossing in the disc where the mask is fully open), as pixel
// ranges [lo, hi) within [x_first, x_end): (maybe lo, maybe hi, sure lo, sure hi). Each holds for every point of
// a pixel's square, not only its centre (a linear function moves by at most half its two rates there, a stop
// point by half the lengths of its two rates), so they serve the cut pixels as well as the whole ones; and
// each is kept a pixel inside (sure) or outside (maybe) its closed-form ends, so that a rounding of theirs never
// changes which pixels get light.
fn row_spans(s: Shader, x_first: f32, x_end: f32, y: f32) -> vec4<f32> {
    let yc = y + 0.5;
    let xm = 0.5 * (x_first + x_end); // pixel x has its centre at t = x + 0.5 - xm
    let centre = vec2<f32>(xm, yc);
    let ratio = at_plane(s.ratio, centre) - 1.0;
    let ratio_reach = 0.5 * (abs(s.ratio.ax) + abs(s.ratio.ay));
    let weight = at_plane(s.weight, centre);
    let weight_reach = 0.5 * (abs(s.weight.ax) + abs(s.weight.ay));
    var maybe = meet(below_zero(ratio - ratio_reach, s.ratio.ax), below_zero(-weight - weight_reach, -s.weight.ax));
    var sure = meet(below_zero(ratio + ratio_reach, s.ratio.ax), below_zero(weight_reach - weight, -s.weight.ax));
    for (var k = 0u; k < select(s.crossings, 0u, s.open); k = k + 1u) {
        // The stop point along the row: at t = 0 (the centre) and its rate in x, u then v.
        let st = stop_planes(s, k);
        let l = vec4<f32>(at_plane(st.u, centre), st.u.ax, at_plane(st.v, centre), st.v.ax);
        let reach = 0.5 * (length(vec2<f32>(st.u.ax, st.v.ax)) + length(vec2<f32>(st.u.ay, st.v.ay)));
        let open = sqrt(box_params.open_radius2) - reach;
        let support = sqrt(box_params.support_radius2) + reach;
        sure = meet(sure, select(vec2<f32>(FAR, -FAR), within_radius(l.x, l.y, l.z, l.w, open * open), open > 0.0));
        maybe = meet(maybe, within_radius(l.x, l.y, l.z, l.w, support * support));
    }
    let offset = xm - 0.5;
    let m_lo = clamp(floor(maybe.x + offset) - 1.0, x_first, x_end);
    let m_hi = clamp(ceil(maybe.y + offset) + 2.0, m_lo, x_end);
    let s_lo = clamp(ceil(sure.x + offset) + 1.0, m_lo, m_hi);
    let s_hi = clamp(floor(sure.y + offset) - 1.0, s_lo, m_hi);
    return vec4<f32>(m_lo, m_hi, s_lo, s_hi);
}

// The i-th pixel of [lo, left_end) then [right_first, hi): both sides of a row's middle in one loop (lanes whose
// sides differ in length wait less than in two loops).
fn beside_middle(lo: f32, left_end: f32, right_first: f32, i: f32) -> f32 {
    return select(right_first + (i - (left_end - lo)), lo + i, lo + i < left_end);
}

// `shade`, or the weight alone where the pixel is in the row's sure span.
fn shade_in(s: Shader, p: vec2<f32>, sure: bool) -> f32 {
    return shade_with(s, p, select(s.crossings, 0u, s.open || sure));
}

// The cut pixels of row y, x_first .. x_end - 1 but for the whole ones full_lo .. full_hi - 1 (both sides in one
// loop, `beside_middle`): each gets the triangle's irradiance x the area it covers
// of the pixel, shaded at the centroid of that part.
fn add_cut(band: Band, sign: f32, s: Shader, x_first: f32, x_end: f32, full_lo: f32, full_hi: f32, y: f32,
    spans: vec4<f32>, irradiance: f32, rgb: vec3<f32>) {
    let lo = max(x_first, spans.x);
    let hi = min(x_end, spans.y);
    // Left of the whole pixels: [lo, left_end); right of them: [right_first, hi).
    let left_end = clamp(full_lo, lo, hi);
    let right_first = clamp(full_hi, left_end, hi);
    let count = (left_end - lo) + (hi - right_first);
    for (var i = 0.0; i < count; i = i + 1.0) {
        let x = beside_middle(lo, left_end, right_first, i);
        let part = band_part(band, x, y, sign);
        add(x, y, irradiance * part.x * shade_in(s, part.yz, x >= spans.z && x < spans.w), rgb);
    }
}

// The pixels x_first .. x_end - 1 of row y that the triangle covers whole, each shaded at its centre: nothing
// outside the row's maybe span; in its sure span the shading is the weight alone, linear in x, and a run of
// four pixels or more goes in as second differences (O(1) however long it is); the rest pixel by pixel.
fn add_whole(s: Shader, x_first: f32, x_end: f32, y: f32, spans: vec4<f32>, irradiance: f32, rgb: vec3<f32>) {
    let yc = y + 0.5;
    let lo = max(x_first, spans.x);
    let hi = min(x_end, spans.y);
    let r_lo = clamp(spans.z, lo, hi);
    let r_hi = clamp(spans.w, r_lo, hi);
    let run = r_hi - r_lo >= 4.0 && r_hi - r_lo < 65536.0; // `mul64_small`'s range
    let e = irradiance * at_plane(s.weight, vec2<f32>(r_lo + 0.5, yc));
    add_linear(r_lo, select(0u, u32(r_hi - r_lo), run), y, e, irradiance * s.weight.ax, rgb);
    // The rest, left and right of the run, in one loop.
    let left_end = select(hi, r_lo, run);
    let right_first = select(hi, r_hi, run);
    let count = (left_end - lo) + (hi - right_first);
    for (var i = 0.0; i < count; i = i + 1.0) {
        let x = beside_middle(lo, left_end, right_first, i);
        add(x, y, irradiance * shade_in(s, vec2<f32>(x + 0.5, yc), x >= spans.z && x < spans.w), rgb);
    }
}

fn plane_of(l0: Plane, l1: Plane, l2: Plane, f: vec3<f32>) -> Plane {
    return Plane(l0.a0 * f.x + l1.a0 * f.y + l2.a0 * f.z, l0.ax * f.x + l1.ax * f.y + l2.ax * f.z, l0.ay * f.x + l1.ay * f.y + l2.ay * f.z);
}


fn inside_open(v: Vertex, crossings: u32) -> bool {
    var inside = dot(v.stop0, v.stop0) < box_params.open_radius2;
    if (crossings > 1u) {
        inside = inside && dot(v.stop1, v.stop1) < box_params.open_radius2;
    }
    if (crossings > 2u) {
        inside = inside && dot(v.stop2, v.stop2) < box_params.open_radius2;
    }
    return inside;
}

fn stop_of(v: Vertex, k: u32) -> vec2<f32> {
    if (k == 0u) {
        return v.stop0;
    }
    if (k == 1u) {
        return v.stop1;
    }
    return v.stop2;
}

// Invocations per triangle: each draws every ROW_SPLIT-th of its rows, from row `part` on (1 on a software
// rasteriser; more on a GPU, where one invocation walking a large triangle's rows alone holds up its warp).
override ROW_SPLIT: u32 = 1u;

// Workgroup (x, y) draws 64 invocations' worth of triangles, block y, of job x (in a spread order): a software
// rasteriser hands each of its threads a contiguous run of a dispatch's workgroups (x fastest), so each thread
// gets a part of every job's grid rather than a run of jobs, and neighbouring jobs (a ghost's wavelengths, a
// lens's ghosts in order) cost alike. In job order, with a job a row of workgroups, one thread went on alone
// for as long as both had worked (the Nikon zoom at grid 64 on 2 threads: 2 s both, then 2.5-3 s one).
@compute @workgroup_size(64)
fn splat_box(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    if (wid.x >= box_params.jobs) {
        return;
    }
    let job = job_at(box_jobs, (wid.x * box_params.job_stride) % box_params.jobs);
    let n = job.steps.w;
    let invocation = wid.y * 64u + local;
    let triangle = invocation / ROW_SPLIT;
    let part = invocation % ROW_SPLIT;
    if (triangle >= 2u * n * n) {
        return;
    }
    let cell = triangle / 2u;
    let ix = cell % n;
    let iy = cell / n;
    let v00 = job.steps.z + iy * (n + 1u) + ix;
    // The CPU's triangles: (v00, v10, v11) and (v00, v11, v01).
    var second = v00 + 1u;
    var third = v00 + n + 2u;
    if (triangle % 2u == 1u) {
        second = v00 + n + 2u;
        third = v00 + n + 1u;
    }
    let a = vertex_at(grid, v00);
    let b = vertex_at(grid, second);
    let c = vertex_at(grid, third);
    if (a.valid == 0u || b.valid == 0u || c.valid == 0u || (a.ratio > 1.0 && b.ratio > 1.0 && c.ratio > 1.0)) {
        return;
    }
    let crossings = u32(job.frame.z + 0.5);
    // Entirely outside the mask's square on one side at some crossing: nothing passes.
    for (var k = 0u; k < crossings; k = k + 1u) {
        let sa = stop_of(a, k);
        let sb = stop_of(b, k);
        let sc = stop_of(c, k);
        if (all(vec3<bool>(sa.x > 1.0, sb.x > 1.0, sc.x > 1.0)) || all(vec3<bool>(sa.x < -1.0, sb.x < -1.0, sc.x < -1.0))
            || all(vec3<bool>(sa.y > 1.0, sb.y > 1.0, sc.y > 1.0)) || all(vec3<bool>(sa.y < -1.0, sb.y < -1.0, sc.y < -1.0))) {
            return;
        }
    }
    let w = f32(box_params.width);
    let h = f32(box_params.height);
    let lo = min(min(a.pixel, b.pixel), c.pixel);
    let hi = max(max(a.pixel, b.pixel), c.pixel);
    if (lo.x > w + 1.0 || lo.y > h + 1.0 || hi.x < -1.0 || hi.y < -1.0) {
        return;
    }
    let rgb = job.rgb.rgb;
    let flux = job.frame.w;
    let open = inside_open(a, crossings) && inside_open(b, crossings) && inside_open(c, crossings);
    let centre = (a.pixel + b.pixel + c.pixel) / 3.0;
    let area2 = (b.pixel.x - a.pixel.x) * (c.pixel.y - a.pixel.y) - (b.pixel.y - a.pixel.y) * (c.pixel.x - a.pixel.x);
    var s: Shader;
    s.open = open;
    s.crossings = crossings;
    // Barycentric planes: l_i is the edge function of the opposite edge over twice the area; for a triangle
    // collapsed to a line or a point (a ghost focused there) the corners' mean.
    let collapsed = area2 == 0.0;
    let inv = select(1.0 / area2, 0.0, collapsed);
    let mean = select(0.0, 1.0 / 3.0, collapsed);
    let l0 = Plane((b.pixel.x * c.pixel.y - b.pixel.y * c.pixel.x) * inv + mean, (b.pixel.y - c.pixel.y) * inv, (c.pixel.x - b.pixel.x) * inv);
    let l1 = Plane((c.pixel.x * a.pixel.y - c.pixel.y * a.pixel.x) * inv + mean, (c.pixel.y - a.pixel.y) * inv, (a.pixel.x - c.pixel.x) * inv);
    let l2 = Plane((a.pixel.x * b.pixel.y - a.pixel.y * b.pixel.x) * inv + mean, (a.pixel.y - b.pixel.y) * inv, (b.pixel.x - a.pixel.x) * inv);
    s.ratio = plane_of(l0, l1, l2, vec3<f32>(a.ratio, b.ratio, c.ratio));
    s.weight = plane_of(l0, l1, l2, vec3<f32>(a.weight, b.weight, c.weight));
    s.s0u = plane_of(l0, l1, l2, vec3<f32>(a.stop0.x, b.stop0.x, c.stop0.x));
    s.s0v = plane_of(l0, l1, l2, vec3<f32>(a.stop0.y, b.stop0.y, c.stop0.y));
    s.s1u = plane_of(l0, l1, l2, vec3<f32>(a.stop1.x, b.stop1.x, c.stop1.x));
    s.s1v = plane_of(l0, l1, l2, vec3<f32>(a.stop1.y, b.stop1.y, c.stop1.y));
    s.s2u = plane_of(l0, l1, l2, vec3<f32>(a.stop2.x, b.stop2.x, c.stop2.x));
    s.s2v = plane_of(l0, l1, l2, vec3<f32>(a.stop2.y, b.stop2.y, c.stop2.y));
    if (collapsed || (hi.x < floor(lo.x) + 1.0 && hi.y < floor(lo.y) + 1.0)) {
        // Collapsed, or inside one pixel: all of its energy in the pixel of its centroid (added once).
        if (part == 0u) {
            add(floor(centre.x), floor(centre.y), flux * shade(s, centre), rgb);
        }
        return;
    }
    let irradiance = flux / (0.5 * abs(area2));
    let sign = select(1.0, -1.0, area2 < 0.0); // the edge sum has the sign of area2
    // Irradiance (the triangle's flux over its footprint) x the area it covers of each pixel, shaded at the
    // centroid of that part: the box filter a sensor pixel applies. Rows outside the frame or the strip are skipped.
    let first = f32(box_params.first_row);
    let y_first = max(floor(lo.y), first);
    let y_last = min(floor(hi.y), min(h, first + f32(box_params.rows)) - 1.0);
    for (var y = y_first + f32(part); y <= y_last; y = y + f32(ROW_SPLIT)) {
        // The columns the row touches, and those it covers whole (the triangle spans the row and both of its
        // sections lie beyond the pixel on either side: a convex section's extent is extreme at the band's ends).
        let top = section(a.pixel, b.pixel, c.pixel, y);
        let bottom = section(a.pixel, b.pixel, c.pixel, y + 1.0);
        var x_lo = min(top.x, bottom.x);
        var x_hi = max(top.y, bottom.y);
        for (var i = 0u; i < 3u; i = i + 1u) {
            let v = select(select(c.pixel, b.pixel, i == 1u), a.pixel, i == 0u);
            let inside = v.y > y && v.y < y + 1.0;
            x_lo = select(x_lo, min(x_lo, v.x), inside);
            x_hi = select(x_hi, max(x_hi, v.x), inside);
        }
        let x_first = max(floor(x_lo), 0.0);
        let x_end = min(floor(x_hi), w - 1.0) + 1.0;
        let spans = lo.y <= y && hi.y >= y + 1.0;
        let full_lo = clamp(select(x_end, ceil(max(top.x, bottom.x)), spans), x_first, x_end);
        let full_hi = clamp(select(x_end, floor(min(top.y, bottom.y)), spans), full_lo, x_end);
        if (x_end <= x_first) {
            continue;
        }
        let lit = row_spans(s, x_first, x_end, y);
        let band = band_of(a.pixel, b.pixel, c.pixel, y);
        add_cut(band, sign, s, x_first, x_end, full_lo, full_hi, y, lit, irradiance, rgb);
        add_whole(s, full_lo, full_hi, y, lit, irradiance, rgb);
    }
}

// One invocation per row of the strip: the second differences summed twice along the row (the linear runs),
// plus the direct sums, as floats; both cleared for the next strip.
@compute @workgroup_size(64)
fn resolve_box(@builtin(global_invocation_id) gid: vec3<u32>) {
    let row = gid.y * box_params.groups_x * 64u + gid.x;
    if (row >= box_params.rows) {
        return;
    }
    var slope = array<vec2<u32>, 3>(vec2<u32>(0u), vec2<u32>(0u), vec2<u32>(0u));
    var level = array<vec2<u32>, 3>(vec2<u32>(0u), vec2<u32>(0u), vec2<u32>(0u));
    for (var x = 0u; x < box_params.width; x = x + 1u) {
        let base = (row * box_params.width + x) * WORDS_PER_PIXEL;
        var out = vec4<f32>(0.0, 0.0, 0.0, 1.0);
        for (var c = 0u; c < 3u; c = c + 1u) {
            let word = base + 2u * c;
            let direct = vec2<u32>(atomicLoad(&sums[word]), atomicLoad(&sums[word + 1u]));
            let second = vec2<u32>(atomicLoad(&sums[word + 6u]), atomicLoad(&sums[word + 7u]));
            slope[c] = add64(slope[c], second);
            level[c] = add64(level[c], slope[c]);
            out[c] = max(float64(add64(level[c], direct)) * box_params.unit_per_fixed, 0.0);
            atomicStore(&sums[word], 0u);
            atomicStore(&sums[word + 1u], 0u);
            atomicStore(&sums[word + 6u], 0u);
            atomicStore(&sums[word + 7u], 0u);
        }
        textureStore(resolved, vec2<u32>(x, box_params.first_row + row), out);
    }
}

// The same words as `sums`, for `resolve_box_scan` (bound apart: the splat's atomics are done, a pass boundary
// lies between), read and cleared by plain loads and stores.
@group(0) @binding(6) var<storage, read_write> plain_sums: array<u32>;

// The three channels' 64-bit sums at `word` (R, G, B as (low, high) pairs) as `Sums` (scan64.wgsl).
fn load_sums(word: u32) -> Sums {
    return Sums(
        vec3<u32>(plain_sums[word], plain_sums[word + 2u], plain_sums[word + 4u]),
        vec3<u32>(plain_sums[word + 1u], plain_sums[word + 3u], plain_sums[word + 5u]),
    );
}

// `resolve_box` on a GPU: one workgroup per row of the strip, 256 columns at a time, one column an invocation
// (neighbouring invocations read neighbouring words; one invocation walking a whole row leaves a GPU idle):
// the second differences scanned into slopes, the slopes into levels (`scan_chunk` of scan64.wgsl, each
// running sum a pair of vectors in registers, as the ghosts' `resolve`), plus the direct sums. The same sums.
@compute @workgroup_size(256)
fn resolve_box_scan(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let row = wid.y * box_params.groups_x + wid.x;
    if (row >= box_params.rows) {
        return;
    }
    var slope_before = no_sums();
    var level_before = no_sums();
    for (var x0 = 0u; x0 < box_params.width; x0 = x0 + CHUNK) {
        let x = x0 + t;
        let inside = x < box_params.width;
        let base = (row * box_params.width + min(x, box_params.width - 1u)) * WORDS_PER_PIXEL;
        var direct = no_sums();
        var second = no_sums();
        if (inside) {
            direct = load_sums(base);
            second = load_sums(base + 6u);
        }
        let slope = add_sums(slope_before, scan_chunk(t, second));
        slope_before = add_sums(slope_before, chunk[CHUNK - 1u]);
        workgroupBarrier();
        let level = add_sums(level_before, scan_chunk(t, slope));
        level_before = add_sums(level_before, chunk[CHUNK - 1u]);
        if (inside) {
            let rgb = max(float_sums(add_sums(level, direct)) * box_params.unit_per_fixed, vec3<f32>(0.0));
            textureStore(resolved, vec2<u32>(x, box_params.first_row + row), vec4<f32>(rgb, 1.0));
            for (var word = base; word < base + WORDS_PER_PIXEL; word = word + 1u) {
                plain_sums[word] = 0u;
            }
        }
        workgroupBarrier();
    }
}
