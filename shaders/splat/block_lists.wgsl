// block_lists.wgsl — per-column-block splat lists and the tile column's
// pixels `Col`, shared by rasterize.wgsl and rasterize_backward.wgsl
// (prepended to each by its host module).
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

// One list entry as the rasterizers walk it: `mo` = mean x, mean y,
// opacity; `conic` = a, b, c; `color` = r, g, b; `key` = its position in
// the tile list (forward) or relative to the tile start (backward); `id` =
// the splat (backward). `entry_none` is a no-op: opacity 0 gives α = 0.
struct Entry {
    mo: vec4<f32>,
    conic: vec4<f32>,
    color: vec4<f32>,
    key: u32,
    id: u32,
}

fn entry_none() -> Entry {
    return Entry(vec4<f32>(0.0), vec4<f32>(1.0, 0.0, 1.0, 0.0), vec4<f32>(0.0), 0xffffffffu, 0u);
}

// A list walked LANES entries at a time: lane t of the subgroup fetches
// entry m0 + t from workgroup memory and `lane_chunk` hands every lane all
// of them (e0..e7; with LANES = 1 only e0 is used). On llvmpipe a
// workgroup-memory read whose index it cannot prove uniform is a loop of
// per-lane scalar loads through the stack, which dominated both
// rasterizers when every lane read every entry; one such read per chunk
// and constant-lane broadcasts (a register extract) cost ~LANES× less.
// `LANES`, `lane_index` and `lane_chunk` come from the host
// (`kernel::lane_wgsl`): 8 when every subgroup is exactly one 8-column
// block, else 1.
struct Chunk {
    e0: Entry,
    e1: Entry,
    e2: Entry,
    e3: Entry,
    e4: Entry,
    e5: Entry,
    e6: Entry,
    e7: Entry,
}

// The sixteen pixels of one tile column as named fields (an indexed private
// array would live in per-lane scratch memory on llvmpipe). `Px` and
// `px_init` are each rasterizer's own pixel state (WGSL resolves
// module-scope names in any order).
struct Col {
    p0: Px,
    p1: Px,
    p2: Px,
    p3: Px,
    p4: Px,
    p5: Px,
    p6: Px,
    p7: Px,
    p8: Px,
    p9: Px,
    p10: Px,
    p11: Px,
    p12: Px,
    p13: Px,
    p14: Px,
    p15: Px,
}

// Column x's pixels from row y0, each in its initial state.
fn col_init(x: u32, y0: u32) -> Col {
    return Col(px_init(x, y0), px_init(x, y0 + 1u), px_init(x, y0 + 2u), px_init(x, y0 + 3u),
        px_init(x, y0 + 4u), px_init(x, y0 + 5u), px_init(x, y0 + 6u), px_init(x, y0 + 7u),
        px_init(x, y0 + 8u), px_init(x, y0 + 9u), px_init(x, y0 + 10u), px_init(x, y0 + 11u),
        px_init(x, y0 + 12u), px_init(x, y0 + 13u), px_init(x, y0 + 14u), px_init(x, y0 + 15u));
}
