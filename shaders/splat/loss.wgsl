// loss.wgsl — masked L1 loss gradient w.r.t. the rendered image (RoMo masks:
// moving pixels weigh 0; normalised by 3·Σ mask, as `train::loss`):
// dL/dx = (1−λ)·m·sign(x − y)/(3·kept). Also writes per-workgroup partial
// sums of m·|d| and m·d² for the host to reduce (L1 value and PSNR).

struct LossUniforms {
    n_pixels: u32,
    has_mask: u32,
    pad0: u32,
    pad1: u32,
    // (1 − λ) / (3 · kept)
    scale: f32,
    pad2: f32,
    pad3: f32,
    pad4: f32,
}

// Bindings and injected constants: the `kernel!` declaration in
// crates/splat/src/gpu/loss.rs.

var<workgroup> s_l1: array<f32, WORKGROUP_SIZE>;
var<workgroup> s_se: array<f32, WORKGROUP_SIZE>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn l1_grad(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
           @builtin(local_invocation_index) lid: u32) {
    let block = wid.y * nwg.x + wid.x;
    let i = block * WORKGROUP_SIZE + lid;
    var l1 = 0.0;
    var se = 0.0;
    if (i < u.n_pixels) {
        var m = 1.0;
        if (u.has_mask != 0u) {
            m = mask[i];
        }
        for (var c = 0u; c < 3u; c++) {
            let d = image[3u * i + c] - target_rgb[3u * i + c];
            l1 += m * abs(d);
            se += m * d * d;
            var s = 0.0;
            if (m != 0.0) {
                s = sign(d);
            }
            v_image[3u * i + c] = u.scale * m * s;
        }
    }
    s_l1[lid] = l1;
    s_se[lid] = se;
    workgroupBarrier();
    // Two-level sum: WORKGROUP_SIZE / 8 invocations add 8 values each, then
    // one adds those. Loops rather than `if`s: llvmpipe runs a masked `if` body in every
    // subgroup, but skips a loop no lane of the subgroup enters; a halving
    // tree cost 8 barriers and 8 full passes (about a third of this kernel).
    for (var i = lid; i < WORKGROUP_SIZE / 8u; i += WORKGROUP_SIZE) {
        var a = 0.0;
        var b = 0.0;
        for (var j = 0u; j < 8u; j++) {
            a += s_l1[8u * i + j];
            b += s_se[8u * i + j];
        }
        s_l1[8u * i] = a;
        s_se[8u * i] = b;
    }
    workgroupBarrier();
    for (var i = lid; i < 1u; i += WORKGROUP_SIZE) {
        var a = 0.0;
        var b = 0.0;
        for (var j = 0u; j < WORKGROUP_SIZE / 8u; j++) {
            a += s_l1[8u * j];
            b += s_se[8u * j];
        }
        partials[2u * block] = a;
        partials[2u * block + 1u] = b;
    }
}
