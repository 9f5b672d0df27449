// block_lists.wgsl — per-column-block splat lists, shared by rasterize.wgsl
// and rasterize_backward.wgsl (prepended to each by its host module).
// Each invocation has flagged, in `f0` / `f1` (bit q = its slot
// 16·lid + q), the splats of the current batch that can touch column block
// 0 / 1; `compact_block_lists` turns the flags into ordered lists
// `s_list[b·TILE_PIXELS + m]`, m < `s_len[b]`, for the first `lists` blocks.
// Call it from workgroup-uniform control flow (it contains barriers); the
// lists are ready when it returns.

var<workgroup> s_list: array<u32, 512>;
var<workgroup> s_cnt: array<u32, 32>;
var<workgroup> s_len: array<u32, 2>;

fn compact_block_lists(lid: u32, f0: u32, f1: u32, lists: u32) {
    s_cnt[lid] = countOneBits(f0);
    s_cnt[THREADS + lid] = countOneBits(f1);
    workgroupBarrier();
    // Exclusive scan of the per-invocation counts, one invocation per list.
    if (lid < lists) {
        var total = 0u;
        for (var t = 0u; t < THREADS; t++) {
            let c = s_cnt[lid * THREADS + t];
            s_cnt[lid * THREADS + t] = total;
            total += c;
        }
        s_len[lid] = total;
    }
    workgroupBarrier();
    var o0 = s_cnt[lid];
    var o1 = TILE_PIXELS + s_cnt[THREADS + lid];
    for (var q = 0u; q < TILE_PIXELS / THREADS; q++) {
        let idx = lid * (TILE_PIXELS / THREADS) + q;
        if (((f0 >> q) & 1u) != 0u) {
            s_list[o0] = idx;
            o0++;
        }
        if (((f1 >> q) & 1u) != 0u) {
            s_list[o1] = idx;
            o1++;
        }
    }
    workgroupBarrier();
}
