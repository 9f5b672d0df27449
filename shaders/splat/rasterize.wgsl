// rasterize.wgsl — forward tile rasterizer (Kerbl et al. 2023 §6, INRIA
// `renderCUDA`): one workgroup per 16×16 tile, the tile's depth-sorted splats
// loaded into workgroup memory 256 at a time, front-to-back compositing per
// pixel (α ≤ 0.99, α < 1/255 skipped, stop before T < 1e-4), background
// weighted by the final transmittance. Writes what backward needs: final T
// and the count of list entries up to the last contributor.
// Each invocation owns PPT vertically adjacent pixels of the tile, so one
// read of a splat from workgroup memory serves PPT pixels: on CPU drivers
// (llvmpipe) every workgroup-memory read inside a loop is a per-lane gather,
// and those reads, not the arithmetic, dominated the 1-pixel-per-invocation
// kernel. The sixteen pixels (a whole tile column) are the named fields of
// `Col` (an indexed private array would become per-lane scratch memory).
// Each 8-column block walks only the splats that can reach it (see the
// batch loop), LANES entries per step (`Chunk` in block_lists.wgsl).

// Bindings and injected constants: the `kernel!` declaration in
// crates/splat/src/gpu/rasterize.rs.

const PPT: u32 = 16u;
// Column blocks of 8 × 16 pixels (one SIMD group on llvmpipe), each with its
// own list of the batch's splats that can reach it.
const BLOCK_COLS: u32 = 8u;

var<workgroup> s_mean_op: array<vec4<f32>, 256>;  // mean x, mean y, opacity
var<workgroup> s_conic: array<vec4<f32>, 256>;    // a, b, c
var<workgroup> s_color: array<vec4<f32>, 256>;    // r, g, b
var<workgroup> n_done: atomic<u32>;
var<workgroup> all_done: u32;

/// One pixel's compositing state.
struct Px {
    py: f32,
    tr: f32,
    col: vec3<f32>,
    last: u32,
    live: bool,
}

fn px_init(x: u32, y: u32) -> Px {
    return Px(f32(y) + 0.5, 1.0, vec3<f32>(0.0), 0u, x < cam.width && y < cam.height);
}

/// Composite list entry `pos` (0-based in the tile list) at one pixel.
fn px_step(q: Px, pos: u32, mo: vec4<f32>, conic: vec3<f32>, color: vec3<f32>, px: f32) -> Px {
    var p = q;
    if (!p.live) {
        return p;
    }
    let a = alpha_at(mo.xy, conic, mo.z, px, p.py);
    if (a.x < 0.0) {
        return p;
    }
    let tr = p.tr;
    let next = tr * (1.0 - a.x);
    if (next < T_MIN) {
        p.live = false;
        return p;
    }
    p.col += color * a.x * tr;
    p.tr = next;
    p.last = pos + 1u;
    return p;
}

/// Composite one list entry at the column's sixteen pixels.
fn col_step(c: ptr<function, Col>, e: Entry, px: f32) {
    let conic = e.conic.xyz;
    let color = e.color.xyz;
    (*c).p0 = px_step((*c).p0, e.key, e.mo, conic, color, px);
    (*c).p1 = px_step((*c).p1, e.key, e.mo, conic, color, px);
    (*c).p2 = px_step((*c).p2, e.key, e.mo, conic, color, px);
    (*c).p3 = px_step((*c).p3, e.key, e.mo, conic, color, px);
    (*c).p4 = px_step((*c).p4, e.key, e.mo, conic, color, px);
    (*c).p5 = px_step((*c).p5, e.key, e.mo, conic, color, px);
    (*c).p6 = px_step((*c).p6, e.key, e.mo, conic, color, px);
    (*c).p7 = px_step((*c).p7, e.key, e.mo, conic, color, px);
    (*c).p8 = px_step((*c).p8, e.key, e.mo, conic, color, px);
    (*c).p9 = px_step((*c).p9, e.key, e.mo, conic, color, px);
    (*c).p10 = px_step((*c).p10, e.key, e.mo, conic, color, px);
    (*c).p11 = px_step((*c).p11, e.key, e.mo, conic, color, px);
    (*c).p12 = px_step((*c).p12, e.key, e.mo, conic, color, px);
    (*c).p13 = px_step((*c).p13, e.key, e.mo, conic, color, px);
    (*c).p14 = px_step((*c).p14, e.key, e.mo, conic, color, px);
    (*c).p15 = px_step((*c).p15, e.key, e.mo, conic, color, px);
}

fn col_live(c: Col) -> u32 {
    return u32(c.p0.live) + u32(c.p1.live) + u32(c.p2.live) + u32(c.p3.live) + u32(c.p4.live)
        + u32(c.p5.live) + u32(c.p6.live) + u32(c.p7.live) + u32(c.p8.live) + u32(c.p9.live)
        + u32(c.p10.live) + u32(c.p11.live) + u32(c.p12.live) + u32(c.p13.live)
        + u32(c.p14.live) + u32(c.p15.live);
}

fn px_write(p: Px, x: u32, y: u32) {
    if (x < cam.width && y < cam.height) {
        let pix = y * cam.width + x;
        let c = p.col + p.tr * cam.background.xyz;
        image[3u * pix] = c.x;
        image[3u * pix + 1u] = c.y;
        image[3u * pix + 2u] = c.z;
        final_t[pix] = p.tr;
        last_contrib[pix] = p.last;
    }
}

@compute @workgroup_size(THREADS, 1)
fn rasterize_main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid3: vec3<u32>,
                  @builtin(local_invocation_index) lid: u32) {
    let tile = wid.y * cam.grid_x + wid.x;
    let x = wid.x * TILE_SIZE + lid3.x;
    let y0 = wid.y * TILE_SIZE + lid3.y * PPT;
    let px = f32(x) + 0.5;
    let my_block = lid3.x / BLOCK_COLS;
    let bmin0 = vec2<f32>(f32(wid.x * TILE_SIZE) + 0.5, f32(wid.y * TILE_SIZE) + 0.5);
    let bmax0 = bmin0 + vec2<f32>(f32(BLOCK_COLS - 1u), f32(TILE_SIZE - 1u));
    let bmin1 = bmin0 + vec2<f32>(f32(BLOCK_COLS), 0.0);
    let bmax1 = bmax0 + vec2<f32>(f32(BLOCK_COLS), 0.0);
    let start = ranges[2u * tile];
    let end = max(ranges[2u * tile + 1u], start);
    if (lid == 0u) {
        atomicStore(&n_done, 0u);
    }
    workgroupBarrier();
    let lane = lane_index();
    var col = col_init(x, y0);
    var done = col_live(col) == 0u;
    if (done) {
        atomicAdd(&n_done, 1u);
    }
    for (var batch = start; batch < end; batch += TILE_PIXELS) {
        workgroupBarrier();
        if (lid == 0u) {
            all_done = atomicLoad(&n_done);
        }
        if (workgroupUniformLoad(&all_done) == THREADS) {
            break;
        }
        // Load slots [16·lid, 16·lid + 16), flag the splats whose α ≥ 1/255
        // box (`alpha_box`, conservative) meets each column block, and
        // compact the flags in order: a block walks only its own list, so a
        // splat that cannot reach it costs it nothing (llvmpipe runs masked
        // `if` bodies anyway, but not loop iterations that do not exist).
        var f0 = 0u;
        var f1 = 0u;
        for (var q = 0u; q < TILE_PIXELS / THREADS; q++) {
            let idx = lid * (TILE_PIXELS / THREADS) + q;
            let k = batch + idx;
            if (k < end) {
                let p = projected[tile_values[k]];
                s_mean_op[idx] = vec4<f32>(p.mean_x, p.mean_y, p.opacity, 0.0);
                let conic = vec3<f32>(p.conic_a, p.conic_b, p.conic_c);
                s_conic[idx] = vec4<f32>(conic, 0.0);
                s_color[idx] = vec4<f32>(p.color_r, p.color_g, p.color_b, 0.0);
                let mean = vec2<f32>(p.mean_x, p.mean_y);
                let half = alpha_box(conic, p.opacity);
                if (!box_misses(mean, half, bmin0, bmax0)) {
                    f0 |= 1u << q;
                }
                if (!box_misses(mean, half, bmin1, bmax1)) {
                    f1 |= 1u << q;
                }
            }
        }
        compact_block_lists(lid, f0, f1, 2u);
        let len = s_len[my_block];
        // Subgroup-uniform trip count (the chunk broadcasts need every lane):
        // a lane whose pixels are all done keeps fetching, its steps are no-ops.
        for (var m0 = 0u; m0 < len && !lane_all(done); m0 += LANES) {
            var mine = entry_none();
            if (m0 + lane < len) {
                let j = s_list[my_block * TILE_PIXELS + m0 + lane];
                mine = Entry(s_mean_op[j], s_conic[j], s_color[j], batch - start + j, 0u);
            }
            let ch = lane_chunk(mine);
            col_step(&col, ch.e0, px);
            if (LANES > 1u) {
                col_step(&col, ch.e1, px);
                col_step(&col, ch.e2, px);
                col_step(&col, ch.e3, px);
                col_step(&col, ch.e4, px);
                col_step(&col, ch.e5, px);
                col_step(&col, ch.e6, px);
                col_step(&col, ch.e7, px);
            }
            if (!done && col_live(col) == 0u) {
                done = true;
                atomicAdd(&n_done, 1u);
            }
        }
    }
    px_write(col.p0, x, y0);
    px_write(col.p1, x, y0 + 1u);
    px_write(col.p2, x, y0 + 2u);
    px_write(col.p3, x, y0 + 3u);
    px_write(col.p4, x, y0 + 4u);
    px_write(col.p5, x, y0 + 5u);
    px_write(col.p6, x, y0 + 6u);
    px_write(col.p7, x, y0 + 7u);
    px_write(col.p8, x, y0 + 8u);
    px_write(col.p9, x, y0 + 9u);
    px_write(col.p10, x, y0 + 10u);
    px_write(col.p11, x, y0 + 11u);
    px_write(col.p12, x, y0 + 12u);
    px_write(col.p13, x, y0 + 13u);
    px_write(col.p14, x, y0 + 14u);
    px_write(col.p15, x, y0 + 15u);
}
