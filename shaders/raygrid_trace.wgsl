// Ray grids on the GPU, pass 1: trace every grid ray of every job (workgroup row y = job) exactly, in f32.
// CPU twin: `RayGridRenderer::trace_lanes` in crates/flare_core/src/raytrace/tracer.rs (f64), with the tracer of
// crates/flare_core/src/optics/trace.rs. The declarations come from raygrid_common.wgsl.

// Entries of each reflectance table (over sin^2 i in [0, 1]).
const TABLE_SAMPLES: u32 = 1025u;
// The surface kinds the steps of this pipeline's jobs may hold (set when the pipeline is made, one pipeline per
// value): 0 spheres and planes only, 1 also conics and aspheres, 2 also toroids. A software rasteriser runs both
// sides of a branch, so each kind a lens lacks, compiled out, is time saved (on lavapipe the Double Gauss's
// trace at grid 64 took 40 % less with spheres only). Must be kept in sync with `TraceShapes` in
// crates/flare_core/src/render/raygrid.rs.
override SHAPES: u32 = 2u;
const MAX_NEWTON_STEPS: u32 = 40u;
// Steps of a path held in workgroup memory (64 bytes each: 16320 bytes, within the 16352 every adapter offers).
// Must be kept in sync with `MAX_PATH_STEPS` in crates/flare_core/src/render/raygrid.rs, which refuses longer
// paths.
const MAX_PATH_STEPS: u32 = 255u;

@group(0) @binding(0) var<storage, read> steps: array<Step>;
// The jobs as texels (`job_at`).
@group(0) @binding(1) var jobs: texture_2d<u32>;
// The reflectance tables (f32 bits), then per job with a pre-pass its lit cells as bits (row by row, 16 to an
// entry; from `Job.lit_cells.x`), as one run of words in texels (`texel_at`).
@group(0) @binding(2) var tables: texture_2d<u32>;
@group(0) @binding(3) var<storage, read_write> vertices: array<Vertex>;

// Whether the entrance point x0 lies in (or within a thousandth of a cell of) a lit cell of the job's pre-pass:
// the CPU's `LitCells::contains`, with a margin so that a point the CPU finds on a cell boundary is not lost to
// f32 rounding (a twin may trace a ray more, never one less).
fn table_word(i: u32) -> u32 {
    return texel_at(tables, i / 4u)[i % 4u];
}

fn lit_at(job: Job, x0: vec2<f32>) -> bool {
    let n = job.lit_cells.y;
    if (n == 0u) {
        return true;
    }
    let f = clamp((x0 - job.lit.xy) / job.lit.zw, vec2<f32>(-1.0), vec2<f32>(f32(n) + 1.0));
    let last = vec2<f32>(f32(n - 1u));
    let lo = vec2<u32>(clamp(floor(f - 1.0e-3), vec2<f32>(0.0), last));
    let hi = vec2<u32>(clamp(ceil(f + 1.0e-3) - 1.0, vec2<f32>(0.0), last));
    let cells = vec4<u32>(lo.y * n + lo.x, lo.y * n + hi.x, hi.y * n + lo.x, hi.y * n + hi.x);
    var any = 0u;
    for (var i = 0u; i < 4u; i = i + 1u) {
        any = any | (table_word(job.lit_cells.x + cells[i] / 16u) >> (cells[i] % 16u));
    }
    return (any & 1u) == 1u;
}

fn table_at(offset: u32, sin2: f32) -> f32 {
    let x = clamp(sin2, 0.0, 1.0) * f32(TABLE_SAMPLES - 1u);
    let k = min(u32(x), TABLE_SAMPLES - 2u);
    let f = x - f32(k);
    return bitcast<f32>(table_word(offset + k)) * (1.0 - f) + bitcast<f32>(table_word(offset + k + 1u)) * f;
}

// The sag and its slope over r of an aspheric step at r^2; a negative `ok` where it is undefined.
struct Sag {
    z: f32,
    slope_over_r: f32,
    ok: bool,
};

// What every step needs (the first half of `Step`), and the aspheric terms (the second), read apart: a spherical
// step never reads its terms.
struct Surface {
    surface: vec4<f32>,
    optics: vec4<u32>,
};

struct Terms {
    lo: vec4<f32>,
    hi: vec4<f32>,
};

fn has(st: Surface, flag: u32) -> bool {
    return (st.optics.z & flag) != 0u;
}

fn sag(st: Surface, t: Terms, r2: f32) -> Sag {
    var out: Sag;
    let c = st.surface.y;
    let root = 1.0 - (1.0 + st.surface.z) * c * c * r2;
    if (root <= 0.0) {
        out.ok = false;
        return out;
    }
    let sq = sqrt(root);
    var z = c * r2 / (1.0 + sq) + t.lo.x * r2;
    var m = c / sq + 2.0 * t.lo.x;
    var terms = array<f32, 7>(t.lo.y, t.lo.z, t.lo.w, t.hi.x, t.hi.y, t.hi.z, t.hi.w);
    var power = r2 * r2;
    var slope_power = r2;
    for (var i = 0u; i < 7u; i = i + 1u) {
        z = z + terms[i] * power;
        m = m + f32(2u * i + 4u) * terms[i] * slope_power;
        power = power * r2;
        slope_power = slope_power * r2;
    }
    out.z = z;
    out.slope_over_r = m;
    out.ok = true;
    return out;
}

// A toroid (optics/lens.rs): the profile above at y^2 swept with the x-z curvature c_x; its sag at (x, y) and
// its two slopes, from (1 - c_x z)^2 + c_x^2 x^2 = (1 - c_x z_y)^2.
struct Toroid {
    z: f32,
    gx: f32,
    gy: f32,
    ok: bool,
};

fn is_toroid(st: Surface) -> bool {
    return SHAPES == 2u && has(st, STEP_TOROID);
}

// The sphere formulas alone (a sphere or a plane).
fn is_sphere(st: Surface) -> bool {
    return SHAPES == 0u || has(st, STEP_SPHERE);
}

fn toroid_sag(st: Surface, t: Terms, x: f32, y: f32) -> Toroid {
    var out: Toroid;
    out.ok = false;
    let profile = sag(st, t, y * y);
    if (!profile.ok) {
        return out;
    }
    let cx = bitcast<f32>(st.optics.w);
    let w = 1.0 - cx * profile.z;
    let root = w * w - cx * cx * x * x;
    if (w <= 0.0 || root < 0.0) {
        return out;
    }
    let z = profile.z + cx * x * x / (w + sqrt(root));
    let wz = 1.0 - cx * z;
    if (wz <= 0.0) {
        return out;
    }
    out.z = z;
    out.gx = cx * x / wz;
    out.gy = w * y * profile.slope_over_r / wz;
    out.ok = true;
    return out;
}

// `z - sag` at the point `at` of the line along d and its derivative along the line (x, y), and whether the
// sag is defined there (z 1) or not (z 0): an asphere's or a toroid's.
fn residual(st: Surface, terms: Terms, at: vec3<f32>, d: vec3<f32>) -> vec3<f32> {
    if (is_toroid(st)) {
        let t = toroid_sag(st, terms, at.x, at.y);
        return vec3<f32>(at.z - t.z, d.z - t.gx * d.x - t.gy * d.y, select(0.0, 1.0, t.ok));
    }
    let sg = sag(st, terms, at.x * at.x + at.y * at.y);
    return vec3<f32>(at.z - sg.z, d.z - sg.slope_over_r * (at.x * d.x + at.y * d.y), select(0.0, 1.0, sg.ok));
}

// Newton's method along p + s d from s (the CPU tracer's `newton`).
fn newton(p: vec3<f32>, d: vec3<f32>, start: f32, st: Surface, terms: Terms) -> Hit {
    var out: Hit;
    out.hit = false;
    var s = start;
    for (var i = 0u; i < MAX_NEWTON_STEPS; i = i + 1u) {
        let r = residual(st, terms, p + s * d, d);
        if (r.z == 0.0 || r.y == 0.0) {
            return out;
        }
        let step = r.x / r.y;
        s = s - step;
        if (abs(step) <= 1e-6 * (1.0 + abs(s))) {
            out.s = s;
            out.hit = true;
            return out;
        }
    }
    return out;
}

// Distance along d from p (relative to the vertex) to the step's surface; negative infinity-free: `hit` says.
struct Hit {
    s: f32,
    hit: bool,
};

// The surface kinds beyond the sphere are each evaluated in a loop of at most one pass, not behind a branch: a
// software rasteriser runs both sides of every branch, but skips a loop that no lane enters, so a lens's
// spherical steps do not pay for the aspheric and toroidal formulas (and the Newton iterations) of the others.
fn aspheric(st: Surface) -> bool {
    return !is_sphere(st) && !is_toroid(st);
}

// Step i of `job`'s path is `st`: its terms are read only where an asphere or a toroid needs them.
fn intersect(p: vec3<f32>, d: vec3<f32>, st: Surface, job: Job, i: u32) -> Hit {
    let c = st.surface.y;
    let z_dir = select(1.0, -1.0, has(st, STEP_BACKWARD));
    let q = select(1.0 + st.surface.z, 1.0, is_sphere(st));
    // The quadric (the sphere when spherical) by the stable root: a s^2 + 2 b s + g0 = 0.
    let g0 = c * (p.x * p.x + p.y * p.y + q * p.z * p.z) - 2.0 * p.z;
    let a = c * (d.x * d.x + d.y * d.y + q * d.z * d.z);
    let b = c * (p.x * d.x + p.y * d.y + q * p.z * d.z) - d.z;
    let disc = b * b - a * g0;
    let den = z_dir * sqrt(max(disc, 0.0)) - b;
    var out: Hit;
    out.hit = disc >= 0.0 && den != 0.0;
    out.s = select(0.0, g0 / den, out.hit);
    // An asphere: Newton's method from the quadric's root, or from the vertex plane where the quadric has none.
    for (var once = aspheric(st); once; once = false) {
        let start = select(-p.z / d.z, out.s, out.hit);
        out.hit = out.hit || d.z != 0.0;
        if (out.hit) {
            out = newton(p, d, start, st, terms_of(job, i));
        }
    }
    // A toroid: from the vertex plane (the CPU tracer's `intersect_toroid`).
    for (var once = is_toroid(st); once; once = false) {
        out.hit = d.z != 0.0;
        if (out.hit) {
            out = newton(p, d, -p.z / d.z, st, terms_of(job, i));
        }
    }
    return out;
}

// The unit normal at p (relative to the vertex) in xyz, w 1; w 0 where the surface is undefined.
fn normal_at(p: vec3<f32>, st: Surface, job: Job, i: u32) -> vec4<f32> {
    let c = st.surface.y;
    var n = vec4<f32>(normalize(vec3<f32>(-c * p.x, -c * p.y, 1.0 - c * p.z)), 1.0);
    for (var once = aspheric(st); once; once = false) {
        let sg = sag(st, terms_of(job, i), p.x * p.x + p.y * p.y);
        n = select(vec4<f32>(0.0), vec4<f32>(normalize(vec3<f32>(-sg.slope_over_r * p.x, -sg.slope_over_r * p.y, 1.0)), 1.0), sg.ok);
    }
    for (var once = is_toroid(st); once; once = false) {
        let t = toroid_sag(st, terms_of(job, i), p.x, p.y);
        n = select(vec4<f32>(0.0), vec4<f32>(normalize(vec3<f32>(-t.gx, -t.gy, 1.0)), 1.0), t.ok);
    }
    return n;
}

// Where the steps of a job's path are read from: the form is set when the pipeline is made. Must be kept in
// sync with `GpuRayGrid::chunked_paths` in crates/flare_core/src/render/raygrid.rs.
// - false (a GPU): one dispatch for every job; each workgroup copies its job's path into workgroup memory once
//   (every invocation of a workgroup traces the same job) and reads it there.
// - true (a software rasteriser): one dispatch per chunk of consecutive jobs whose paths fit one uniform binding
//   (`PathChunk`). lavapipe loads a storage or workgroup word whose address it cannot prove the same in every
//   lane one lane at a time, through the stack (a store-to-load stall a lane and component: three quarters of
//   the tracer's time); a uniform buffer it gathers with plain loads.
override CHUNKED_PATHS: bool = false;
// Steps a chunk holds: 16 + 255 x 64 = 16336 bytes, within the 16 KiB uniform binding every adapter offers. Must
// be kept in sync with `CHUNK_STEPS` in crates/flare_core/src/render/raygrid.rs.
const CHUNK_STEPS: u32 = 255u;

struct PathChunk {
    first: vec4<u32>,      // the chunk's first job, and the first step it holds (indices into the whole batch)
    steps: array<Step, CHUNK_STEPS>,
};

@group(0) @binding(4) var<uniform> chunk: PathChunk;

var<workgroup> path: array<Step, MAX_PATH_STEPS>;

// Step i of `job`'s path, from wherever this form keeps it: what every step needs, and the aspheric terms.
fn step_of(job: Job, i: u32) -> Surface {
    if (CHUNKED_PATHS) {
        let k = job.steps.x - chunk.first.y + i;
        return Surface(chunk.steps[k].surface, chunk.steps[k].optics);
    }
    return Surface(path[i].surface, path[i].optics);
}

fn terms_of(job: Job, i: u32) -> Terms {
    if (CHUNKED_PATHS) {
        let k = job.steps.x - chunk.first.y + i;
        return Terms(chunk.steps[k].terms_lo, chunk.steps[k].terms_hi);
    }
    return Terms(path[i].terms_lo, path[i].terms_hi);
}

@compute @workgroup_size(64)
fn trace_main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(workgroup_id) group: vec3<u32>,
    @builtin(local_invocation_index) local: u32) {
    let job = job_at(jobs, group.y + select(0u, chunk.first.x, CHUNKED_PATHS));
    for (var i = select(local, MAX_PATH_STEPS, CHUNKED_PATHS); i < min(job.steps.y, MAX_PATH_STEPS); i = i + 64u) {
        path[i] = steps[job.steps.x + i];
    }
    workgroupBarrier();
    let n = job.steps.w;
    let k = id.x;
    if (k >= (n + 1u) * (n + 1u)) {
        return;
    }
    var v: Vertex;
    v.valid = 0u;
    v.weight = 1.0;
    var p = vec3<f32>(job.region.x + f32(k % (n + 1u)) * job.region.z, job.region.y + f32(k / (n + 1u)) * job.region.w, 0.0);
    var d = job.direction.xyz;
    var crossings = 0u;
    var ratio2 = 0.0;
    // A ray outside every lit cell of the pre-pass is not traced (as on the CPU): it stays invalid.
    var alive = lit_at(job, p.xy);
    let stop_radius = job.view.w;
    for (var i = 0u; i < job.steps.y && alive; i = i + 1u) {
        let st = step_of(job, i);
        let vertex = vec3<f32>(0.0, 0.0, st.surface.x);
        let h = intersect(p - vertex, d, st, job, i);
        if (!h.hit) {
            alive = false;
            break;
        }
        p = p + h.s * d;
        let nn = normal_at(p - vertex, st, job, i);
        if (nn.w == 0.0) {
            alive = false;
            break;
        }
        let normal = nn.xyz;
        let cos_i = dot(d, normal);
        let c = min(abs(cos_i), 1.0);
        let r = table_at(st.optics.y, 1.0 - c * c);
        let reflect = has(st, STEP_REFLECT);
        if (reflect) {
            v.weight = v.weight * r;
        } else {
            v.weight = v.weight * (1.0 - r);
        }
        if (has(st, STEP_STOP)) {
            let q = p.xy / stop_radius;
            if (crossings == 0u) {
                v.stop0 = q;
            } else if (crossings == 1u) {
                v.stop1 = q;
            } else if (crossings == 2u) {
                v.stop2 = q;
            }
            crossings = crossings + 1u;
        } else {
            ratio2 = max(ratio2, dot(p.xy, p.xy) * st.surface.w);
        }
        let eta = bitcast<f32>(st.optics.x);
        if (reflect) {
            d = d - 2.0 * cos_i * normal;
        } else if (eta != 1.0) {
            let root = 1.0 - eta * eta * max(1.0 - cos_i * cos_i, 0.0);
            if (root < 0.0) {
                alive = false;
                break;
            }
            let cos_t = sign(cos_i) * sqrt(root);
            d = eta * d + (cos_t - eta * cos_i) * normal;
        }
    }
    v.ratio = sqrt(ratio2);
    if (alive && d.z > 0.0) {
        let t = (job.direction.w - p.z) / d.z;
        var landing = p + t * d;
        // The view's turn about the axis (the CPU twin's `View::seer`): the landing point and the stop
        // coordinates turn with the light; the blades, looked up at the turned coordinates, do not.
        let turn = job.rgb.w;
        if (turn != 0.0) {
            let cs = cos(turn);
            let sn = sin(turn);
            let m = mat2x2<f32>(vec2<f32>(cs, sn), vec2<f32>(-sn, cs));
            landing = vec3<f32>(m * landing.xy, landing.z);
            v.stop0 = m * v.stop0;
            v.stop1 = m * v.stop1;
            v.stop2 = m * v.stop2;
        }
        let kpx = job.view.z;
        v.pixel = vec2<f32>(0.5 * job.frame.x - (landing.x - job.view.x) * kpx, 0.5 * job.frame.y + (landing.y - job.view.y) * kpx);
        let finite = abs(v.pixel.x) < 1e30 && abs(v.pixel.y) < 1e30 && abs(v.weight) < 1e30 && v.ratio < 1e30;
        v.valid = select(0u, 1u, finite);
    }
    vertices[job.steps.z + k] = v;
}

