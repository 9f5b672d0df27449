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
// kernel. The sixteen pixels (a whole tile column) are named `Px` values
// updated by an inlined function (an indexed private array would become
// per-lane scratch memory). Each 8-column block walks only the splats that
// can reach it (see the batch loop), which on a trained scene skips many.

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

/// Composite list entry `pos` (0-based in the tile list) at one pixel;
/// returns 1 when this pixel just finished (T would fall below T_MIN).
fn px_step(p: ptr<function, Px>, pos: u32, mo: vec4<f32>, conic: vec3<f32>, color: vec3<f32>, px: f32) -> u32 {
    if (!(*p).live) {
        return 0u;
    }
    let a = alpha_at(mo.xy, conic, mo.z, px, (*p).py);
    if (a.x < 0.0) {
        return 0u;
    }
    let tr = (*p).tr;
    let next = tr * (1.0 - a.x);
    if (next < T_MIN) {
        (*p).live = false;
        return 1u;
    }
    (*p).col += color * a.x * tr;
    (*p).tr = next;
    (*p).last = pos + 1u;
    return 0u;
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
    var p0 = px_init(x, y0);
    var p1 = px_init(x, y0 + 1u);
    var p2 = px_init(x, y0 + 2u);
    var p3 = px_init(x, y0 + 3u);
    var p4 = px_init(x, y0 + 4u);
    var p5 = px_init(x, y0 + 5u);
    var p6 = px_init(x, y0 + 6u);
    var p7 = px_init(x, y0 + 7u);
    var p8 = px_init(x, y0 + 8u);
    var p9 = px_init(x, y0 + 9u);
    var p10 = px_init(x, y0 + 10u);
    var p11 = px_init(x, y0 + 11u);
    var p12 = px_init(x, y0 + 12u);
    var p13 = px_init(x, y0 + 13u);
    var p14 = px_init(x, y0 + 14u);
    var p15 = px_init(x, y0 + 15u);
    var n_live = u32(p0.live) + u32(p1.live) + u32(p2.live) + u32(p3.live) + u32(p4.live) + u32(p5.live) + u32(p6.live) + u32(p7.live) + u32(p8.live) + u32(p9.live) + u32(p10.live) + u32(p11.live) + u32(p12.live) + u32(p13.live) + u32(p14.live) + u32(p15.live);
    var done = n_live == 0u;
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
        for (var m = 0u; m < len && !done; m++) {
            let j = s_list[my_block * TILE_PIXELS + m];
            let mo = s_mean_op[j];
            let conic = s_conic[j].xyz;
            let color = s_color[j].xyz;
            let pos = batch - start + j;
            var ended = px_step(&p0, pos, mo, conic, color, px);
            ended += px_step(&p1, pos, mo, conic, color, px);
            ended += px_step(&p2, pos, mo, conic, color, px);
            ended += px_step(&p3, pos, mo, conic, color, px);
            ended += px_step(&p4, pos, mo, conic, color, px);
            ended += px_step(&p5, pos, mo, conic, color, px);
            ended += px_step(&p6, pos, mo, conic, color, px);
            ended += px_step(&p7, pos, mo, conic, color, px);
            ended += px_step(&p8, pos, mo, conic, color, px);
            ended += px_step(&p9, pos, mo, conic, color, px);
            ended += px_step(&p10, pos, mo, conic, color, px);
            ended += px_step(&p11, pos, mo, conic, color, px);
            ended += px_step(&p12, pos, mo, conic, color, px);
            ended += px_step(&p13, pos, mo, conic, color, px);
            ended += px_step(&p14, pos, mo, conic, color, px);
            ended += px_step(&p15, pos, mo, conic, color, px);
            n_live -= ended;
            if (n_live == 0u) {
                done = true;
                atomicAdd(&n_done, 1u);
            }
        }
    }
    px_write(p0, x, y0);
    px_write(p1, x, y0 + 1u);
    px_write(p2, x, y0 + 2u);
    px_write(p3, x, y0 + 3u);
    px_write(p4, x, y0 + 4u);
    px_write(p5, x, y0 + 5u);
    px_write(p6, x, y0 + 6u);
    px_write(p7, x, y0 + 7u);
    px_write(p8, x, y0 + 8u);
    px_write(p9, x, y0 + 9u);
    px_write(p10, x, y0 + 10u);
    px_write(p11, x, y0 + 11u);
    px_write(p12, x, y0 + 12u);
    px_write(p13, x, y0 + 13u);
    px_write(p14, x, y0 + 14u);
    px_write(p15, x, y0 + 15u);
}
