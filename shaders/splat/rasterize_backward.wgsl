// rasterize_backward.wgsl — backward of the tile rasterizer (INRIA
// `backward.cu` renderCUDA; reference `reference::rasterize_backward`).
// One 16×16 workgroup per tile; each pixel walks its tile list in reverse
// from its last contributor (batches loaded into workgroup memory from the
// back), recovers T_i = T_{i+1} / (1 − α_i) and accumulates dL/d(mean2d,
// conic, opacity, colour) per splat with `grad_add` (float atomics or a CAS
// loop, chosen by the host). `grads` uses the `ProjectedGrads` layout: 12
// floats per splat (mean2d 0..2, conic 4..7, opacity 7, colour 8..11).

@group(0) @binding(0) var<uniform> cam: CameraUniforms;
@group(0) @binding(1) var<storage, read> projected: array<ProjectedSplat>;
@group(0) @binding(2) var<storage, read> tile_values: array<u32>;
@group(0) @binding(3) var<storage, read> ranges: array<u32>;
@group(0) @binding(4) var<storage, read> final_t: array<f32>;
@group(0) @binding(5) var<storage, read> last_contrib: array<u32>;
@group(0) @binding(6) var<storage, read> v_image: array<f32>;
@group(0) @binding(7) var<storage, read_write> grads: array<GradAtomic>;

var<workgroup> s_id: array<u32, 256>;
var<workgroup> s_mean_op: array<vec4<f32>, 256>;
var<workgroup> s_conic: array<vec4<f32>, 256>;
var<workgroup> s_color: array<vec4<f32>, 256>;

@compute @workgroup_size(16, 16)
fn rasterize_backward_main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid3: vec3<u32>,
                           @builtin(local_invocation_index) lid: u32) {
    let tile = wid.y * cam.grid_x + wid.x;
    let x = wid.x * TILE_SIZE + lid3.x;
    let y = wid.y * TILE_SIZE + lid3.y;
    let inside = x < cam.width && y < cam.height;
    let px = f32(x) + 0.5;
    let py = f32(y) + 0.5;
    let start = ranges[2u * tile];
    let end = max(ranges[2u * tile + 1u], start);
    var t_final = 0.0;
    var last = 0u;
    var v_pix = vec3<f32>(0.0);
    if (inside) {
        let pix = y * cam.width + x;
        t_final = final_t[pix];
        last = last_contrib[pix];
        v_pix = vec3<f32>(v_image[3u * pix], v_image[3u * pix + 1u], v_image[3u * pix + 2u]);
    }
    let bg_dot = dot(cam.background.xyz, v_pix);
    var tr = t_final;
    var behind = vec3<f32>(0.0);
    var last_alpha = 0.0;
    var last_color = vec3<f32>(0.0);
    // Batches from the back: [batch_lo, batch_hi).
    var batch_hi = end;
    loop {
        if (batch_hi <= start) {
            break;
        }
        let batch_lo = max(start, select(0u, batch_hi - TILE_PIXELS, batch_hi >= TILE_PIXELS));
        workgroupBarrier();
        if (lid < batch_hi - batch_lo) {
            let k = batch_hi - 1u - lid;
            let id = tile_values[k];
            let p = projected[id];
            s_id[lid] = id;
            s_mean_op[lid] = vec4<f32>(p.mean_x, p.mean_y, p.opacity, 0.0);
            s_conic[lid] = vec4<f32>(p.conic_a, p.conic_b, p.conic_c, 0.0);
            s_color[lid] = vec4<f32>(p.color_r, p.color_g, p.color_b, 0.0);
        }
        workgroupBarrier();
        let count = batch_hi - batch_lo;
        for (var j = 0u; j < count; j++) {
            let k_rel = batch_hi - 1u - j - start; // position in the tile list
            if (!inside || k_rel >= last) {
                continue;
            }
            let mo = s_mean_op[j];
            let conic = s_conic[j].xyz;
            let a = alpha_at(mo.xy, conic, mo.z, px, py);
            if (a.x < 0.0) {
                continue;
            }
            let alpha = a.x;
            let g = a.y;
            let dx = a.z;
            let dy = a.w;
            tr = tr / (1.0 - alpha);
            let color = s_color[j].xyz;
            behind = last_alpha * last_color + (1.0 - last_alpha) * behind;
            last_color = color;
            var v_alpha = dot(color - behind, v_pix) * tr;
            last_alpha = alpha;
            v_alpha += -t_final / (1.0 - alpha) * bg_dot;
            let base = 12u * s_id[j];
            let vc = alpha * tr * v_pix;
            grad_add(base + 8u, vc.x);
            grad_add(base + 9u, vc.y);
            grad_add(base + 10u, vc.z);
            if (mo.z * g >= ALPHA_MAX) {
                continue;
            }
            grad_add(base + 7u, g * v_alpha);
            let v_power = g * (mo.z * v_alpha);
            let dp_ddx = -(conic.x * dx + conic.y * dy);
            let dp_ddy = -(conic.z * dy + conic.y * dx);
            grad_add(base + 0u, v_power * dp_ddx);
            grad_add(base + 1u, v_power * dp_ddy);
            grad_add(base + 4u, v_power * (-0.5 * dx * dx));
            grad_add(base + 5u, v_power * (-dx * dy));
            grad_add(base + 6u, v_power * (-0.5 * dy * dy));
        }
        batch_hi = batch_lo;
    }
}
