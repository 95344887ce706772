// Ray grids on the GPU, pass 2 as compute: each grid triangle box-filtered as the CPU twin does it
// (`splat_triangle` in crates/flare_core/src/raytrace/splat.rs): each pixel the triangle touches gets the
// triangle's irradiance x the area it covers of the pixel, shaded at the centroid of that part; the pixels a row
// covers whole are shaded at their centres. The CPU cuts polygons; here each part's area and centroid come in
// closed form from the triangle's edges (`pixel_part`), which gives the same numbers without per-invocation
// arrays or data-dependent loops over vertices (4.4x faster on lavapipe than the cutting it replaced). No
// supersampling: the box filter is exact. Energy goes into a per-pixel 64-bit fixed-point sum (two u32 words
// added with carry by atomics), so the image does not depend on the order in which triangles land: the same
// bytes on every run. `resolve_box` turns the sums into floats and clears them. The declarations come from
// raygrid_common.wgsl, the fixed-point helpers from fixed64.wgsl, the mask lookup (a storage buffer, filtered
// as `ApertureMask::sample` does) from mask_texels.wgsl. Must be kept in sync with `BoxParams` in
// crates/flare_core/src/render/raygrid.rs.

struct BoxParams {
    width: u32,           // the frame (pixels)
    height: u32,
    jobs: u32,            // jobs in this batch
    first_row: u32,       // the strip of rows this dispatch adds into and resolves
    rows: u32,
    groups_x: u32,        // workgroups along x of `resolve_box`
    mask_size: u32,       // texels across the aperture mask
    unused1: u32,
    fixed_per_unit: f32,  // fixed-point units per unit of irradiance, and its inverse
    unit_per_fixed: f32,
    open_radius2: f32,    // the square of the radius (stop radii) within which the mask is fully open
    unused2: f32,
};

@group(0) @binding(0) var<storage, read> grid: array<Vertex>;
@group(0) @binding(1) var<storage, read> box_jobs: array<Job>;
// The aperture mask's texels (u8, four to a word, row 0 at v = +1).
@group(0) @binding(2) var<storage, read> mask_texels: array<u32>;
@group(0) @binding(3) var<uniform> box_params: BoxParams;
// Per pixel of the strip, R, G, B as 64-bit sums (low word, high word); all zero between strips.
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

fn mask_word(w: u32) -> u32 {
    return mask_texels[w];
}

fn mask_at(u: f32, v: f32) -> f32 {
    return mask_bilinear(u, v, box_params.mask_size);
}

fn shade(s: Shader, p: vec2<f32>) -> f32 {
    if (at_plane(s.ratio, p) > 1.0) {
        return 0.0;
    }
    var m = max(at_plane(s.weight, p), 0.0);
    if (s.open) {
        return m;
    }
    if (m > 0.0) {
        m = m * mask_at(at_plane(s.s0u, p), at_plane(s.s0v, p));
    }
    if (s.crossings > 1u && m > 0.0) {
        m = m * mask_at(at_plane(s.s1u, p), at_plane(s.s1v, p));
    }
    if (s.crossings > 2u && m > 0.0) {
        m = m * mask_at(at_plane(s.s2u, p), at_plane(s.s2v, p));
    }
    return m;
}

// ---- the part of a triangle in one pixel, in closed form ----
//
// The CPU twin cuts the triangle into rows and each row into pixels (Sutherland-Hodgman) and takes each piece's
// area and centroid. Here the same area and centroid come from the triangle's three edges by Green's theorem,
// without cutting: with G(x) = clamp(x, 0, 1) in the pixel's own unit square,
//   area         = sum over edges of  integral G(x_e(y)) dy
//   area x cx    = sum over edges of  integral G(x_e(y))^2 / 2 dy
//   area x cy    = sum over edges of  integral y G(x_e(y)) dy
// each integral over the edge's y clamped to [0, 1], signed by its direction (the sum is the signed area). On an
// edge, G is linear in y between the points where x crosses 0 and 1, so each integral is three trapezoids. The
// code has no loop and no array, and takes the same steps in every pixel: what a SIMD software rasteriser
// (lavapipe) and a GPU both run well.

// The three integrals of the directed edge p -> q, both relative to the pixel's corner.
fn edge_moments(p: vec2<f32>, q: vec2<f32>) -> vec3<f32> {
    let dy = q.y - p.y;
    let k = select(0.0, (q.x - p.x) / dy, dy != 0.0);
    let ya = clamp(p.y, 0.0, 1.0);
    let yb = clamp(q.y, 0.0, 1.0);
    let xa = p.x + (ya - p.y) * k;
    let xb = p.x + (yb - p.y) * k;
    let dx = xb - xa;
    let inv = select(0.0, 1.0 / dx, dx != 0.0);
    let t0 = clamp(-xa * inv, 0.0, 1.0);
    let t1 = clamp((1.0 - xa) * inv, 0.0, 1.0);
    let t = vec4<f32>(0.0, min(t0, t1), max(t0, t1), 1.0);
    let y = ya + t * (yb - ya);
    let g = clamp(vec4<f32>(xa) + t * dx, vec4<f32>(0.0), vec4<f32>(1.0));
    var m = vec3<f32>(0.0);
    for (var i = 0u; i < 3u; i = i + 1u) {
        let d = y[i + 1u] - y[i];
        let g0 = g[i];
        let g1 = g[i + 1u];
        m = m + d * vec3<f32>(0.5 * (g0 + g1), (g0 * g0 + g0 * g1 + g1 * g1) / 6.0,
            (y[i] * (2.0 * g0 + g1) + y[i + 1u] * (g0 + 2.0 * g1)) / 6.0);
    }
    return m;
}

// Area (px^2) in x and the centroid (frame pixels) in yz of the triangle's part in pixel (x, y); `sign` makes the
// area positive for the triangle's winding.
fn pixel_part(a: vec2<f32>, b: vec2<f32>, c: vec2<f32>, x: f32, y: f32, sign: f32) -> vec3<f32> {
    let o = vec2<f32>(x, y);
    let m = sign * (edge_moments(a - o, b - o) + edge_moments(b - o, c - o) + edge_moments(c - o, a - o));
    if (!(m.x > 0.0)) {
        return vec3<f32>(0.0);
    }
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
    atomicAdd(&sums[word + 1u], v.y + select(0u, 1u, old + v.x < old));
}

// Adds `energy` (irradiance x pixel area, before the colour) at pixel (x, y) when it lies in the frame.
// Only the strip's rows are kept: a frame whose sums do not fit one buffer is drawn a strip at a time.
fn add(x: f32, y: f32, energy: f32, rgb: vec3<f32>) {
    let first = f32(box_params.first_row);
    if (x < 0.0 || y < first || x >= f32(box_params.width) || y >= first + f32(box_params.rows) || !(energy > 0.0)) {
        return;
    }
    let word = ((u32(y) - box_params.first_row) * box_params.width + u32(x)) * 6u;
    let value = rgb * (energy * box_params.fixed_per_unit);
    for (var c = 0u; c < 3u; c = c + 1u) {
        let f = fixed(value[c]);
        if (f.x != 0u || f.y != 0u) {
            atomic_add64(word + 2u * c, f);
        }
    }
}

fn plane_of(l0: Plane, l1: Plane, l2: Plane, f: vec3<f32>) -> Plane {
    return Plane(l0.a0 * f.x + l1.a0 * f.y + l2.a0 * f.z, l0.ax * f.x + l1.ax * f.y + l2.ax * f.z, l0.ay * f.x + l1.ay * f.y + l2.ay * f.z);
}

fn mean_plane(f: vec3<f32>) -> Plane {
    return Plane((f.x + f.y + f.z) / 3.0, 0.0, 0.0);
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

@compute @workgroup_size(64)
fn splat_box(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.y >= box_params.jobs) {
        return;
    }
    let job = box_jobs[gid.y];
    let n = job.steps.w;
    if (gid.x >= 2u * n * n) {
        return;
    }
    let cell = gid.x / 2u;
    let ix = cell % n;
    let iy = cell / n;
    let v00 = job.steps.z + iy * (n + 1u) + ix;
    // The CPU's triangles: (v00, v10, v11) and (v00, v11, v01).
    var second = v00 + 1u;
    var third = v00 + n + 2u;
    if (gid.x % 2u == 1u) {
        second = v00 + n + 2u;
        third = v00 + n + 1u;
    }
    let a = grid[v00];
    let b = grid[second];
    let c = grid[third];
    if (a.valid < 0.5 || b.valid < 0.5 || c.valid < 0.5 || (a.ratio > 1.0 && b.ratio > 1.0 && c.ratio > 1.0)) {
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
    if (area2 == 0.0) {
        // Collapsed to a line or a point (a ghost focused there): all of its energy in the pixel of its centroid.
        s.ratio = mean_plane(vec3<f32>(a.ratio, b.ratio, c.ratio));
        s.weight = mean_plane(vec3<f32>(a.weight, b.weight, c.weight));
        s.s0u = mean_plane(vec3<f32>(a.stop0.x, b.stop0.x, c.stop0.x));
        s.s0v = mean_plane(vec3<f32>(a.stop0.y, b.stop0.y, c.stop0.y));
        s.s1u = mean_plane(vec3<f32>(a.stop1.x, b.stop1.x, c.stop1.x));
        s.s1v = mean_plane(vec3<f32>(a.stop1.y, b.stop1.y, c.stop1.y));
        s.s2u = mean_plane(vec3<f32>(a.stop2.x, b.stop2.x, c.stop2.x));
        s.s2v = mean_plane(vec3<f32>(a.stop2.y, b.stop2.y, c.stop2.y));
        add(floor(centre.x), floor(centre.y), flux * shade(s, centre), rgb);
        return;
    }
    // Barycentric planes: l_i is the edge function of the opposite edge over twice the area.
    let l0 = Plane((b.pixel.x * c.pixel.y - b.pixel.y * c.pixel.x) / area2, (b.pixel.y - c.pixel.y) / area2, (c.pixel.x - b.pixel.x) / area2);
    let l1 = Plane((c.pixel.x * a.pixel.y - c.pixel.y * a.pixel.x) / area2, (c.pixel.y - a.pixel.y) / area2, (a.pixel.x - c.pixel.x) / area2);
    let l2 = Plane((a.pixel.x * b.pixel.y - a.pixel.y * b.pixel.x) / area2, (a.pixel.y - b.pixel.y) / area2, (b.pixel.x - a.pixel.x) / area2);
    s.ratio = plane_of(l0, l1, l2, vec3<f32>(a.ratio, b.ratio, c.ratio));
    s.weight = plane_of(l0, l1, l2, vec3<f32>(a.weight, b.weight, c.weight));
    s.s0u = plane_of(l0, l1, l2, vec3<f32>(a.stop0.x, b.stop0.x, c.stop0.x));
    s.s0v = plane_of(l0, l1, l2, vec3<f32>(a.stop0.y, b.stop0.y, c.stop0.y));
    s.s1u = plane_of(l0, l1, l2, vec3<f32>(a.stop1.x, b.stop1.x, c.stop1.x));
    s.s1v = plane_of(l0, l1, l2, vec3<f32>(a.stop1.y, b.stop1.y, c.stop1.y));
    s.s2u = plane_of(l0, l1, l2, vec3<f32>(a.stop2.x, b.stop2.x, c.stop2.x));
    s.s2v = plane_of(l0, l1, l2, vec3<f32>(a.stop2.y, b.stop2.y, c.stop2.y));
    let irradiance = flux / (0.5 * abs(area2));
    let sign = select(1.0, -1.0, area2 < 0.0); // the edge sum has the sign of area2
    // Irradiance (the triangle's flux over its footprint) x the area it covers of each pixel, shaded at the
    // centroid of that part: the box filter a sensor pixel applies. Rows outside the frame or the strip are skipped.
    let first = f32(box_params.first_row);
    let y_first = max(floor(lo.y), first);
    let y_last = min(floor(hi.y), min(h, first + f32(box_params.rows)) - 1.0);
    for (var y = y_first; y <= y_last; y = y + 1.0) {
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
        for (var x = x_first; x < full_lo; x = x + 1.0) {
            let part = pixel_part(a.pixel, b.pixel, c.pixel, x, y, sign);
            add(x, y, irradiance * part.x * shade(s, part.yz), rgb);
        }
        for (var x = full_lo; x < full_hi; x = x + 1.0) {
            add(x, y, irradiance * shade(s, vec2<f32>(x + 0.5, y + 0.5)), rgb);
        }
        for (var x = full_hi; x < x_end; x = x + 1.0) {
            let part = pixel_part(a.pixel, b.pixel, c.pixel, x, y, sign);
            add(x, y, irradiance * part.x * shade(s, part.yz), rgb);
        }
    }
}

@compute @workgroup_size(64)
fn resolve_box(@builtin(global_invocation_id) gid: vec3<u32>) {
    let pixel = gid.y * box_params.groups_x * 64u + gid.x;
    if (pixel >= box_params.width * box_params.rows) {
        return;
    }
    var out = vec4<f32>(0.0, 0.0, 0.0, 1.0);
    for (var c = 0u; c < 3u; c = c + 1u) {
        let word = pixel * 6u + 2u * c;
        let lo = atomicLoad(&sums[word]);
        let hi = atomicLoad(&sums[word + 1u]);
        out[c] = max(float64(vec2<u32>(lo, hi)) * box_params.unit_per_fixed, 0.0);
        atomicStore(&sums[word], 0u);
        atomicStore(&sums[word + 1u], 0u);
    }
    textureStore(resolved, vec2<u32>(pixel % box_params.width, box_params.first_row + pixel / box_params.width), out);
}
