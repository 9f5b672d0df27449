// project_backward.wgsl — backward of the projection (INRIA `backward.cu`
// computeCov2DCUDA / preprocessCUDA, gsplat proj_bwd), one invocation per
// splat, mirroring `reference::project_backward::backward_one`: recompute the
// forward with `project_geometry` (common.wgsl), then the chain rule through
// colour/SH and view direction, opacity (sigmoid, antialiasing
// compensation), conic → Σ2 → (J, Σ3) → camera-space mean (clamped J as
// gsplat), Σ3 → scales and the normalised quaternion. Culled splats get 0.

// Bindings and injected constants: the `kernel!` declaration in
// crates/splat/src/gpu/project_backward.rs.
// `io` holds dL/d projected splat (12 floats per splat) in [0, 12n) and,
// after it, the geometry gradients in planar segments (one buffer for
// inputs and outputs keeps the kernel at 8 storage buffers with the camera,
// the GL fallback's per-stage limit): means [12n, 15n), log-scales
// [15n, 18n), rotations [18n, 22n), opacity logits [22n, 23n),
// ‖dL/d mean2d‖ [23n, 24n). The host copies the segments out.

fn set_mean(i: u32, a: u32, v: f32) { io[12u * cam.n + 3u * i + a] = v; }
fn set_log_scale(i: u32, a: u32, v: f32) { io[15u * cam.n + 3u * i + a] = v; }
fn set_rotation(i: u32, a: u32, v: f32) { io[18u * cam.n + 4u * i + a] = v; }
fn set_opacity(i: u32, v: f32) { io[22u * cam.n + i] = v; }
fn set_mean2d_abs(i: u32, v: f32) { io[23u * cam.n + i] = v; }

fn write_zero(i: u32) {
    for (var a = 0u; a < 3u; a++) {
        set_mean(i, a, 0.0);
        set_log_scale(i, a, 0.0);
    }
    for (var a = 0u; a < 4u; a++) {
        set_rotation(i, a, 0.0);
    }
    set_opacity(i, 0.0);
    let k3 = cam.sh_stored * 3u;
    for (var a = 0u; a < k3; a++) {
        g_sh[i * k3 + a] = 0.0;
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn project_backward_main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
                         @builtin(local_invocation_index) lid: u32) {
    let i = linear_index(wid, nwg, lid, WORKGROUP_SIZE);
    if (i >= cam.n) {
        return;
    }
    let vb = 12u * i;
    let v_mean2d = vec2<f32>(io[vb], io[vb + 1u]);
    let v_conic = vec3<f32>(io[vb + 4u], io[vb + 5u], io[vb + 6u]);
    let v_opacity = io[vb + 7u];
    let v_color = vec3<f32>(io[vb + 8u], io[vb + 9u], io[vb + 10u]);
    set_mean2d_abs(i, sqrt(v_mean2d.x * v_mean2d.x + v_mean2d.y * v_mean2d.y));

    let m = vec3<f32>(means[3u * i], means[3u * i + 1u], means[3u * i + 2u]);
    let ls = vec3<f32>(log_scales[3u * i], log_scales[3u * i + 1u], log_scales[3u * i + 2u]);
    let q = vec4<f32>(rotations[4u * i], rotations[4u * i + 1u], rotations[4u * i + 2u], rotations[4u * i + 3u]);
    let it = project_geometry(m, ls, q, opacity_logits[i], cam);
    if (!it.ok) {
        write_zero(i);
        return;
    }
    // Colour → SH and view direction.
    let vd = view_dir(m, cam);
    let dir = vd.xyz;
    let dist = vd.w;
    let deg = cam.sh_degree;
    let basis = sh_basis(deg, dir);
    let ncoef = (deg + 1u) * (deg + 1u);
    let base = i * cam.sh_stored * 3u;
    var raw = vec3<f32>(0.0);
    for (var k = 0u; k < ncoef; k++) {
        let o = base + 3u * k;
        raw += sh_at(basis, k) * vec3<f32>(sh[o], sh[o + 1u], sh[o + 2u]);
    }
    let col = raw + vec3<f32>(0.5);
    let col_out = vec3<f32>(max0(col.x), max0(col.y), max0(col.z));
    if (!all_finite3(col_out)) {
        write_zero(i); // culled in the forward as well
        return;
    }
    var vc = v_color;
    if (col.x < 0.0) { vc.x = 0.0; }
    if (col.y < 0.0) { vc.y = 0.0; }
    if (col.z < 0.0) { vc.z = 0.0; }
    let bgrad = sh_basis_grad(deg, dir);
    var v_dir = vec3<f32>(0.0);
    for (var k = 0u; k < ncoef; k++) {
        let o = base + 3u * k;
        let shk = vec3<f32>(sh[o], sh[o + 1u], sh[o + 2u]);
        g_sh[o] = sh_at(basis, k) * vc.x;
        g_sh[o + 1u] = sh_at(basis, k) * vc.y;
        g_sh[o + 2u] = sh_at(basis, k) * vc.z;
        let w = shk * vc;
        v_dir += (w.x + w.y + w.z) * sh_grad_at(bgrad, k);
    }
    // Stored coefficients above the active degree get no gradient.
    for (var o = base + 3u * ncoef; o < base + cam.sh_stored * 3u; o++) {
        g_sh[o] = 0.0;
    }
    var g_mean = vec3<f32>(0.0);
    if (dist > 0.0) {
        let dd = dot(dir, v_dir);
        g_mean += (v_dir - dir * dd) / dist;
    }
    // Opacity.
    let s = it.sig;
    set_opacity(i, v_opacity * it.comp * s * (1.0 - s));
    let v_comp = v_opacity * s;
    // Conic → dilated covariance: dL/dΣ' = −C G C.
    let ca = it.conic.x; let cb = it.conic.y; let cc = it.conic.z;
    let ga = v_conic.x; let gb = 0.5 * v_conic.y; let gc = v_conic.z;
    let cg00 = ca * ga + cb * gb; let cg01 = ca * gb + cb * gc;
    let cg10 = cb * ga + cc * gb; let cg11 = cb * gb + cc * gc;
    var v00 = -(cg00 * ca + cg01 * cb);
    var v01 = -(cg00 * cb + cg01 * cc);
    var v10 = -(cg10 * ca + cg11 * cb);
    var v11 = -(cg10 * cb + cg11 * cc);
    if (cam.antialiased != 0u && it.comp > 0.0) {
        let a0 = it.cov2d.x; let b0 = it.cov2d.y; let c0 = it.cov2d.z;
        let det0 = a0 * c0 - b0 * b0;
        let lp = cam.background.w;
        let d1 = it.det;
        let kk = v_comp / (2.0 * it.comp) / (d1 * d1);
        v00 += kk * (c0 * d1 - det0 * (c0 + lp));
        v11 += kk * (a0 * d1 - det0 * (a0 + lp));
        let off = kk * (-b0 * d1 + det0 * b0);
        v01 += off;
        v10 += off;
    }
    // Σ2 = T Σ3 Tᵀ, T = J W (rows jw0, jw1).
    let t0 = it.jw0; let t1 = it.jw1;
    let ts0 = t0.x * it.c0 + t0.y * it.c1 + t0.z * it.c2;
    let ts1 = t1.x * it.c0 + t1.y * it.c1 + t1.z * it.c2;
    let vt0 = (v00 + v00) * ts0 + (v01 + v10) * ts1;
    let vt1 = (v10 + v01) * ts0 + (v11 + v11) * ts1;
    // v3 = Tᵀ V2 T (rows).
    let u0 = v00 * t0 + v01 * t1; // (V2 T) row 0
    let u1 = v10 * t0 + v11 * t1; // (V2 T) row 1
    let v3r0 = t0.x * u0 + t1.x * u1;
    let v3r1 = t0.y * u0 + t1.y * u1;
    let v3r2 = t0.z * u0 + t1.z * u1;
    // dL/dJ = dL/dT Wᵀ.
    let w0 = cam.rot0.xyz; let w1 = cam.rot1.xyz; let w2 = cam.rot2.xyz;
    let vj00 = dot(vt0, w0); let vj02 = dot(vt0, w2);
    let vj11 = dot(vt1, w1); let vj12 = dot(vt1, w2);
    let tx = it.p_cam.x; let ty = it.p_cam.y; let tz = it.p_cam.z;
    let fx = cam.focal.x; let fy = cam.focal.y;
    let tz2 = tz * tz;
    var v_pc = vec3<f32>(0.0);
    v_pc.x += fx / tz * v_mean2d.x;
    v_pc.y += fy / tz * v_mean2d.y;
    v_pc.z += -(fx * tx * v_mean2d.x + fy * ty * v_mean2d.y) / tz2;
    v_pc.z += -(fx * vj00 + fy * vj11) / tz2;
    let cxz = min(max(tx / tz, -cam.clip.z), cam.clip.z);
    let cyz = min(max(ty / tz, -cam.clip.w), cam.clip.w);
    if (it.clamped_x) {
        v_pc.z += fx * cxz / tz2 * vj02;
    } else {
        v_pc.x += -fx / tz2 * vj02;
        v_pc.z += 2.0 * fx * tx / (tz2 * tz) * vj02;
    }
    if (it.clamped_y) {
        v_pc.z += fy * cyz / tz2 * vj12;
    } else {
        v_pc.y += -fy / tz2 * vj12;
        v_pc.z += 2.0 * fy * ty / (tz2 * tz) * vj12;
    }
    g_mean += w0 * v_pc.x + w1 * v_pc.y + w2 * v_pc.z;
    // Σ3 = M Mᵀ, M = R S (rows m_a = r_a ∘ s).
    let sc = it.scale;
    let m0 = it.r0 * sc; let m1 = it.r1 * sc; let m2 = it.r2 * sc;
    let v3 = mat3x3<f32>(v3r0, v3r1, v3r2); // columns hold rows
    let sym = v3 + transpose(v3);
    let vm0 = sym[0].x * m0 + sym[0].y * m1 + sym[0].z * m2;
    let vm1 = sym[1].x * m0 + sym[1].y * m1 + sym[1].z * m2;
    let vm2 = sym[2].x * m0 + sym[2].y * m1 + sym[2].z * m2;
    let g_ls = vm0 * it.r0 * sc + vm1 * it.r1 * sc + vm2 * it.r2 * sc;
    let vr0 = vm0 * sc; let vr1 = vm1 * sc; let vr2 = vm2 * sc;
    // R(q̂) → q̂ → q.
    let qw = it.qn.x; let qx = it.qn.y; let qy = it.qn.z; let qz = it.qn.w;
    let vq = 2.0 * vec4<f32>(
        -qz * vr0.y + qy * vr0.z + qz * vr1.x - qx * vr1.z - qy * vr2.x + qx * vr2.y,
        qy * vr0.y + qz * vr0.z + qy * vr1.x - 2.0 * qx * vr1.y - qw * vr1.z + qz * vr2.x + qw * vr2.y - 2.0 * qx * vr2.z,
        -2.0 * qy * vr0.x + qx * vr0.y + qw * vr0.z + qx * vr1.x + qz * vr1.z - qw * vr2.x + qz * vr2.y - 2.0 * qy * vr2.z,
        -2.0 * qz * vr0.x - qw * vr0.y + qx * vr0.z + qw * vr1.x - 2.0 * qz * vr1.y + qy * vr1.z + qx * vr2.x + qy * vr2.y);
    let dq = dot(it.qn, vq);
    let g_q = (vq - it.qn * dq) / it.qnorm;
    for (var a = 0u; a < 3u; a++) {
        set_mean(i, a, g_mean[a]);
        set_log_scale(i, a, g_ls[a]);
    }
    for (var a = 0u; a < 4u; a++) {
        set_rotation(i, a, g_q[a]);
    }
}
