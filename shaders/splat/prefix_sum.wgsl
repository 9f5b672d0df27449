// prefix_sum.wgsl — exclusive scan of u32 (per-splat tile counts, radix
// digit counts). Blocks of 256 are scanned in workgroup memory
// (Hillis–Steele), block totals are scanned recursively by the host, then
// added back. `write_total` stores the grand total at output[n].

struct ScanUniforms {
    n: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

// Bindings and injected constants: the `kernel!` declaration in
// crates/splat/src/gpu/prefix_sum.rs.

var<workgroup> tmp: array<u32, WORKGROUP_SIZE>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn scan_blocks(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
               @builtin(local_invocation_index) lid: u32) {
    let block = wid.y * nwg.x + wid.x;
    let i = block * WORKGROUP_SIZE + lid;
    var v = 0u;
    if (i < u.n) {
        v = input[i];
    }
    tmp[lid] = v;
    workgroupBarrier();
    for (var off = 1u; off < WORKGROUP_SIZE; off = off * 2u) {
        var add = 0u;
        if (lid >= off) {
            add = tmp[lid - off];
        }
        workgroupBarrier();
        tmp[lid] = tmp[lid] + add;
        workgroupBarrier();
    }
    if (i < u.n) {
        output[i] = tmp[lid] - v;
    }
    if (lid == WORKGROUP_SIZE - 1u) {
        block_sums[block] = tmp[lid];
    }
}

// output[i] += block_sums[block of i] (block_sums already scanned, exclusive).
@compute @workgroup_size(WORKGROUP_SIZE)
fn add_block_offsets(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
                     @builtin(local_invocation_index) lid: u32) {
    let block = wid.y * nwg.x + wid.x;
    let i = block * WORKGROUP_SIZE + lid;
    if (i < u.n) {
        output[i] = output[i] + block_sums[block];
    }
}

// output[n] = output[n-1] + input[n-1] (0 when n == 0).
@compute @workgroup_size(1)
fn write_total() {
    if (u.n == 0u) {
        output[0] = 0u;
    } else {
        output[u.n] = output[u.n - 1u] + input[u.n - 1u];
    }
}
