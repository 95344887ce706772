// A workgroup's inclusive scan of 64-bit fixed-point sums (Hillis-Steele, 6 steps), shared by the resolves
// that sum a row 64 columns at a time on a GPU (prepended, after fixed64.wgsl, to ghosts_compute.wgsl and
// raygrid_box.wgsl when they are embedded). CPU side: the per-row sums of render/cpu/ghosts.rs and
// raytrace's box filter, which add the same integers in order.

// The running sums of one chunk of 64 columns (three channels each).
var<workgroup> scan_chunk: array<vec2<u32>, 192>;

// The inclusive scan over the workgroup's 64 invocations of `v`; the chunk's total is left in
// `scan_chunk[63 * 3 + c]` until the next barrier. Called from uniform control flow.
fn scan64(t: u32, v: array<vec2<u32>, 3>) -> array<vec2<u32>, 3> {
    for (var c = 0u; c < 3u; c = c + 1u) {
        scan_chunk[t * 3u + c] = v[c];
    }
    workgroupBarrier();
    for (var step = 1u; step < 64u; step = step * 2u) {
        var add = array<vec2<u32>, 3>(vec2<u32>(0u), vec2<u32>(0u), vec2<u32>(0u));
        if (t >= step) {
            for (var c = 0u; c < 3u; c = c + 1u) {
                add[c] = scan_chunk[(t - step) * 3u + c];
            }
        }
        workgroupBarrier();
        if (t >= step) {
            for (var c = 0u; c < 3u; c = c + 1u) {
                scan_chunk[t * 3u + c] = add64(scan_chunk[t * 3u + c], add[c]);
            }
        }
        workgroupBarrier();
    }
    var out = array<vec2<u32>, 3>(vec2<u32>(0u), vec2<u32>(0u), vec2<u32>(0u));
    for (var c = 0u; c < 3u; c = c + 1u) {
        out[c] = scan_chunk[t * 3u + c];
    }
    return out;
}
