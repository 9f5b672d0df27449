// project.wgsl — forward projection of 3D Gaussians to 2D EWA splats
// (Zwicker et al. 2001; Kerbl et al. 2023 §4), one invocation per splat.
// The math lives in common.wgsl (`project_geometry`, `sh_basis`) and follows
// `reference::project::project_one`; culled splats are written as all zeros.

// Bindings and injected constants: the `kernel!` declaration in
// crates/splat/src/gpu/project.rs.

@compute @workgroup_size(WORKGROUP_SIZE)
fn project_main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
                @builtin(local_invocation_index) lid: u32) {
    let i = linear_index(wid, nwg, lid, WORKGROUP_SIZE);
    if (i >= cam.n) {
        return;
    }
    let m = vec3<f32>(means[3u * i], means[3u * i + 1u], means[3u * i + 2u]);
    let ls = vec3<f32>(log_scales[3u * i], log_scales[3u * i + 1u], log_scales[3u * i + 2u]);
    let q = vec4<f32>(rotations[4u * i], rotations[4u * i + 1u], rotations[4u * i + 2u], rotations[4u * i + 3u]);
    let it = project_geometry(m, ls, q, opacity_logits[i], cam);
    var out: ProjectedSplat;
    if (it.ok) {
        let vd = view_dir(m, cam);
        let basis = sh_basis(cam.sh_degree, vd.xyz);
        let ncoef = (cam.sh_degree + 1u) * (cam.sh_degree + 1u);
        let base = i * cam.sh_stored * 3u;
        var col = vec3<f32>(0.0);
        for (var k = 0u; k < ncoef; k++) {
            let o = base + 3u * k;
            col += sh_at(basis, k) * vec3<f32>(sh[o], sh[o + 1u], sh[o + 2u]);
        }
        col = col + vec3<f32>(0.5);
        col = vec3<f32>(max0(col.x), max0(col.y), max0(col.z));
        if (all_finite3(col)) {
            out.mean_x = it.mean2d.x;
            out.mean_y = it.mean2d.y;
            out.depth = it.p_cam.z;
            out.radius = it.radius;
            out.conic_a = it.conic.x;
            out.conic_b = it.conic.y;
            out.conic_c = it.conic.z;
            out.opacity = it.sig * it.comp;
            let lp = cam.background.w;
            out.extent = tile_extent(it.cov2d.x + lp, it.cov2d.z + lp, out.opacity);
            out.color_r = col.x;
            out.color_g = col.y;
            out.color_b = col.z;
        }
    }
    projected[i] = out;
}
