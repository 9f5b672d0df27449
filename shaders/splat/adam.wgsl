// adam.wgsl — one Adam step (Kingma & Ba 2015) on one parameter group, as
// torch.optim.Adam / `train::adam::adam_step`: m ← β1 m + (1−β1) g,
// v ← β2 v + (1−β2) g², p ← p − lr/bc1 · m / (sqrt(v)/sqrt(bc2) + ε).
// Non-finite gradients count as 0. Element k uses `lr_head` when
// (k mod stride) < head (SH DC terms) and `lr` otherwise.
// Sparse mode (`sparse_width` > 0 elements per splat; gsplat's SelectiveAdam,
// Brush): elements of splats not visible in this step's render (radius 0 in
// `projected`) are left alone — parameter and both moments — instead of
// decaying the moments and moving by momentum as dense torch Adam does.

struct AdamUniforms {
    n: u32,
    stride: u32,
    head: u32,
    sparse_width: u32,
    lr: f32,
    lr_head: f32,
    beta1: f32,
    beta2: f32,
    bc1: f32,
    sbc2: f32,
    eps: f32,
    pad2: f32,
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
    let k = linear_index(wid, nwg, lid, WORKGROUP_SIZE);
    if (k >= u.n) {
        return;
    }
    if (u.sparse_width > 0u && !(projected[divmod(k, u.sparse_width).x].radius > 0.0)) {
        return;
    }
    var g = grads[k];
    if (!is_finite(g)) {
        g = 0.0;
    }
    let m = u.beta1 * exp_avg[k] + (1.0 - u.beta1) * g;
    let v = u.beta2 * exp_avg_sq[k] + (1.0 - u.beta2) * g * g;
    exp_avg[k] = m;
    exp_avg_sq[k] = v;
    var lr = u.lr;
    if (u.stride > 0u && divmod(k, u.stride).y < u.head) {
        lr = u.lr_head;
    }
    params[k] = params[k] - lr / u.bc1 * m / (sqrt(v) / u.sbc2 + u.eps);
}
