// densify_stats.wgsl — per-step densification statistics (INRIA
// `add_densification_stats`, as `reference::backend::CpuBackend::step`): for
// every splat visible in this view, grad_accum += ‖dL/d mean2d · (w/2, h/2)‖
// (NDC units, so INRIA's 2e-4 threshold applies), count += 1,
// max_radius = max(max_radius, radius); and a count of visible splats.

// Bindings and injected constants: the `kernel!` declaration in
// crates/splat/src/gpu/densify_stats.rs.

@compute @workgroup_size(WORKGROUP_SIZE)
fn densify_stats_main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
                      @builtin(local_invocation_index) lid: u32) {
    let i = linear_index(wid, nwg, lid, WORKGROUP_SIZE);
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
