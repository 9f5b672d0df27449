// densify_stats.wgsl — per-step densification statistics (INRIA
// `add_densification_stats`, as `reference::backend::CpuBackend::step`): for
// every splat visible in this view, grad_accum += ‖dL/d mean2d · (w/2, h/2)‖
// (NDC units, so INRIA's 2e-4 threshold applies), count += 1,
// max_radius = max(max_radius, radius); and a count of visible splats.

@group(0) @binding(0) var<uniform> cam: CameraUniforms;
@group(0) @binding(1) var<storage, read> projected: array<ProjectedSplat>;
@group(0) @binding(2) var<storage, read> v_proj: array<f32>;
@group(0) @binding(3) var<storage, read_write> grad_accum: array<f32>;
@group(0) @binding(4) var<storage, read_write> vis_count: array<u32>;
@group(0) @binding(5) var<storage, read_write> max_radius: array<f32>;
@group(0) @binding(6) var<storage, read_write> visible: atomic<u32>;

@compute @workgroup_size(256)
fn densify_stats_main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
                      @builtin(local_invocation_index) lid: u32) {
    let i = linear_index(wid, nwg, lid, 256u);
    if (i >= cam.n) {
        return;
    }
    let r = projected[i].radius;
    if (r > 0.0) {
        atomicAdd(&visible, 1u);
        let gx = v_proj[12u * i] * (f32(cam.width) * 0.5);
        let gy = v_proj[12u * i + 1u] * (f32(cam.height) * 0.5);
        grad_accum[i] = grad_accum[i] + sqrt(gx * gx + gy * gy);
        vis_count[i] = vis_count[i] + 1u;
        max_radius[i] = max(max_radius[i], r);
    }
}
