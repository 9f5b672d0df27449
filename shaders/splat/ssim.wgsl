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
// (src → dst, `n_maps` maps), `blur_v_terms` (vertical filter of the
// statistics in src, then the weighted derivative maps → dst and partial
// sums of g·S), `blur_h` (9 maps), `blur_v_grad` (vertical filter of the
// derivative maps in src, then dL/dx added to v_image).

struct SsimUniforms {
    width: u32,
    height: u32,
    // Maps × 3 channels processed by blur_h.
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

// Maps k0, k0 + 1, … of channel c at element i of a line: planar map k of
// channel c starts at (3k + c)·n, so consecutive maps are `ms` = 3n apart.
fn at3(base: u32, ms: u32, i: i32, lim: i32, stride: u32) -> vec3<f32> {
    return vec3<f32>(at(base, i, lim, stride), at(base + ms, i, lim, stride), at(base + 2u * ms, i, lim, stride));
}

// SSIM at one pixel of one channel from its window statistics (μx, μy,
// E[x²], E[y²], E[xy]) and the pixel weight g: (g·S, g·dS/dμx,
// g·dS/dE[x²], g·dS/dE[xy]).
fn ssim_at(mx: f32, my: f32, exx: f32, eyy: f32, exy: f32, g: f32) -> vec4<f32> {
    if (g == 0.0) {
        return vec4<f32>(0.0);
    }
    let a1 = 2.0 * mx * my + C1;
    let a2 = 2.0 * (exy - mx * my) + C2;
    let b1 = mx * mx + my * my + C1;
    let b2 = (exx - mx * mx) + (eyy - my * my) + C2;
    let s = a1 * a2 / (b1 * b2);
    let ds_dexx = -s / b2;
    let ds_dexy = 2.0 * a1 / (b1 * b2);
    let ds_dmx = 2.0 * my * a2 / (b1 * b2) - 2.0 * mx * s / b1 - 2.0 * mx * ds_dexx - my * ds_dexy;
    return g * vec4<f32>(s, ds_dmx, ds_dexx, ds_dexy);
}

// Vertical filter of channel c's five statistic maps (src) fused with the
// SSIM terms: one invocation per (channel, segment of SEG rows, column)
// slides five 11-value windows (named vec3 + vec2 values) down the column
// and, at each output pixel, writes the weighted derivative maps
// g·dS/d(μx, E[x²], E[xy]) of the channel (maps 0, 1, 2 of dst) and adds g·S
// to its sum; per workgroup partial sums of g·S go to `partials`
// (`ssim::partial_blocks` of them). The vertically filtered statistics
// never reach memory: storing and reloading 15 maps cost more than the
// filter.
@compute @workgroup_size(WORKGROUP_SIZE)
fn blur_v_terms(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
                @builtin(local_invocation_index) lid: u32) {
    let n = u.width * u.height;
    let segs = (u.height + SEG - 1u) / SEG;
    let per_map = segs * u.width;
    let block = wid.y * nwg.x + wid.x;
    let i = block * WORKGROUP_SIZE + lid;
    var total = 0.0;
    if (i < per_map * 3u) {
        let c = i / per_map;
        let r = i % per_map;
        let seg = r / u.width;
        let col = r % u.width;
        let i0 = seg * SEG;
        let stride = u.width;
        let base = c * n + col;
        let ms = 3u * n;
        let base2 = base + 3u * ms;
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
        let l = i32(u.height);
        let s = i32(i0) - 5;
        // a: μx, μy, E[x²] inputs; b: E[y²], E[xy] inputs.
        var a0 = at3(base, ms, s, l, stride);
        var a1 = at3(base, ms, s + 1, l, stride);
        var a2 = at3(base, ms, s + 2, l, stride);
        var a3 = at3(base, ms, s + 3, l, stride);
        var a4 = at3(base, ms, s + 4, l, stride);
        var a5 = at3(base, ms, s + 5, l, stride);
        var a6 = at3(base, ms, s + 6, l, stride);
        var a7 = at3(base, ms, s + 7, l, stride);
        var a8 = at3(base, ms, s + 8, l, stride);
        var a9 = at3(base, ms, s + 9, l, stride);
        var b0 = vec2<f32>(at(base2, s, l, stride), at(base2 + ms, s, l, stride));
        var b1 = vec2<f32>(at(base2, s + 1, l, stride), at(base2 + ms, s + 1, l, stride));
        var b2 = vec2<f32>(at(base2, s + 2, l, stride), at(base2 + ms, s + 2, l, stride));
        var b3 = vec2<f32>(at(base2, s + 3, l, stride), at(base2 + ms, s + 3, l, stride));
        var b4 = vec2<f32>(at(base2, s + 4, l, stride), at(base2 + ms, s + 4, l, stride));
        var b5 = vec2<f32>(at(base2, s + 5, l, stride), at(base2 + ms, s + 5, l, stride));
        var b6 = vec2<f32>(at(base2, s + 6, l, stride), at(base2 + ms, s + 6, l, stride));
        var b7 = vec2<f32>(at(base2, s + 7, l, stride), at(base2 + ms, s + 7, l, stride));
        var b8 = vec2<f32>(at(base2, s + 8, l, stride), at(base2 + ms, s + 8, l, stride));
        var b9 = vec2<f32>(at(base2, s + 9, l, stride), at(base2 + ms, s + 9, l, stride));
        let count = min(SEG, u.height - i0);
        for (var o = 0u; o < count; o++) {
            let e = s + 10 + i32(o);
            let a10 = at3(base, ms, e, l, stride);
            let b10 = vec2<f32>(at(base2, e, l, stride), at(base2 + ms, e, l, stride));
            let fa = t0 * a0 + t1 * a1 + t2 * a2 + t3 * a3 + t4 * a4 + t5 * a5 + t6 * a6 + t7 * a7
                + t8 * a8 + t9 * a9 + t10 * a10;
            let fb = t0 * b0 + t1 * b1 + t2 * b2 + t3 * b3 + t4 * b4 + t5 * b5 + t6 * b6 + t7 * b7
                + t8 * b8 + t9 * b9 + t10 * b10;
            let q = (i0 + o) * u.width + col;
            var m = 1.0;
            if (u.has_mask != 0u) {
                m = mask[q];
            }
            let t = ssim_at(fa.x, fa.y, fa.z, fb.x, fb.y, m * u.norm);
            total += t.x;
            dst[c * n + q] = t.y;
            dst[(3u + c) * n + q] = t.z;
            dst[(6u + c) * n + q] = t.w;
            a0 = a1;
            a1 = a2;
            a2 = a3;
            a3 = a4;
            a4 = a5;
            a5 = a6;
            a6 = a7;
            a7 = a8;
            a8 = a9;
            a9 = a10;
            b0 = b1;
            b1 = b2;
            b2 = b3;
            b3 = b4;
            b4 = b5;
            b5 = b6;
            b6 = b7;
            b7 = b8;
            b8 = b9;
            b9 = b10;
        }
    }
    s_sum[lid] = total;
    workgroupBarrier();
    // Two-level sum (see `l1_grad` in loss.wgsl).
    for (var k = lid; k < WORKGROUP_SIZE / 8u; k += WORKGROUP_SIZE) {
        var a = 0.0;
        for (var j = 0u; j < 8u; j++) {
            a += s_sum[8u * k + j];
        }
        s_sum[8u * k] = a;
    }
    workgroupBarrier();
    for (var k = lid; k < 1u; k += WORKGROUP_SIZE) {
        var a = 0.0;
        for (var j = 0u; j < WORKGROUP_SIZE / 8u; j++) {
            a += s_sum[8u * j];
        }
        partials[block] = a;
    }
}

// Vertical filter of channel c's three derivative maps (src) fused with the
// gradient: one invocation per (channel, segment of SEG rows, column) slides
// three 11-value windows down the column and, at each output pixel, adds
// −λ (f(dμx) + 2x f(dE[x²]) + y f(dE[xy])) to `v_image` (the filtered
// derivative maps never reach memory).
@compute @workgroup_size(WORKGROUP_SIZE)
fn blur_v_grad(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
               @builtin(local_invocation_index) lid: u32) {
    let n = u.width * u.height;
    let segs = (u.height + SEG - 1u) / SEG;
    let per_map = segs * u.width;
    let i = linear_index(wid, nwg, lid, WORKGROUP_SIZE);
    if (i >= per_map * 3u) {
        return;
    }
    let c = i / per_map;
    let r = i % per_map;
    let seg = r / u.width;
    let col = r % u.width;
    let i0 = seg * SEG;
    let stride = u.width;
    let base = c * n + col;
    let ms = 3u * n;
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
    let l = i32(u.height);
    let s = i32(i0) - 5;
    var a0 = at3(base, ms, s, l, stride);
    var a1 = at3(base, ms, s + 1, l, stride);
    var a2 = at3(base, ms, s + 2, l, stride);
    var a3 = at3(base, ms, s + 3, l, stride);
    var a4 = at3(base, ms, s + 4, l, stride);
    var a5 = at3(base, ms, s + 5, l, stride);
    var a6 = at3(base, ms, s + 6, l, stride);
    var a7 = at3(base, ms, s + 7, l, stride);
    var a8 = at3(base, ms, s + 8, l, stride);
    var a9 = at3(base, ms, s + 9, l, stride);
    let count = min(SEG, u.height - i0);
    for (var o = 0u; o < count; o++) {
        let a10 = at3(base, ms, s + 10 + i32(o), l, stride);
        let f = t0 * a0 + t1 * a1 + t2 * a2 + t3 * a3 + t4 * a4 + t5 * a5 + t6 * a6 + t7 * a7
            + t8 * a8 + t9 * a9 + t10 * a10;
        let q = (i0 + o) * u.width + col;
        let x = image[3u * q + c];
        let y = target_rgb[3u * q + c];
        v_image[3u * q + c] += -u.lambda * (f.x + 2.0 * x * f.y + y * f.z);
        a0 = a1;
        a1 = a2;
        a2 = a3;
        a3 = a4;
        a4 = a5;
        a5 = a6;
        a6 = a7;
        a7 = a8;
        a8 = a9;
        a9 = a10;
    }
}
