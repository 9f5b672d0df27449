// mcmc_reg.wgsl — gradients of the 3DGS-MCMC L1 regularisers (Kheradmand et
// al. 2024; gsplat `opacity_reg`, `scale_reg`), added to the image-loss
// gradients before Adam, one invocation per splat, as
// `reference::mcmc::add_regularization_grads`:
//   dL/dlogit     += w_opacity · σ(1 − σ)   (w_opacity = opacity_reg / N)
//   dL/dlog_scale += w_scale · exp(s)        (w_scale = scale_reg / (3N))
// The gradient buffers are plain f32 here (the atomics of the backward pass
// are finished when this runs).

struct McmcRegUniforms {
    n: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
    w_opacity: f32,
    w_scale: f32,
    pad3: f32,
    pad4: f32,
}

// Bindings and injected constants: the `kernel!` declaration in
// crates/splat/src/gpu/mcmc.rs.

@compute @workgroup_size(WORKGROUP_SIZE)
fn mcmc_reg_main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
                 @builtin(local_invocation_index) lid: u32) {
    let i = linear_index(wid, nwg, lid, WORKGROUP_SIZE);
    if (i >= u.n) {
        return;
    }
    let o = 1.0 / (1.0 + exp(-opacity_logits[i]));
    grad_opacity_logits[i] = grad_opacity_logits[i] + u.w_opacity * o * (1.0 - o);
    for (var c = 0u; c < 3u; c++) {
        let k = 3u * i + c;
        grad_log_scales[k] = grad_log_scales[k] + u.w_scale * exp(log_scales[k]);
    }
}
