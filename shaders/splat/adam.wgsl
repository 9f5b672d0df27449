// adam.wgsl — one Adam step (Kingma & Ba 2015) on one parameter group, as
// torch.optim.Adam / `train::adam::adam_step`: m ← β1 m + (1−β1) g,
// v ← β2 v + (1−β2) g², p ← p − lr/bc1 · m / (sqrt(v)/sqrt(bc2) + ε).
// Non-finite gradients count as 0. A group holds one row of `row` floats
// per splat; the first `width` of each row are updated (`n` = splats ×
// width invocations), the rest are left alone: SH coefficients above every
// degree trained so far have zero gradient and zero moments, for which the
// torch update is the identity. Column j < `head` uses `lr_head` (the SH DC
// of r, g, b), the others `lr`.
// Sparse mode (`sparse` = 1; gsplat's SelectiveAdam, Brush): rows of splats
// not visible in this step's render (radius 0 in `projected`) are left
// alone — parameter and both moments — instead of decaying the moments and
// moving by momentum as dense torch Adam does.

struct AdamUniforms {
    n: u32,
    width: u32,
    row: u32,
    head: u32,
    sparse: u32,
    lr: f32,
    lr_head: f32,
    beta1: f32,
    beta2: f32,
    bc1: f32,
    sbc2: f32,
    eps: f32,
}

// Bindings and injected constants: the `kernel!` declaration in
// crates/splat/src/gpu/adam.rs.

// k mod d without an integer division (CPU drivers scalarise vector
// divisions): a float quotient estimate, off by at most (k/d)·2⁻²² + 1,
// then exact correction in wrapping u32 — exact while the quotient k/d (the
// splat index) is below 12 million.
// Returns (k / d, k mod d).
fn divmod(k: u32, d: u32) -> vec2<u32> {
    var q = u32(f32(k) / f32(d));
    var r = k - q * d;
    for (var c = 0u; c < 4u; c++) {
        if (r >= 0x80000000u) {
            r += d;
            q -= 1u;
        } else if (r >= d) {
            r -= d;
            q += 1u;
        }
    }
    return vec2<u32>(q, r);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn adam_main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
             @builtin(local_invocation_index) lid: u32) {
    let e = linear_index(wid, nwg, lid, WORKGROUP_SIZE);
    if (e >= u.n) {
        return;
    }
    // (splat, column); width 1 needs no division.
    var sj = vec2<u32>(e, 0u);
    if (u.width > 1u) {
        sj = divmod(e, u.width);
    }
    if (u.sparse != 0u && !(projected[sj.x].radius > 0.0)) {
        return;
    }
    let k = sj.x * u.row + sj.y;
    var g = grads[k];
    if (!is_finite(g)) {
        g = 0.0;
    }
    let m = u.beta1 * exp_avg[k] + (1.0 - u.beta1) * g;
    let v = u.beta2 * exp_avg_sq[k] + (1.0 - u.beta2) * g * g;
    exp_avg[k] = m;
    exp_avg_sq[k] = v;
    var lr = u.lr;
    if (sj.y < u.head) {
        lr = u.lr_head;
    }
    params[k] = params[k] - lr / u.bc1 * m / (sqrt(v) / u.sbc2 + u.eps);
}
