// rasterize.wgsl — forward tile rasterizer (Kerbl et al. 2023 §6, INRIA
// `renderCUDA`): one 16×16 workgroup per tile, the tile's depth-sorted splats
// loaded into workgroup memory 256 at a time, front-to-back compositing per
// pixel (α ≤ 0.99, α < 1/255 skipped, stop before T < 1e-4), background
// weighted by the final transmittance. Writes what backward needs: final T
// and the count of list entries up to the last contributor.

@group(0) @binding(0) var<uniform> cam: CameraUniforms;
@group(0) @binding(1) var<storage, read> projected: array<ProjectedSplat>;
@group(0) @binding(2) var<storage, read> tile_values: array<u32>;
@group(0) @binding(3) var<storage, read> ranges: array<u32>;
@group(0) @binding(4) var<storage, read_write> image: array<f32>;
@group(0) @binding(5) var<storage, read_write> final_t: array<f32>;
@group(0) @binding(6) var<storage, read_write> last_contrib: array<u32>;

var<workgroup> s_mean_op: array<vec4<f32>, 256>;  // mean x, mean y, opacity
var<workgroup> s_conic: array<vec4<f32>, 256>;    // a, b, c
var<workgroup> s_color: array<vec4<f32>, 256>;    // r, g, b
var<workgroup> n_done: atomic<u32>;
var<workgroup> all_done: u32;

@compute @workgroup_size(16, 16)
fn rasterize_main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid3: vec3<u32>,
                  @builtin(local_invocation_index) lid: u32) {
    let tile = wid.y * cam.grid_x + wid.x;
    let x = wid.x * TILE_SIZE + lid3.x;
    let y = wid.y * TILE_SIZE + lid3.y;
    let inside = x < cam.width && y < cam.height;
    let px = f32(x) + 0.5;
    let py = f32(y) + 0.5;
    let start = ranges[2u * tile];
    let end = max(ranges[2u * tile + 1u], start);
    if (lid == 0u) {
        atomicStore(&n_done, 0u);
    }
    workgroupBarrier();
    var done = !inside;
    if (done) {
        atomicAdd(&n_done, 1u);
    }
    var tr = 1.0;
    var col = vec3<f32>(0.0);
    var last = 0u;
    for (var batch = start; batch < end; batch += TILE_PIXELS) {
        workgroupBarrier();
        if (lid == 0u) {
            all_done = atomicLoad(&n_done);
        }
        if (workgroupUniformLoad(&all_done) == TILE_PIXELS) {
            break;
        }
        let k = batch + lid;
        if (k < end) {
            let p = projected[tile_values[k]];
            s_mean_op[lid] = vec4<f32>(p.mean_x, p.mean_y, p.opacity, 0.0);
            s_conic[lid] = vec4<f32>(p.conic_a, p.conic_b, p.conic_c, 0.0);
            s_color[lid] = vec4<f32>(p.color_r, p.color_g, p.color_b, 0.0);
        }
        workgroupBarrier();
        let count = min(TILE_PIXELS, end - batch);
        for (var j = 0u; j < count && !done; j++) {
            let mo = s_mean_op[j];
            let a = alpha_at(mo.xy, s_conic[j].xyz, mo.z, px, py);
            if (a.x < 0.0) {
                continue;
            }
            let next = tr * (1.0 - a.x);
            if (next < T_MIN) {
                done = true;
                atomicAdd(&n_done, 1u);
                break;
            }
            col += s_color[j].xyz * a.x * tr;
            tr = next;
            last = batch - start + j + 1u;
        }
    }
    if (inside) {
        let pix = y * cam.width + x;
        col += tr * cam.background.xyz;
        image[3u * pix] = col.x;
        image[3u * pix + 1u] = col.y;
        image[3u * pix + 2u] = col.z;
        final_t[pix] = tr;
        last_contrib[pix] = last;
    }
}
