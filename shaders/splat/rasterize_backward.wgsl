// rasterize_backward.wgsl — backward of the tile rasterizer (INRIA
// `backward.cu` renderCUDA; reference `reference::rasterize_backward`).
// One 16×16 workgroup per tile; each pixel walks its tile list in reverse
// from its last contributor (batches loaded into workgroup memory from the
// back), recovers T_i = T_{i+1} / (1 − α_i) and accumulates dL/d(mean2d,
// conic, opacity, colour) per splat with `grad_add` (float atomics or a CAS
// loop, chosen by the host). `grads` uses the `ProjectedGrads` layout: 12
// floats per splat (mean2d 0..2, conic 4..7, opacity 7, colour 8..11).
// Each invocation owns PPT = 16 vertically adjacent pixels (a whole tile
// column) and sums their contributions to a splat in registers before one
// set of atomics, so the atomic count drops by up to PPT. On llvmpipe the
// subgroup reductions and atomics were ≈ 45 % of this kernel at PPT = 8
// (measured by dropping them); a whole column per invocation halves their
// count per pixel (fox, 100k splats: 545 → 340–410 ms under load, same run);
// the per-pixel state lives in the sixteen named fields of `Col` (an indexed
// private array would become per-lane scratch memory on llvmpipe); each
// block's list is walked LANES entries per step (`Chunk` in
// block_lists.wgsl); with subgroups, `grad_acc` further sums over the subgroup's lanes before
// one atomic per subgroup (see `kernel::GRAD_SUBGROUP_WGSL`).
// Traversal starts at the largest `last_contrib` of the tile.

// Bindings and injected constants: the `kernel!` declaration in
// crates/splat/src/gpu/rasterize_backward.rs.

const PPT: u32 = 16u;

var<workgroup> s_id: array<u32, 256>;
var<workgroup> s_mean_op: array<vec4<f32>, 256>;
var<workgroup> s_conic: array<vec4<f32>, 256>;
var<workgroup> s_color: array<vec4<f32>, 256>;
var<workgroup> wg_max_last: atomic<u32>;
var<workgroup> wg_last: u32;
// Per column block ("list", LIST_COLS columns × 16 rows; LIST_COLS comes
// from the host: 8 when every subgroup lies inside one block, else 16):
// the batch slots of splats that can touch the block, in traversal order.
const LISTS: u32 = TILE_SIZE / LIST_COLS;
var<workgroup> wg_list_max: array<atomic<u32>, 2>;
var<workgroup> wg_list_last: array<u32, 2>;

/// One pixel's backward state (reverse traversal).
struct Px {
    py: f32,
    t_final: f32,
    // List entries up to the last contributor (0 outside the image).
    last: u32,
    v_pix: vec3<f32>,
    // T_final · (background · dL/dpixel).
    t_bg: f32,
    tr: f32,
    behind: vec3<f32>,
    last_alpha: f32,
    last_color: vec3<f32>,
}

/// One invocation's gradient sums for the current splat.
struct Acc {
    mean: vec2<f32>,
    conic: vec3<f32>,
    op: f32,
    col: vec3<f32>,
    touched: bool,
}

fn px_init(x: u32, y: u32) -> Px {
    var p: Px;
    p.py = f32(y) + 0.5;
    p.t_final = 0.0;
    p.last = 0u;
    p.v_pix = vec3<f32>(0.0);
    if (x < cam.width && y < cam.height) {
        let pix = y * cam.width + x;
        p.t_final = final_t[pix];
        p.last = last_contrib[pix];
        p.v_pix = vec3<f32>(v_image[3u * pix], v_image[3u * pix + 1u], v_image[3u * pix + 2u]);
    }
    p.t_bg = p.t_final * dot(cam.background.xyz, p.v_pix);
    p.tr = p.t_final;
    p.behind = vec3<f32>(0.0);
    p.last_alpha = 0.0;
    p.last_color = vec3<f32>(0.0);
    return p;
}

/// Undo list entry `k_rel` (splat `mo`/`conic`/`color`) at one pixel and add
/// its gradient contributions to `acc`.
fn px_step(q: Px, acc: ptr<function, Acc>, k_rel: u32, mo: vec4<f32>, conic: vec3<f32>,
           color: vec3<f32>, px: f32) -> Px {
    var p = q;
    if (k_rel >= p.last) {
        return p;
    }
    let a = alpha_at(mo.xy, conic, mo.z, px, p.py);
    if (a.x < 0.0) {
        return p;
    }
    let alpha = a.x;
    let g = a.y;
    let dx = a.z;
    let dy = a.w;
    let inv = 1.0 / (1.0 - alpha);
    let tr = p.tr * inv;
    p.tr = tr;
    let behind = p.last_alpha * p.last_color + (1.0 - p.last_alpha) * p.behind;
    p.behind = behind;
    p.last_color = color;
    p.last_alpha = alpha;
    let v_pix = p.v_pix;
    let v_alpha = dot(color - behind, v_pix) * tr - p.t_bg * inv;
    (*acc).col += alpha * tr * v_pix;
    (*acc).touched = true;
    if (mo.z * g >= ALPHA_MAX) {
        return p;
    }
    (*acc).op += g * v_alpha;
    let v_power = g * (mo.z * v_alpha);
    (*acc).mean += v_power * vec2<f32>(-(conic.x * dx + conic.y * dy), -(conic.z * dy + conic.y * dx));
    (*acc).conic += v_power * vec3<f32>(-0.5 * dx * dx, -dx * dy, -0.5 * dy * dy);
    return p;
}

/// Undo one list entry at the column's sixteen pixels, then add the
/// column's (and, with subgroups, the subgroup's) gradient sums to the
/// splat's. Call from subgroup-uniform control flow.
fn col_step(c: ptr<function, Col>, e: Entry, px: f32, my_max: u32, leader: bool) {
    var acc: Acc;
    acc.mean = vec2<f32>(0.0);
    acc.conic = vec3<f32>(0.0);
    acc.op = 0.0;
    acc.col = vec3<f32>(0.0);
    acc.touched = false;
    let k_rel = e.key;
    if (k_rel < my_max) {
        let conic = e.conic.xyz;
        let color = e.color.xyz;
        (*c).p0 = px_step((*c).p0, &acc, k_rel, e.mo, conic, color, px);
        (*c).p1 = px_step((*c).p1, &acc, k_rel, e.mo, conic, color, px);
        (*c).p2 = px_step((*c).p2, &acc, k_rel, e.mo, conic, color, px);
        (*c).p3 = px_step((*c).p3, &acc, k_rel, e.mo, conic, color, px);
        (*c).p4 = px_step((*c).p4, &acc, k_rel, e.mo, conic, color, px);
        (*c).p5 = px_step((*c).p5, &acc, k_rel, e.mo, conic, color, px);
        (*c).p6 = px_step((*c).p6, &acc, k_rel, e.mo, conic, color, px);
        (*c).p7 = px_step((*c).p7, &acc, k_rel, e.mo, conic, color, px);
        (*c).p8 = px_step((*c).p8, &acc, k_rel, e.mo, conic, color, px);
        (*c).p9 = px_step((*c).p9, &acc, k_rel, e.mo, conic, color, px);
        (*c).p10 = px_step((*c).p10, &acc, k_rel, e.mo, conic, color, px);
        (*c).p11 = px_step((*c).p11, &acc, k_rel, e.mo, conic, color, px);
        (*c).p12 = px_step((*c).p12, &acc, k_rel, e.mo, conic, color, px);
        (*c).p13 = px_step((*c).p13, &acc, k_rel, e.mo, conic, color, px);
        (*c).p14 = px_step((*c).p14, &acc, k_rel, e.mo, conic, color, px);
        (*c).p15 = px_step((*c).p15, &acc, k_rel, e.mo, conic, color, px);
    }
    if (grad_any(acc.touched)) {
        let base = 12u * e.id;
        grad_acc(base + 0u, acc.mean.x, leader);
        grad_acc(base + 1u, acc.mean.y, leader);
        grad_acc(base + 4u, acc.conic.x, leader);
        grad_acc(base + 5u, acc.conic.y, leader);
        grad_acc(base + 6u, acc.conic.z, leader);
        grad_acc(base + 7u, acc.op, leader);
        grad_acc(base + 8u, acc.col.x, leader);
        grad_acc(base + 9u, acc.col.y, leader);
        grad_acc(base + 10u, acc.col.z, leader);
    }
}

@compute @workgroup_size(THREADS, 1)
fn rasterize_backward_main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid3: vec3<u32>,
                           @builtin(local_invocation_index) lid: u32) {
    let tile = wid.y * cam.grid_x + wid.x;
    let x = wid.x * TILE_SIZE + lid3.x;
    let y0 = wid.y * TILE_SIZE + lid3.y * PPT;
    let px = f32(x) + 0.5;
    let start = ranges[2u * tile];
    let end = max(ranges[2u * tile + 1u], start);
    let lane = lane_index();
    var col = col_init(x, y0);
    let my_max = max(max(max(max(col.p0.last, col.p1.last), max(col.p2.last, col.p3.last)),
        max(max(col.p4.last, col.p5.last), max(col.p6.last, col.p7.last))),
        max(max(max(col.p8.last, col.p9.last), max(col.p10.last, col.p11.last)),
        max(max(col.p12.last, col.p13.last), max(col.p14.last, col.p15.last))));
    let my_list = lid3.x / LIST_COLS;
    if (lid == 0u) {
        atomicStore(&wg_max_last, 0u);
        atomicStore(&wg_list_max[0], 0u);
        atomicStore(&wg_list_max[1], 0u);
    }
    workgroupBarrier();
    atomicMax(&wg_max_last, my_max);
    atomicMax(&wg_list_max[my_list], my_max);
    workgroupBarrier();
    if (lid == 0u) {
        wg_last = atomicLoad(&wg_max_last);
        wg_list_last[0] = atomicLoad(&wg_list_max[0]);
        wg_list_last[1] = atomicLoad(&wg_list_max[1]);
    }
    let max_last = workgroupUniformLoad(&wg_last);
    let list_last0 = wg_list_last[0];
    let list_last1 = wg_list_last[1];
    // Pixel-centre bounds of the two column blocks.
    let bmin0 = vec2<f32>(f32(wid.x * TILE_SIZE) + 0.5, f32(wid.y * TILE_SIZE) + 0.5);
    let bmax0 = bmin0 + vec2<f32>(f32(LIST_COLS - 1u), f32(TILE_SIZE - 1u));
    let bmin1 = bmin0 + vec2<f32>(f32(LIST_COLS), 0.0);
    let bmax1 = bmax0 + vec2<f32>(f32(LIST_COLS), 0.0);
    // Every invocation is active here: pick each subgroup's atomic issuer once.
    let leader = grad_leader(lid);
    // Batches from the back: [batch_lo, batch_hi).
    var batch_hi = min(end, start + max_last);
    loop {
        if (batch_hi <= start) {
            break;
        }
        let batch_lo = max(start, select(0u, batch_hi - TILE_PIXELS, batch_hi >= TILE_PIXELS));
        let count = batch_hi - batch_lo;
        workgroupBarrier();
        // Load: invocation `lid` fills slots [16·lid, 16·lid + 16) and flags
        // the splats that can touch each block (`alpha_box`, conservative, and
        // not past the block's last contributor), then the flags are
        // compacted in order: each block walks only its own list, so a splat
        // that misses a block costs it nothing (llvmpipe executes masked
        // `if` bodies anyway, but not loop iterations that do not exist).
        var f0 = 0u;
        var f1 = 0u;
        for (var q = 0u; q < TILE_PIXELS / THREADS; q++) {
            let idx = lid * (TILE_PIXELS / THREADS) + q;
            if (idx < count) {
                let k = batch_hi - 1u - idx;
                let id = tile_values[k];
                let p = projected[id];
                s_id[idx] = id;
                s_mean_op[idx] = vec4<f32>(p.mean_x, p.mean_y, p.opacity, 0.0);
                let conic = vec3<f32>(p.conic_a, p.conic_b, p.conic_c);
                s_conic[idx] = vec4<f32>(conic, 0.0);
                s_color[idx] = vec4<f32>(p.color_r, p.color_g, p.color_b, 0.0);
                let k_rel = k - start;
                let mean = vec2<f32>(p.mean_x, p.mean_y);
                let half = alpha_box(conic, p.opacity);
                if (k_rel < list_last0 && !box_misses(mean, half, bmin0, bmax0)) {
                    f0 |= 1u << q;
                }
                if (LISTS > 1u && k_rel < list_last1 && !box_misses(mean, half, bmin1, bmax1)) {
                    f1 |= 1u << q;
                }
            }
        }
        compact_block_lists(lid, f0, f1, LISTS);
        // The trip count is uniform over a block's invocations, so the loop
        // stays subgroup-uniform for `lane_chunk` and `grad_acc` (entries at
        // or past a pixel's `last` are skipped in `px_step`).
        let len = s_len[my_list];
        for (var m0 = 0u; m0 < len; m0 += LANES) {
            var mine = entry_none();
            if (m0 + lane < len) {
                let j = s_list[my_list * TILE_PIXELS + m0 + lane];
                // Position in the tile list.
                let k_rel = batch_hi - 1u - j - start;
                mine = Entry(s_mean_op[j], s_conic[j], s_color[j], k_rel, s_id[j]);
            }
            let ch = lane_chunk(mine);
            col_step(&col, ch.e0, px, my_max, leader);
            if (LANES > 1u) {
                col_step(&col, ch.e1, px, my_max, leader);
                col_step(&col, ch.e2, px, my_max, leader);
                col_step(&col, ch.e3, px, my_max, leader);
                col_step(&col, ch.e4, px, my_max, leader);
                col_step(&col, ch.e5, px, my_max, leader);
                col_step(&col, ch.e6, px, my_max, leader);
                col_step(&col, ch.e7, px, my_max, leader);
            }
        }
        batch_hi = batch_lo;
    }
}
