// radix_sort.wgsl — one pass of a stable LSD radix sort of (u32 key, u32
// value) pairs on 4-bit digits. `count` builds per-block digit histograms
// (digit-major, so an exclusive scan gives every block's output offset per
// digit); `scatter` ranks each element among equal digits of its block
// (per-digit bit masks + popcount) and writes it out. Stable, so
// passes over increasing `shift` sort by the whole key.

struct SortUniforms {
    n: u32,
    shift: u32,
    num_blocks: u32,
    // Digit mask: (1 << bits of this pass) - 1, so bits above the sorted
    // width are ignored.
    digit_mask: u32,
}

// Bindings and injected constants: the `kernel!` declaration in
// crates/splat/src/gpu/radix_sort.rs.

var<workgroup> hist: array<atomic<u32>, RADIX>;
// Per digit, a 256-bit mask of the block's elements holding it (8 words).
var<workgroup> masks: array<atomic<u32>, 128>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn count(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_index) lid: u32) {
    let block = wid.y * nwg.x + wid.x;
    if (lid < RADIX) {
        atomicStore(&hist[lid], 0u);
    }
    workgroupBarrier();
    let i = block * WORKGROUP_SIZE + lid;
    if (i < u.n) {
        let d = (keys_in[i] >> u.shift) & u.digit_mask;
        atomicAdd(&hist[d], 1u);
    }
    workgroupBarrier();
    if (lid < RADIX && block < u.num_blocks) {
        counts[lid * u.num_blocks + block] = atomicLoad(&hist[lid]);
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn scatter(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
           @builtin(local_invocation_index) lid: u32) {
    let block = wid.y * nwg.x + wid.x;
    let i = block * WORKGROUP_SIZE + lid;
    var d = RADIX; // no digit for padding invocations
    var key = 0u;
    var value = 0u;
    if (i < u.n) {
        key = keys_in[i];
        value = values_in[i];
        d = (key >> u.shift) & u.digit_mask;
    }
    if (lid < RADIX * 8u) {
        atomicStore(&masks[lid], 0u);
    }
    workgroupBarrier();
    let word = lid / 32u;
    let bit = lid % 32u;
    if (d < RADIX) {
        atomicOr(&masks[d * 8u + word], 1u << bit);
    }
    workgroupBarrier();
    if (d < RADIX && block < u.num_blocks) {
        // Rank among equal digits of this block = set bits below `lid`.
        var rank = countOneBits(atomicLoad(&masks[d * 8u + word]) & ((1u << bit) - 1u));
        for (var w = 0u; w < word; w++) {
            rank += countOneBits(atomicLoad(&masks[d * 8u + w]));
        }
        let dst = offsets[d * u.num_blocks + block] + rank;
        keys_out[dst] = key;
        values_out[dst] = value;
    }
}
