// radix_sort.wgsl — one pass of a stable LSD radix sort of (u32 key, u32
// value) pairs on 4-bit digits. `count` builds per-block digit histograms
// (digit-major, so an exclusive scan gives every block's output offset per
// digit); `scatter` ranks each element among equal digits of its block
// (packed 16-bit counters, Hillis–Steele scan) and writes it out. Stable, so
// passes over increasing `shift` sort by the whole key.

struct SortUniforms {
    n: u32,
    shift: u32,
    num_blocks: u32,
    // Digit mask: (1 << bits of this pass) - 1, so bits above the sorted
    // width are ignored.
    digit_mask: u32,
}

@group(0) @binding(0) var<uniform> u: SortUniforms;
@group(0) @binding(1) var<storage, read> keys_in: array<u32>;
@group(0) @binding(2) var<storage, read> values_in: array<u32>;
@group(0) @binding(3) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(4) var<storage, read_write> values_out: array<u32>;
@group(0) @binding(5) var<storage, read_write> counts: array<u32>;
@group(0) @binding(6) var<storage, read> offsets: array<u32>;

const SORT_WG: u32 = 256u;
const RADIX: u32 = 16u;

var<workgroup> hist: array<atomic<u32>, 16>;
// 16 digits × 16-bit counters = 8 words per invocation.
var<workgroup> packed: array<u32, 2048>;

@compute @workgroup_size(256)
fn count(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_index) lid: u32) {
    let block = wid.y * nwg.x + wid.x;
    if (lid < RADIX) {
        atomicStore(&hist[lid], 0u);
    }
    workgroupBarrier();
    let i = block * SORT_WG + lid;
    if (i < u.n) {
        let d = (keys_in[i] >> u.shift) & u.digit_mask;
        atomicAdd(&hist[d], 1u);
    }
    workgroupBarrier();
    if (lid < RADIX && block < u.num_blocks) {
        counts[lid * u.num_blocks + block] = atomicLoad(&hist[lid]);
    }
}

@compute @workgroup_size(256)
fn scatter(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
           @builtin(local_invocation_index) lid: u32) {
    let block = wid.y * nwg.x + wid.x;
    let i = block * SORT_WG + lid;
    var d = RADIX; // no digit for padding invocations
    var key = 0u;
    var value = 0u;
    if (i < u.n) {
        key = keys_in[i];
        value = values_in[i];
        d = (key >> u.shift) & u.digit_mask;
    }
    for (var w = 0u; w < 8u; w++) {
        packed[lid * 8u + w] = 0u;
    }
    if (d < RADIX) {
        packed[lid * 8u + d / 2u] = 1u << (16u * (d % 2u));
    }
    workgroupBarrier();
    for (var off = 1u; off < SORT_WG; off = off * 2u) {
        var add: array<u32, 8>;
        for (var w = 0u; w < 8u; w++) {
            add[w] = 0u;
            if (lid >= off) {
                add[w] = packed[(lid - off) * 8u + w];
            }
        }
        workgroupBarrier();
        for (var w = 0u; w < 8u; w++) {
            packed[lid * 8u + w] = packed[lid * 8u + w] + add[w];
        }
        workgroupBarrier();
    }
    if (d < RADIX && block < u.num_blocks) {
        let inclusive = (packed[lid * 8u + d / 2u] >> (16u * (d % 2u))) & 0xffffu;
        let dst = offsets[d * u.num_blocks + block] + inclusive - 1u;
        keys_out[dst] = key;
        values_out[dst] = value;
    }
}
