// A workgroup's inclusive scan of 64-bit fixed-point sums, three channels at a time, shared by the resolves
// that sum a row 256 columns at a time on a GPU (prepended, after fixed64.wgsl, to ghosts_compute.wgsl and
// raygrid_box.wgsl when they are embedded; the entry points that call it have 256 invocations). CPU side: the
// per-row sums of render/cpu/ghosts.rs and raytrace's box filter, which add the same integers in order.

// The three channels' 64-bit sums of a column (or of a run of columns) as vectors: the low words and the high
// words. Vectors rather than an array of three (low, high) pairs: the compiler keeps them in registers, where an
// array indexed in a loop may go to memory; on an H200 the ghosts' per-row sum took 0.78 ms of a 4K frame with
// arrays, 0.44 ms with these.
struct Sums {
    lo: vec3<u32>,
    hi: vec3<u32>,
};

fn no_sums() -> Sums {
    return Sums(vec3<u32>(0u), vec3<u32>(0u));
}

// a + b modulo 2^64 per channel (`add64` of fixed64.wgsl, three at a time).
fn add_sums(a: Sums, b: Sums) -> Sums {
    let lo = a.lo + b.lo;
    return Sums(lo, a.hi + b.hi + select(vec3<u32>(0u), vec3<u32>(1u), lo < a.lo));
}

// The sums as floats (`float64` of fixed64.wgsl per channel), before their unit is applied.
fn float_sums(s: Sums) -> vec3<f32> {
    return vec3<f32>(bitcast<vec3<i32>>(s.hi)) * 4294967296.0 + vec3<f32>(s.lo);
}

// Columns of a chunk, one an invocation.
const CHUNK: u32 = 256u;
// A chunk's running sums, one an invocation.
var<workgroup> chunk: array<Sums, 256>;

// The inclusive scan over the workgroup's 256 invocations of `v` (Hillis-Steele, 8 steps, each invocation's
// running sum kept in a register); the chunk's total is left in `chunk[CHUNK - 1]` until the next barrier.
// Called from uniform control flow.
fn scan_chunk(t: u32, v: Sums) -> Sums {
    var sum = v;
    chunk[t] = sum;
    workgroupBarrier();
    for (var step = 1u; step < CHUNK; step = step * 2u) {
        var add = no_sums();
        if (t >= step) {
            add = chunk[t - step];
        }
        workgroupBarrier();
        sum = add_sums(sum, add);
        chunk[t] = sum;
        workgroupBarrier();
    }
    return sum;
}
