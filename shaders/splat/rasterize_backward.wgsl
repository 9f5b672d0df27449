// rasterize_backward.wgsl — backward of the tile rasterizer (INRIA
// `backward.cu` renderCUDA; reference `reference::rasterize_backward`).
// One 16×16 workgroup per tile; each pixel walks its tile list in reverse
// from its last contributor (batches loaded into workgroup memory from the
// back), recovers T_i = T_{i+1} / (1 − α_i) and accumulates dL/d(mean2d,
// conic, opacity, colour) per splat with `grad_add` (float atomics or a CAS
// loop, chosen by the host). `grads` uses the `ProjectedGrads` layout: 12
// floats per splat (mean2d 0..2, conic 4..7, opacity 7, colour 8..11).
// Each invocation owns PPT vertically adjacent pixels of the tile and sums
// their contributions to a splat in registers before one set of atomics, so
// the atomic count drops by up to PPT (atomics dominate on CPU drivers).
// Traversal starts at the largest `last_contrib` of the tile.

@group(0) @binding(0) var<uniform> cam: CameraUniforms;
@group(0) @binding(1) var<storage, read> projected: array<ProjectedSplat>;
@group(0) @binding(2) var<storage, read> tile_values: array<u32>;
@group(0) @binding(3) var<storage, read> ranges: array<u32>;
@group(0) @binding(4) var<storage, read> final_t: array<f32>;
@group(0) @binding(5) var<storage, read> last_contrib: array<u32>;
@group(0) @binding(6) var<storage, read> v_image: array<f32>;
@group(0) @binding(7) var<storage, read_write> grads: array<GradAtomic>;

const PPT: u32 = 4u;

var<workgroup> s_id: array<u32, 256>;
var<workgroup> s_mean_op: array<vec4<f32>, 256>;
var<workgroup> s_conic: array<vec4<f32>, 256>;
var<workgroup> s_color: array<vec4<f32>, 256>;
var<workgroup> wg_max_last: atomic<u32>;
var<workgroup> wg_last: u32;

@compute @workgroup_size(16, 4)
fn rasterize_backward_main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid3: vec3<u32>,
                           @builtin(local_invocation_index) lid: u32) {
    let tile = wid.y * cam.grid_x + wid.x;
    let x = wid.x * TILE_SIZE + lid3.x;
    let y0 = wid.y * TILE_SIZE + lid3.y * PPT;
    let px = f32(x) + 0.5;
    let start = ranges[2u * tile];
    let end = max(ranges[2u * tile + 1u], start);
    var inside: array<bool, 4>;
    var t_final: array<f32, 4>;
    var last: array<u32, 4>;
    var v_pix: array<vec3<f32>, 4>;
    var bg_dot: array<f32, 4>;
    var tr: array<f32, 4>;
    var behind: array<vec3<f32>, 4>;
    var last_alpha: array<f32, 4>;
    var last_color: array<vec3<f32>, 4>;
    var my_max = 0u;
    for (var r = 0u; r < PPT; r++) {
        let y = y0 + r;
        inside[r] = x < cam.width && y < cam.height;
        t_final[r] = 0.0;
        last[r] = 0u;
        v_pix[r] = vec3<f32>(0.0);
        if (inside[r]) {
            let pix = y * cam.width + x;
            t_final[r] = final_t[pix];
            last[r] = last_contrib[pix];
            v_pix[r] = vec3<f32>(v_image[3u * pix], v_image[3u * pix + 1u], v_image[3u * pix + 2u]);
        }
        bg_dot[r] = dot(cam.background.xyz, v_pix[r]);
        tr[r] = t_final[r];
        behind[r] = vec3<f32>(0.0);
        last_alpha[r] = 0.0;
        last_color[r] = vec3<f32>(0.0);
        my_max = max(my_max, last[r]);
    }
    if (lid == 0u) {
        atomicStore(&wg_max_last, 0u);
    }
    workgroupBarrier();
    atomicMax(&wg_max_last, my_max);
    workgroupBarrier();
    if (lid == 0u) {
        wg_last = atomicLoad(&wg_max_last);
    }
    let max_last = workgroupUniformLoad(&wg_last);
    // Batches from the back: [batch_lo, batch_hi).
    var batch_hi = min(end, start + max_last);
    loop {
        if (batch_hi <= start) {
            break;
        }
        let batch_lo = max(start, select(0u, batch_hi - TILE_PIXELS, batch_hi >= TILE_PIXELS));
        let count = batch_hi - batch_lo;
        workgroupBarrier();
        for (var q = 0u; q < TILE_PIXELS / 64u; q++) {
            let idx = lid + 64u * q;
            if (idx < count) {
                let k = batch_hi - 1u - idx;
                let id = tile_values[k];
                let p = projected[id];
                s_id[idx] = id;
                s_mean_op[idx] = vec4<f32>(p.mean_x, p.mean_y, p.opacity, 0.0);
                s_conic[idx] = vec4<f32>(p.conic_a, p.conic_b, p.conic_c, 0.0);
                s_color[idx] = vec4<f32>(p.color_r, p.color_g, p.color_b, 0.0);
            }
        }
        workgroupBarrier();
        for (var j = 0u; j < count; j++) {
            let k_rel = batch_hi - 1u - j - start; // position in the tile list
            if (k_rel >= my_max) {
                continue;
            }
            let mo = s_mean_op[j];
            let conic = s_conic[j].xyz;
            let color = s_color[j].xyz;
            var g_mean = vec2<f32>(0.0);
            var g_conic = vec3<f32>(0.0);
            var g_op = 0.0;
            var g_col = vec3<f32>(0.0);
            var touched = false;
            for (var r = 0u; r < PPT; r++) {
                if (!inside[r] || k_rel >= last[r]) {
                    continue;
                }
                let a = alpha_at(mo.xy, conic, mo.z, px, f32(y0 + r) + 0.5);
                if (a.x < 0.0) {
                    continue;
                }
                let alpha = a.x;
                let g = a.y;
                let dx = a.z;
                let dy = a.w;
                tr[r] = tr[r] / (1.0 - alpha);
                behind[r] = last_alpha[r] * last_color[r] + (1.0 - last_alpha[r]) * behind[r];
                last_color[r] = color;
                var v_alpha = dot(color - behind[r], v_pix[r]) * tr[r];
                last_alpha[r] = alpha;
                v_alpha += -t_final[r] / (1.0 - alpha) * bg_dot[r];
                g_col += alpha * tr[r] * v_pix[r];
                touched = true;
                if (mo.z * g >= ALPHA_MAX) {
                    continue;
                }
                g_op += g * v_alpha;
                let v_power = g * (mo.z * v_alpha);
                g_mean += v_power * vec2<f32>(-(conic.x * dx + conic.y * dy), -(conic.z * dy + conic.y * dx));
                g_conic += v_power * vec3<f32>(-0.5 * dx * dx, -dx * dy, -0.5 * dy * dy);
            }
            if (touched) {
                let base = 12u * s_id[j];
                grad_add(base + 0u, g_mean.x);
                grad_add(base + 1u, g_mean.y);
                grad_add(base + 4u, g_conic.x);
                grad_add(base + 5u, g_conic.y);
                grad_add(base + 6u, g_conic.z);
                grad_add(base + 7u, g_op);
                grad_add(base + 8u, g_col.x);
                grad_add(base + 9u, g_col.y);
                grad_add(base + 10u, g_col.z);
            }
        }
        batch_hi = batch_lo;
    }
}
