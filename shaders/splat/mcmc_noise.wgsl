// mcmc_noise.wgsl — SGLD position noise of 3DGS-MCMC (Kheradmand et al.
// 2024; gsplat `inject_noise_to_position`), one invocation per splat:
//   μ += scale · σ(−k(σ(logit) − t)) · Σ ε,   Σ = R diag(exp(2·log_scale)) Rᵀ,
// with ε ~ N(0, I) from Box–Muller on PCG hashes of (seed, splat index,
// component), exactly as `reference::mcmc` does it on the CPU (same integer
// hash, same operation order). A non-finite result leaves the mean unchanged.

struct McmcNoiseUniforms {
    n: u32,
    seed: u32,
    pad0: u32,
    pad1: u32,
    scale: f32,
    k: f32,
    t: f32,
    pad2: f32,
}

// Bindings and injected constants: the `kernel!` declaration in
// crates/splat/src/gpu/mcmc.rs.

// PCG-RXS-M-XS hash (Jarzynski & Olano 2020), u32 arithmetic wraps.
fn pcg_hash(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// Uniform in (0, 1] from the top 24 bits.
fn unit_from_hash(h: u32) -> f32 {
    return f32((h >> 8u) + 1u) * (1.0 / 16777216.0);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn mcmc_noise_main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
                   @builtin(local_invocation_index) lid: u32) {
    let i = linear_index(wid, nwg, lid, WORKGROUP_SIZE);
    if (i >= u.n) {
        return;
    }
    let base = pcg_hash(i ^ pcg_hash(u.seed));
    let r0 = sqrt(-2.0 * log(unit_from_hash(pcg_hash(base))));
    let t0 = 6.283185307179586 * unit_from_hash(pcg_hash(base + 1u));
    let r1 = sqrt(-2.0 * log(unit_from_hash(pcg_hash(base + 2u))));
    let t1 = 6.283185307179586 * unit_from_hash(pcg_hash(base + 3u));
    let e = vec3<f32>(r0 * cos(t0), r0 * sin(t0), r1 * cos(t1));

    let q0 = vec4<f32>(rotations[4u * i], rotations[4u * i + 1u], rotations[4u * i + 2u],
                       rotations[4u * i + 3u]);
    let qn = max(sqrt(q0.x * q0.x + q0.y * q0.y + q0.z * q0.z + q0.w * q0.w), 1e-12);
    let w = q0.x / qn;
    let x = q0.y / qn;
    let y = q0.z / qn;
    let z = q0.w / qn;
    // Rows of R.
    let ra = vec3<f32>(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y));
    let rb = vec3<f32>(2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x));
    let rc = vec3<f32>(2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y));
    var local: array<f32, 3>;
    for (var c = 0u; c < 3u; c++) {
        let s = exp(2.0 * log_scales[3u * i + c]);
        local[c] = s * (ra[c] * e.x + rb[c] * e.y + rc[c] * e.z);
    }
    let d = vec3<f32>(
        ra.x * local[0] + ra.y * local[1] + ra.z * local[2],
        rb.x * local[0] + rb.y * local[1] + rb.z * local[2],
        rc.x * local[0] + rc.y * local[1] + rc.z * local[2],
    );
    let o = 1.0 / (1.0 + exp(-opacity_logits[i]));
    let gate = 1.0 / (1.0 + exp(min(u.k * (o - u.t), 80.0)));
    let g = u.scale * gate;
    let m = vec3<f32>(means[3u * i], means[3u * i + 1u], means[3u * i + 2u]);
    let out = vec3<f32>(m.x + g * d.x, m.y + g * d.y, m.z + g * d.z);
    if (all_finite3(out)) {
        means[3u * i] = out.x;
        means[3u * i + 1u] = out.y;
        means[3u * i + 2u] = out.z;
    }
}
