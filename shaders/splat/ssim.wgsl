// ssim.wgsl — masked D-SSIM term of the training loss on the GPU and its
// gradient w.r.t. the rendered image (Kerbl et al. 2023 eq. 7; the same
// formulation as the CPU `train::loss::loss_and_grad`): SSIM with the INRIA
// 11×11 Gaussian window (σ = 1.5) and zero padding, computed as separable
// horizontal + vertical 11-tap filters. The window filter is self-adjoint, so
// the backward pass is: per-pixel dS/d(μx, E[x²], E[xy]) weighted by
// g = mask / (3·kept), the same two filters again, and
// dL/dx = −λ (f(dμx) + 2x f(dE[x²]) + y f(dE[xy])), added to `v_image`.
// Maps are planar: map k of channel c at ((k·3 + c)·n + pixel).
//
// Entry points, in order: `products` (x, y, x², y², xy → dst), `blur_h`
// (src → dst, `n_maps` maps), `blur_v` (src → dst), `ssim_terms` (stats in
// src → weighted derivative maps in dst, partial sums of g·S), `blur_h`,
// `blur_v`, `ssim_grad` (src → v_image).

struct SsimUniforms {
    width: u32,
    height: u32,
    // Maps × 3 channels processed by blur_h / blur_v.
    n_maps: u32,
    has_mask: u32,
    // 1 / (3 · kept)
    norm: f32,
    // D-SSIM weight λ.
    lambda: f32,
    pad0: f32,
    pad1: f32,
    // Gaussian taps w[0..11] (offset −5..5), packed 4 per vector.
    taps: array<vec4<f32>, 3>,
}

// Bindings and injected constants: the `kernel!` declaration in
// crates/splat/src/gpu/ssim.rs.

const C1: f32 = 0.0001;
const C2: f32 = 0.0009;

var<workgroup> s_sum: array<f32, WORKGROUP_SIZE>;

// Register blocking: each invocation filters SEG consecutive outputs along
// the filter direction, sliding an 11-value window held in named variables
// (one load per output plus 10 to start; storage reads are per-lane,
// bounds-checked gathers on llvmpipe). The window and the taps are named
// values, not indexed private arrays: llvmpipe keeps a dynamically indexed
// private array in per-lane scratch memory, which cost ~7× the kernel's
// storage traffic. SEG is the host's `BLUR_SEGMENT`.

fn at(base: u32, i: i32, lim: i32, stride: u32) -> f32 {
    if (i < 0 || i >= lim) {
        return 0.0;
    }
    return src[base + u32(i) * stride];
}

// Filter SEG outputs starting at index `i0` along a line of `lim` elements
// (element i at `base + i·stride`) and store them in `dst`.
fn filter_seg(base: u32, i0: u32, lim: u32, stride: u32) {
    let t0 = u.taps[0].x;
    let t1 = u.taps[0].y;
    let t2 = u.taps[0].z;
    let t3 = u.taps[0].w;
    let t4 = u.taps[1].x;
    let t5 = u.taps[1].y;
    let t6 = u.taps[1].z;
    let t7 = u.taps[1].w;
    let t8 = u.taps[2].x;
    let t9 = u.taps[2].y;
    let t10 = u.taps[2].z;
    let l = i32(lim);
    let s = i32(i0) - 5;
    var w0 = at(base, s, l, stride);
    var w1 = at(base, s + 1, l, stride);
    var w2 = at(base, s + 2, l, stride);
    var w3 = at(base, s + 3, l, stride);
    var w4 = at(base, s + 4, l, stride);
    var w5 = at(base, s + 5, l, stride);
    var w6 = at(base, s + 6, l, stride);
    var w7 = at(base, s + 7, l, stride);
    var w8 = at(base, s + 8, l, stride);
    var w9 = at(base, s + 9, l, stride);
    let count = min(SEG, lim - i0);
    for (var o = 0u; o < count; o++) {
        let w10 = at(base, s + 10 + i32(o), l, stride);
        let acc = t0 * w0 + t1 * w1 + t2 * w2 + t3 * w3 + t4 * w4 + t5 * w5 + t6 * w6 + t7 * w7
            + t8 * w8 + t9 * w9 + t10 * w10;
        dst[base + (i0 + o) * stride] = acc;
        w0 = w1;
        w1 = w2;
        w2 = w3;
        w3 = w4;
        w4 = w5;
        w5 = w6;
        w6 = w7;
        w7 = w8;
        w8 = w9;
        w9 = w10;
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn products(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
            @builtin(local_invocation_index) lid: u32) {
    let n = u.width * u.height;
    let q = linear_index(wid, nwg, lid, WORKGROUP_SIZE);
    if (q >= n) {
        return;
    }
    for (var c = 0u; c < 3u; c++) {
        let x = image[3u * q + c];
        let y = target_rgb[3u * q + c];
        dst[c * n + q] = x;
        dst[(3u + c) * n + q] = y;
        dst[(6u + c) * n + q] = x * x;
        dst[(9u + c) * n + q] = y * y;
        dst[(12u + c) * n + q] = x * y;
    }
}

// Horizontal: one invocation per (map, row, segment of SEG columns).
@compute @workgroup_size(WORKGROUP_SIZE)
fn blur_h(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
          @builtin(local_invocation_index) lid: u32) {
    let n = u.width * u.height;
    let segs = (u.width + SEG - 1u) / SEG;
    let per_map = segs * u.height;
    let i = linear_index(wid, nwg, lid, WORKGROUP_SIZE);
    if (i >= per_map * u.n_maps) {
        return;
    }
    let k = i / per_map;
    let r = i % per_map;
    let row = r / segs;
    let seg = r % segs;
    filter_seg(k * n + row * u.width, seg * SEG, u.width, 1u);
}

// Vertical: one invocation per (map, segment of SEG rows, column).
@compute @workgroup_size(WORKGROUP_SIZE)
fn blur_v(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
          @builtin(local_invocation_index) lid: u32) {
    let n = u.width * u.height;
    let segs = (u.height + SEG - 1u) / SEG;
    let per_map = segs * u.width;
    let i = linear_index(wid, nwg, lid, WORKGROUP_SIZE);
    if (i >= per_map * u.n_maps) {
        return;
    }
    let k = i / per_map;
    let r = i % per_map;
    let seg = r / u.width;
    let col = r % u.width;
    filter_seg(k * n + col, seg * SEG, u.height, u.width);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn ssim_terms(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
              @builtin(local_invocation_index) lid: u32) {
    let n = u.width * u.height;
    let block = wid.y * nwg.x + wid.x;
    let q = block * WORKGROUP_SIZE + lid;
    var total = 0.0;
    if (q < n) {
        var m = 1.0;
        if (u.has_mask != 0u) {
            m = mask[q];
        }
        let g = m * u.norm;
        for (var c = 0u; c < 3u; c++) {
            var d_mx = 0.0;
            var d_exx = 0.0;
            var d_exy = 0.0;
            if (g != 0.0) {
                let mx = src[c * n + q];
                let my = src[(3u + c) * n + q];
                let exx = src[(6u + c) * n + q];
                let eyy = src[(9u + c) * n + q];
                let exy = src[(12u + c) * n + q];
                let a1 = 2.0 * mx * my + C1;
                let a2 = 2.0 * (exy - mx * my) + C2;
                let b1 = mx * mx + my * my + C1;
                let b2 = (exx - mx * mx) + (eyy - my * my) + C2;
                let s = a1 * a2 / (b1 * b2);
                total += g * s;
                let ds_dexx = -s / b2;
                let ds_dexy = 2.0 * a1 / (b1 * b2);
                let ds_dmx = 2.0 * my * a2 / (b1 * b2) - 2.0 * mx * s / b1 - 2.0 * mx * ds_dexx
                    - my * ds_dexy;
                d_mx = g * ds_dmx;
                d_exx = g * ds_dexx;
                d_exy = g * ds_dexy;
            }
            dst[c * n + q] = d_mx;
            dst[(3u + c) * n + q] = d_exx;
            dst[(6u + c) * n + q] = d_exy;
        }
    }
    s_sum[lid] = total;
    workgroupBarrier();
    // Two-level sum (see `l1_grad` in loss.wgsl).
    for (var i = lid; i < WORKGROUP_SIZE / 8u; i += WORKGROUP_SIZE) {
        var a = 0.0;
        for (var j = 0u; j < 8u; j++) {
            a += s_sum[8u * i + j];
        }
        s_sum[8u * i] = a;
    }
    workgroupBarrier();
    for (var i = lid; i < 1u; i += WORKGROUP_SIZE) {
        var a = 0.0;
        for (var j = 0u; j < WORKGROUP_SIZE / 8u; j++) {
            a += s_sum[8u * j];
        }
        partials[block] = a;
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn ssim_grad(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
             @builtin(local_invocation_index) lid: u32) {
    let n = u.width * u.height;
    let q = linear_index(wid, nwg, lid, WORKGROUP_SIZE);
    if (q >= n) {
        return;
    }
    for (var c = 0u; c < 3u; c++) {
        let x = image[3u * q + c];
        let y = target_rgb[3u * q + c];
        let d = src[c * n + q] + 2.0 * x * src[(3u + c) * n + q] + y * src[(6u + c) * n + q];
        v_image[3u * q + c] += -u.lambda * d;
    }
}
