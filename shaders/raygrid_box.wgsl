// Ray grids on the GPU, pass 2 as compute: each grid triangle box-filtered exactly as the CPU twin does it
// (`splat_triangle` in crates/flare_core/src/raytrace/splat.rs, same names, same steps): clipped to the frame,
// cut into rows and each row into pixels, each piece adding the triangle's irradiance x its area, shaded at its
// centroid; the pixels a row covers whole are added without cutting. No supersampling: the box filter is exact.
// Energy goes into a per-pixel 64-bit fixed-point sum (two u32 words added with carry by atomics), so the image
// does not depend on the order in which triangles land: the same bytes on every run. `resolve_box` turns the
// sums into floats and clears them. The declarations come from raygrid_common.wgsl, the mask lookup from
// aperture.wgsl, the fixed-point helpers from fixed64.wgsl. Must be kept in sync with `BoxParams` in crates/flare_core/src/render/raygrid.rs.

struct BoxParams {
    width: u32,           // the frame (pixels)
    height: u32,
    jobs: u32,            // jobs in this batch
    first_row: u32,       // the strip of rows this dispatch adds into and resolves
    rows: u32,
    groups_x: u32,        // workgroups along x of `resolve_box`
    unused0: u32,
    unused1: u32,
    fixed_per_unit: f32,  // fixed-point units per unit of irradiance, and its inverse
    unit_per_fixed: f32,
    open_radius2: f32,    // the square of the radius (stop radii) within which the mask is fully open
    unused2: f32,
};

@group(0) @binding(0) var<storage, read> grid: array<Vertex>;
@group(0) @binding(1) var<storage, read> box_jobs: array<Job>;
@group(0) @binding(2) var aperture_texture: texture_2d<f32>;
@group(0) @binding(3) var aperture_sampler: sampler;
// Per pixel of the strip, R, G, B as 64-bit sums (low word, high word); all zero between strips.
@group(0) @binding(4) var<storage, read_write> sums: array<atomic<u32>>;
@group(0) @binding(5) var<uniform> box_params: BoxParams;
@group(0) @binding(6) var resolved: texture_storage_2d<rgba32float, write>;

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

fn mask_at(u: f32, v: f32) -> f32 {
    return aperture_at(vec2<f32>(u, v));
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

// ---- convex polygons (Polygon, Cutter) ----

struct Poly {
    v: array<vec2<f32>, 8>,
    n: u32,
};

fn push(poly: ptr<function, Poly>, q: vec2<f32>) {
    if ((*poly).n < 8u) {
        (*poly).v[(*poly).n] = q;
        (*poly).n = (*poly).n + 1u;
    }
}

// The parts with p[axis] <= at (`lower`) and p[axis] >= at (`upper`): Sutherland-Hodgman against one line.
fn split(p: Poly, axis: u32, at: f32, lower: ptr<function, Poly>, upper: ptr<function, Poly>) {
    let n = p.n;
    var below = 0u;
    var above = 0u;
    for (var i = 0u; i < n; i = i + 1u) {
        below = below | (select(0u, 1u, p.v[i][axis] <= at) << i);
        above = above | (select(0u, 1u, p.v[i][axis] >= at) << i);
    }
    let all = (1u << n) - 1u;
    (*lower).n = 0u;
    (*upper).n = 0u;
    if (below == all) {
        *lower = p;
        return;
    }
    if (above == all) {
        *upper = p;
        return;
    }
    var a = p.v[n - 1u];
    var a_bit = 1u << (n - 1u);
    for (var i = 0u; i < n; i = i + 1u) {
        let b = p.v[i];
        let b_bit = 1u << i;
        let a_le = (below & a_bit) != 0u;
        let a_ge = (above & a_bit) != 0u;
        let b_le = (below & b_bit) != 0u;
        let b_ge = (above & b_bit) != 0u;
        if (a_le) {
            push(lower, a);
        }
        if (a_ge) {
            push(upper, a);
        }
        if ((a_le && !a_ge && b_ge && !b_le) || (a_ge && !a_le && b_le && !b_ge)) {
            let t = (at - a[axis]) / (b[axis] - a[axis]);
            var q = a + t * (b - a);
            q[axis] = at;
            push(lower, q);
            push(upper, q);
        }
        a = b;
        a_bit = b_bit;
    }
}

fn bounds(p: Poly) -> vec4<f32> {
    var b = vec4<f32>(3.0e38, 3.0e38, -3.0e38, -3.0e38);
    for (var i = 0u; i < p.n; i = i + 1u) {
        b = vec4<f32>(min(b.xy, p.v[i]), max(b.zw, p.v[i]));
    }
    return b;
}

// Area (px^2) in x and the centroid in yz; area 0 when empty or of no area.
fn area_centroid(p: Poly) -> vec3<f32> {
    if (p.n < 3u) {
        return vec3<f32>(0.0);
    }
    let o = p.v[0];
    var area2 = 0.0;
    var c = vec2<f32>(0.0);
    for (var i = 1u; i + 1u < p.n; i = i + 1u) {
        let a = p.v[i] - o;
        let b = p.v[i + 1u] - o;
        let cross = a.x * b.y - a.y * b.x;
        area2 = area2 + cross;
        c = c + cross * (a + b);
    }
    if (area2 == 0.0) {
        return vec3<f32>(0.0);
    }
    return vec3<f32>(0.5 * abs(area2), o + c / (3.0 * area2));
}

// The columns [lo, hi) of the pixels a row part (within y..y + 1) covers whole; lo >= hi when none.
fn full_columns(p: Poly, y: f32) -> vec2<f32> {
    var bottom = vec2<f32>(3.0e38, -3.0e38);
    var top = vec2<f32>(3.0e38, -3.0e38);
    for (var i = 0u; i < p.n; i = i + 1u) {
        let v = p.v[i];
        if (v.y == y) {
            bottom = vec2<f32>(min(bottom.x, v.x), max(bottom.y, v.x));
        } else if (v.y == y + 1.0) {
            top = vec2<f32>(min(top.x, v.x), max(top.y, v.x));
        }
    }
    return vec2<f32>(ceil(max(bottom.x, top.x)), floor(min(bottom.y, top.y)));
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
    let area_px = 0.5 * abs(area2);
    let col = floor(lo.x);
    let row = floor(lo.y);
    if (hi.x < col + 1.0 && hi.y < row + 1.0) {
        // Inside one pixel: all of it there.
        add(col, row, flux * shade(s, centre), rgb);
        return;
    }
    // Irradiance (the triangle's flux over its footprint) x the area it covers of each pixel, shaded at the
    // centroid of that part: the box filter a sensor pixel applies.
    let irradiance = flux / area_px;
    var rest: Poly;
    rest.n = 3u;
    rest.v[0] = a.pixel;
    rest.v[1] = b.pixel;
    rest.v[2] = c.pixel;
    var scrap: Poly;
    var kept: Poly;
    if (lo.x < 0.0 || lo.y < 0.0 || hi.x > w || hi.y > h) {
        split(rest, 0u, 0.0, &scrap, &kept);
        split(kept, 0u, w, &rest, &scrap);
        split(rest, 1u, 0.0, &scrap, &kept);
        split(kept, 1u, h, &rest, &scrap);
    }
    if (rest.n < 3u) {
        return;
    }
    var y = floor(bounds(rest).y);
    var columns: Poly;
    var piece: Poly;
    while (rest.n >= 3u) {
        if (y >= f32(box_params.first_row + box_params.rows)) {
            break;
        }
        split(rest, 1u, y + 1.0, &columns, &kept);
        rest = kept;
        // Rows are cut one after another from the top whatever the strip (the same pieces, bit for bit, in a
        // frame drawn whole or in strips); only the strip's rows are cut into pixels.
        let in_strip = y >= f32(box_params.first_row) && y < f32(box_params.first_row + box_params.rows);
        if (columns.n >= 3u && in_strip) {
            let full = full_columns(columns, y);
            var x = floor(bounds(columns).x);
            while (columns.n >= 3u) {
                if (x == full.x && full.x < full.y) {
                    for (var cx = full.x; cx < full.y; cx = cx + 1.0) {
                        add(cx, y, irradiance * shade(s, vec2<f32>(cx + 0.5, y + 0.5)), rgb);
                    }
                    split(columns, 0u, full.y, &piece, &kept);
                    columns = kept;
                    x = full.y;
                    continue;
                }
                split(columns, 0u, x + 1.0, &piece, &kept);
                columns = kept;
                let ac = area_centroid(piece);
                if (ac.x > 0.0) {
                    add(x, y, irradiance * ac.x * shade(s, ac.yz), rgb);
                }
                x = x + 1.0;
            }
        }
        y = y + 1.0;
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
