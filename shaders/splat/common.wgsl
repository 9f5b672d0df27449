// common.wgsl — helpers shared by every splat kernel. The host prepends this
// file to each kernel, so anything two kernels must agree on (tile rectangle
// of a splat, struct layouts) is defined exactly once (Brush's lesson: two
// kernels that each recomputed a tile count disagreed through float drift).

const TILE_SIZE: u32 = 16u;
const TILE_PIXELS: u32 = 256u;

// Layout shared with `splat::types::ProjectedSplat` (48 bytes, all f32 so no
// vec3 padding rules apply).
struct ProjectedSplat {
    mean_x: f32,
    mean_y: f32,
    depth: f32,
    radius: f32,
    conic_a: f32,
    conic_b: f32,
    conic_c: f32,
    opacity: f32,
    color_r: f32,
    color_g: f32,
    color_b: f32,
    // Tile-binning half extents in pixels, x in the low 16 bits, y in the
    // high 16 (`ProjectedSplat::tile_extent` on the Rust side; see `tile_extent`).
    extent: u32,
}

// Linear invocation index for 1D work spread over a 2D grid of workgroups
// (see `kernel::groups_1d`).
fn linear_index(wid: vec3<u32>, nwg: vec3<u32>, lid: u32, wg_size: u32) -> u32 {
    return (wid.y * nwg.x + wid.x) * wg_size + lid;
}

// Largest tile extent (pixels): keeps the packed pair a finite f32 bit
// pattern on the Rust side (`reference::project::MAX_EXTENT`).
const MAX_EXTENT: f32 = 32639.0;

// gsplat's opacity-aware per-axis tile extents, packed (x low, y high 16
// bits): α = o·G ≥ 1/255 only within Mahalanobis distance
// sqrt(2 ln(255 o)), so k = min(3, that) and the half extents are
// ceil(k·sqrt(Σ'xx)), ceil(k·sqrt(Σ'yy)) of the dilated covariance; 0 (no
// tiles) when 255·o ≤ 1. Mirrors `reference::project::tile_extent`.
fn tile_extent(sxx: f32, syy: f32, o: f32) -> u32 {
    let th = 255.0 * o;
    if (!(th > 1.0)) {
        return 0u;
    }
    let k = min(sqrt(2.0 * log(th)), 3.0);
    let ex = min(ceil(k * sqrt(max(sxx, 0.0))), MAX_EXTENT);
    let ey = min(ceil(k * sqrt(max(syy, 0.0))), MAX_EXTENT);
    return u32(ex) | (u32(ey) << 16u);
}

// Tiles touched by a projected splat: [min.xy, max.zw) in tile units, clamped
// to the grid, from its mean and packed per-axis extents. Radius 0 (culled)
// or a zero extent gives an empty rectangle. Mirrors
// `reference::rasterize::tile_rect`.
fn tile_rect(p: ProjectedSplat, grid: vec2<u32>) -> vec4<u32> {
    let ext = vec2<f32>(f32(p.extent & 0xffffu), f32(p.extent >> 16u));
    if (!(p.radius > 0.0 && ext.x > 0.0 && ext.y > 0.0)) {
        return vec4<u32>(0u, 0u, 0u, 0u);
    }
    let ts = f32(TILE_SIZE);
    let lo = vec2<f32>(p.mean_x - ext.x, p.mean_y - ext.y) / ts;
    let hi = vec2<f32>(p.mean_x + ext.x, p.mean_y + ext.y) / ts;
    let gmax = vec2<f32>(grid);
    let mn = clamp(floor(lo), vec2<f32>(0.0), gmax);
    let mx = clamp(ceil(hi), vec2<f32>(0.0), gmax);
    return vec4<u32>(vec2<u32>(mn), vec2<u32>(mx));
}

// k² = min(9, 2 ln(255 o)): the squared Mahalanobis radius within which a
// splat of opacity `o` reaches α ≥ 1/255 (3σ cap, as the tile extents);
// −1 (no tile) when 255·o ≤ 1. Mirrors `reference::rasterize::tile_k2`.
fn tile_k2(o: f32) -> f32 {
    let th = 255.0 * o;
    if (!(th > 1.0)) {
        return -1.0;
    }
    return min(2.0 * log(th), 9.0);
}

// Whether splat `p` reaches Mahalanobis distance² ≤ `k2` at some pixel
// centre of tile `t`: the exact minimum of the quadratic over the tile's
// pixel-centre rectangle, taken on the edges that face the mean (0 when the
// mean is inside). Mirrors `reference::rasterize::tile_hit` operation for
// operation.
fn tile_hit(p: ProjectedSplat, k2: f32, t: vec2<u32>) -> bool {
    let ts = f32(TILE_SIZE);
    let lo = vec2<f32>(f32(t.x) * ts + 0.5, f32(t.y) * ts + 0.5);
    let hi = vec2<f32>(lo.x + (ts - 1.0), lo.y + (ts - 1.0));
    let a = p.conic_a;
    let b = p.conic_b;
    let c = p.conic_c;
    let mean = vec2<f32>(p.mean_x, p.mean_y);
    let near = vec2<f32>(clamp(mean.x, lo.x, hi.x), clamp(mean.y, lo.y, hi.y));
    if (near.x == mean.x && near.y == mean.y) {
        return k2 >= 0.0;
    }
    var best = 3.4028235e38;
    if (near.x != mean.x) {
        let dx = near.x - mean.x;
        let dy = clamp(-b * dx / c, lo.y - mean.y, hi.y - mean.y);
        best = min(best, a * dx * dx + 2.0 * b * dx * dy + c * dy * dy);
    }
    if (near.y != mean.y) {
        let dy = near.y - mean.y;
        let dx = clamp(-b * dy / a, lo.x - mean.x, hi.x - mean.x);
        best = min(best, a * dx * dx + 2.0 * b * dx * dy + c * dy * dy);
    }
    return best <= k2;
}

// Tiles of `tile_rect` that `tile_hit` keeps.
fn tile_count(p: ProjectedSplat, grid: vec2<u32>) -> u32 {
    let r = tile_rect(p, grid);
    let k2 = tile_k2(p.opacity);
    var n = 0u;
    for (var ty = r.y; ty < r.w; ty++) {
        for (var tx = r.x; tx < r.z; tx++) {
            n += u32(tile_hit(p, k2, vec2<u32>(tx, ty)));
        }
    }
    return n;
}

// ---------------------------------------------------------------------------
// Camera and render options shared by project / rasterize / backward kernels.
// Layout mirrors `gpu::project::CameraUniforms` (160 bytes).
struct CameraUniforms {
    rot0: vec4<f32>,        // world-to-camera rotation rows (w unused)
    rot1: vec4<f32>,
    rot2: vec4<f32>,
    trans: vec4<f32>,       // world-to-camera translation (xyz)
    center: vec4<f32>,      // camera centre in world (xyz)
    focal: vec4<f32>,       // fx, fy, cx, cy
    clip: vec4<f32>,        // near, far, 1.3·tan(fovx/2), 1.3·tan(fovy/2)
    background: vec4<f32>,  // rgb, w = low-pass dilation (px²)
    width: u32,
    height: u32,
    grid_x: u32,
    grid_y: u32,
    n: u32,                 // number of splats
    sh_degree: u32,         // degree used for colour (≤ stored)
    sh_stored: u32,         // coefficients stored per channel
    antialiased: u32,       // 1 = Mip-Splatting opacity compensation
}

const ALPHA_MAX: f32 = 0.99;
const ALPHA_MIN: f32 = 0.00392156862745098; // 1 / 255
const T_MIN: f32 = 0.0001;

fn is_finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

fn is_nan(x: f32) -> bool {
    let b = bitcast<u32>(x);
    return (b & 0x7f800000u) == 0x7f800000u && (b & 0x007fffffu) != 0u;
}

// Rust's `v.max(0.0)`: NaN gives 0 (WGSL's max leaves NaN unspecified).
fn max0(v: f32) -> f32 {
    if (is_nan(v)) {
        return 0.0;
    }
    return max(v, 0.0);
}

fn all_finite3(v: vec3<f32>) -> bool {
    return is_finite(v.x) && is_finite(v.y) && is_finite(v.z);
}

fn sigmoid(x: f32) -> f32 {
    return 1.0 / (1.0 + exp(-x));
}

const SH_C0: f32 = 0.28209479177387814;
const SH_C1: f32 = 0.4886025119029199;
const SH_C2_0: f32 = 1.0925484305920792;
const SH_C2_1: f32 = -1.0925484305920792;
const SH_C2_2: f32 = 0.31539156525252005;
const SH_C2_3: f32 = -1.0925484305920792;
const SH_C2_4: f32 = 0.5462742152960396;
const SH_C3_0: f32 = -0.5900435899266435;
const SH_C3_1: f32 = 2.890611442640554;
const SH_C3_2: f32 = -0.4570457994644658;
const SH_C3_3: f32 = 0.3731763325901154;
const SH_C3_4: f32 = -0.4570457994644658;
const SH_C3_5: f32 = 1.445305721320277;
const SH_C3_6: f32 = -0.5900435899266435;

// Sixteen SH values, entry k in component k % 4 of `v[k / 4]`. Named
// vectors rather than an array: `sh_at` picks entry k with selects, so a
// loop over k stays in registers (llvmpipe keeps a dynamically indexed
// private array in per-lane scratch memory, ~64 scattered stores per
// invocation for the basis and its gradient).
struct Sh16 {
    v0: vec4<f32>,
    v1: vec4<f32>,
    v2: vec4<f32>,
    v3: vec4<f32>,
}

// Entry `k` (< 16) of `b`.
fn sh_at(b: Sh16, k: u32) -> f32 {
    var v = b.v0;
    v = select(v, b.v1, k >= 4u);
    v = select(v, b.v2, k >= 8u);
    v = select(v, b.v3, k >= 12u);
    let c = k & 3u;
    return select(select(select(v.x, v.y, c == 1u), v.z, c == 2u), v.w, c == 3u);
}

// Entries above degree `degree` set to 0.
fn sh_truncate(b: Sh16, degree: u32) -> Sh16 {
    var r = b;
    let zero = vec4<f32>(0.0);
    if (degree < 1u) {
        r.v0 = vec4<f32>(r.v0.x, 0.0, 0.0, 0.0);
    }
    if (degree < 2u) {
        r.v1 = zero;
        r.v2 = zero;
    }
    if (degree < 3u) {
        r.v2 = vec4<f32>(r.v2.x, 0.0, 0.0, 0.0);
        r.v3 = zero;
    }
    return r;
}

// Real SH basis (INRIA constants and signs), (degree+1)² entries, rest 0.
fn sh_basis(degree: u32, d: vec3<f32>) -> Sh16 {
    let x = d.x; let y = d.y; let z = d.z;
    let xx = x * x; let yy = y * y; let zz = z * z;
    let xy = x * y; let yz = y * z; let xz = x * z;
    var b: Sh16;
    b.v0 = vec4<f32>(SH_C0, -SH_C1 * y, SH_C1 * z, -SH_C1 * x);
    b.v1 = vec4<f32>(SH_C2_0 * xy, SH_C2_1 * yz, SH_C2_2 * (2.0 * zz - xx - yy), SH_C2_3 * xz);
    b.v2 = vec4<f32>(SH_C2_4 * (xx - yy), SH_C3_0 * y * (3.0 * xx - yy), SH_C3_1 * xy * z,
        SH_C3_2 * y * (4.0 * zz - xx - yy));
    b.v3 = vec4<f32>(SH_C3_3 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy), SH_C3_4 * x * (4.0 * zz - xx - yy),
        SH_C3_5 * z * (xx - yy), SH_C3_6 * x * (xx - 3.0 * yy));
    return sh_truncate(b, degree);
}

// d basis_k / d(x, y, z), one `Sh16` per axis.
struct ShGrad {
    x: Sh16,
    y: Sh16,
    z: Sh16,
}

fn sh_grad_at(g: ShGrad, k: u32) -> vec3<f32> {
    return vec3<f32>(sh_at(g.x, k), sh_at(g.y, k), sh_at(g.z, k));
}

fn sh_basis_grad(degree: u32, d: vec3<f32>) -> ShGrad {
    let x = d.x; let y = d.y; let z = d.z;
    let xx = x * x; let yy = y * y; let zz = z * z;
    var g: ShGrad;
    g.x.v0 = vec4<f32>(0.0, 0.0, 0.0, -SH_C1);
    g.y.v0 = vec4<f32>(0.0, -SH_C1, 0.0, 0.0);
    g.z.v0 = vec4<f32>(0.0, 0.0, SH_C1, 0.0);
    g.x.v1 = vec4<f32>(SH_C2_0 * y, 0.0, -2.0 * SH_C2_2 * x, SH_C2_3 * z);
    g.y.v1 = vec4<f32>(SH_C2_0 * x, SH_C2_1 * z, -2.0 * SH_C2_2 * y, 0.0);
    g.z.v1 = vec4<f32>(0.0, SH_C2_1 * y, 4.0 * SH_C2_2 * z, SH_C2_3 * x);
    g.x.v2 = vec4<f32>(2.0 * SH_C2_4 * x, SH_C3_0 * 6.0 * x * y, SH_C3_1 * y * z, SH_C3_2 * (-2.0 * x * y));
    g.y.v2 = vec4<f32>(-2.0 * SH_C2_4 * y, SH_C3_0 * (3.0 * xx - 3.0 * yy), SH_C3_1 * x * z,
        SH_C3_2 * (4.0 * zz - xx - 3.0 * yy));
    g.z.v2 = vec4<f32>(0.0, 0.0, SH_C3_1 * x * y, SH_C3_2 * (8.0 * y * z));
    g.x.v3 = vec4<f32>(SH_C3_3 * (-6.0 * x * z), SH_C3_4 * (4.0 * zz - 3.0 * xx - yy), SH_C3_5 * 2.0 * x * z,
        SH_C3_6 * (3.0 * xx - 3.0 * yy));
    g.y.v3 = vec4<f32>(SH_C3_3 * (-6.0 * y * z), SH_C3_4 * (-2.0 * x * y), -SH_C3_5 * 2.0 * y * z,
        -SH_C3_6 * 6.0 * x * y);
    g.z.v3 = vec4<f32>(SH_C3_3 * (6.0 * zz - 3.0 * xx - 3.0 * yy), SH_C3_4 * (8.0 * x * z), SH_C3_5 * (xx - yy), 0.0);
    // Entry 0 (constant) has no gradient; the rest up to `degree`.
    g.x = sh_truncate(g.x, degree);
    g.y = sh_truncate(g.y, degree);
    g.z = sh_truncate(g.z, degree);
    return g;
}

// Forward projection intermediates, shared by `project` and
// `project_backward` so both follow the same math as
// `reference::project::project_one`.
struct ProjInter {
    ok: bool,
    p_cam: vec3<f32>,
    qn: vec4<f32>,
    qnorm: f32,
    r0: vec3<f32>,          // rows of R(q̂)
    r1: vec3<f32>,
    r2: vec3<f32>,
    scale: vec3<f32>,
    c0: vec3<f32>,          // rows of Σ3
    c1: vec3<f32>,
    c2: vec3<f32>,
    jw0: vec3<f32>,         // rows of J·W
    jw1: vec3<f32>,
    clamped_x: bool,
    clamped_y: bool,
    cov2d: vec3<f32>,       // undilated (a, b, c)
    det: f32,               // dilated determinant
    comp: f32,
    sig: f32,
    mean2d: vec2<f32>,
    radius: f32,
    conic: vec3<f32>,
}

// Geometry of one splat (everything but colour). `ok == false` = culled.
fn project_geometry(m: vec3<f32>, ls: vec3<f32>, q: vec4<f32>, logit: f32, cam: CameraUniforms) -> ProjInter {
    var it: ProjInter;
    it.ok = false;
    if (!(all_finite3(m) && all_finite3(ls) && all_finite3(q.xyz) && is_finite(q.w) && is_finite(logit))) {
        return it;
    }
    let w0 = cam.rot0.xyz; let w1 = cam.rot1.xyz; let w2 = cam.rot2.xyz;
    it.p_cam = vec3<f32>(dot(w0, m) + cam.trans.x, dot(w1, m) + cam.trans.y, dot(w2, m) + cam.trans.z);
    let tx = it.p_cam.x; let ty = it.p_cam.y; let tz = it.p_cam.z;
    if (!is_finite(tz) || tz < cam.clip.x || tz > cam.clip.y) {
        return it;
    }
    let n2 = q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w;
    if (!(n2 > 0.0) || !is_finite(n2)) {
        return it;
    }
    it.qnorm = sqrt(n2);
    it.qn = q / it.qnorm;
    let qw = it.qn.x; let qx = it.qn.y; let qy = it.qn.z; let qz = it.qn.w;
    it.r0 = vec3<f32>(1.0 - 2.0 * (qy * qy + qz * qz), 2.0 * (qx * qy - qw * qz), 2.0 * (qx * qz + qw * qy));
    it.r1 = vec3<f32>(2.0 * (qx * qy + qw * qz), 1.0 - 2.0 * (qx * qx + qz * qz), 2.0 * (qy * qz - qw * qx));
    it.r2 = vec3<f32>(2.0 * (qx * qz - qw * qy), 2.0 * (qy * qz + qw * qx), 1.0 - 2.0 * (qx * qx + qy * qy));
    it.scale = exp(ls);
    let m0 = it.r0 * it.scale; let m1 = it.r1 * it.scale; let m2 = it.r2 * it.scale;
    it.c0 = vec3<f32>(dot(m0, m0), dot(m0, m1), dot(m0, m2));
    it.c1 = vec3<f32>(dot(m1, m0), dot(m1, m1), dot(m1, m2));
    it.c2 = vec3<f32>(dot(m2, m0), dot(m2, m1), dot(m2, m2));
    let xz = tx / tz; let yz = ty / tz;
    let cx_ = min(max(xz, -cam.clip.z), cam.clip.z);
    let cy_ = min(max(yz, -cam.clip.w), cam.clip.w);
    it.clamped_x = cx_ != xz;
    it.clamped_y = cy_ != yz;
    let fx = cam.focal.x; let fy = cam.focal.y;
    let j00 = fx / tz; let j02 = -fx * cx_ / tz;
    let j11 = fy / tz; let j12 = -fy * cy_ / tz;
    it.jw0 = j00 * w0 + j02 * w2;
    it.jw1 = j11 * w1 + j12 * w2;
    let t0 = it.jw0.x * it.c0 + it.jw0.y * it.c1 + it.jw0.z * it.c2;
    let t1 = it.jw1.x * it.c0 + it.jw1.y * it.c1 + it.jw1.z * it.c2;
    it.cov2d = vec3<f32>(dot(t0, it.jw0), dot(t0, it.jw1), dot(t1, it.jw1));
    let lp = cam.background.w;
    let a = it.cov2d.x + lp; let b = it.cov2d.y; let c = it.cov2d.z + lp;
    it.det = a * c - b * b;
    if (!(it.det > 0.0) || !is_finite(it.det)) {
        return it;
    }
    it.conic = vec3<f32>(c / it.det, -b / it.det, a / it.det);
    let mid = 0.5 * (a + c);
    let lambda = mid + sqrt(max(mid * mid - it.det, 0.1));
    it.radius = ceil(3.0 * sqrt(lambda));
    it.mean2d = vec2<f32>(fx * xz + cam.focal.z, fy * yz + cam.focal.w);
    let w = f32(cam.width); let h = f32(cam.height);
    if (!(it.radius > 0.0) || it.mean2d.x + it.radius <= 0.0 || it.mean2d.x - it.radius >= w
        || it.mean2d.y + it.radius <= 0.0 || it.mean2d.y - it.radius >= h) {
        return it;
    }
    it.comp = 1.0;
    if (cam.antialiased != 0u) {
        let det0 = it.cov2d.x * it.cov2d.z - it.cov2d.y * it.cov2d.y;
        it.comp = sqrt(max(det0 / it.det, 0.0));
    }
    it.sig = sigmoid(logit);
    it.ok = is_finite(it.mean2d.x) && is_finite(it.mean2d.y) && all_finite3(it.conic)
        && is_finite(it.radius) && is_finite(it.sig * it.comp);
    return it;
}

// Unit view direction from the camera centre and its length (dir = +z when 0).
fn view_dir(m: vec3<f32>, cam: CameraUniforms) -> vec4<f32> {
    let d = m - cam.center.xyz;
    let dist = sqrt(dot(d, d));
    if (dist > 0.0) {
        return vec4<f32>(d / dist, dist);
    }
    return vec4<f32>(0.0, 0.0, 1.0, 0.0);
}

// Half widths (x, y) of the axis-aligned box around a splat's mean outside
// which α = o·G < 1/255 at every pixel, so `alpha_at` skips it: α ≥ 1/255
// needs Mahalanobis d² ≤ 2 ln(255 o), and |dx| ≤ d·sqrt(Σ'xx) with
// Σ' = conic⁻¹. Unlike the tile extents this is not capped at 3σ: it only
// lets rasterizers skip work that `alpha_at` would skip anyway (the margins
// cover f32 rounding of α near the threshold). Negative = no pixel at all;
// NaN (degenerate conic) compares false in `box_misses`, so nothing is skipped.
fn alpha_box(conic: vec3<f32>, o: f32) -> vec2<f32> {
    let th = 255.0 * o;
    if (!(th > 1.0)) {
        return vec2<f32>(-1.0);
    }
    let k2 = 2.0 * log(th) + 0.01;
    let det = conic.x * conic.z - conic.y * conic.y;
    return sqrt(k2 * vec2<f32>(conic.z, conic.x) / det) * 1.001 + 0.01;
}

// True when every pixel centre of [bmin, bmax] lies outside a splat's
// `alpha_box` `half` around `mean` (so no pixel there gets α ≥ 1/255).
fn box_misses(mean: vec2<f32>, half: vec2<f32>, bmin: vec2<f32>, bmax: vec2<f32>) -> bool {
    let gap = max(max(bmin - mean, mean - bmax), vec2<f32>(0.0));
    return gap.x > half.x || gap.y > half.y;
}

// Gaussian falloff at a pixel centre: (alpha, G, dx, dy); alpha < 0 = skip.
// Mirrors `reference::rasterize::alpha_at`.
fn alpha_at(mean: vec2<f32>, conic: vec3<f32>, opacity: f32, px: f32, py: f32) -> vec4<f32> {
    let dx = mean.x - px;
    let dy = mean.y - py;
    let power = -0.5 * (conic.x * dx * dx + conic.z * dy * dy) - conic.y * dx * dy;
    if (power > 0.0) {
        return vec4<f32>(-1.0, 0.0, dx, dy);
    }
    let g = exp(power);
    let alpha = min(opacity * g, ALPHA_MAX);
    if (alpha < ALPHA_MIN) {
        return vec4<f32>(-1.0, g, dx, dy);
    }
    return vec4<f32>(alpha, g, dx, dy);
}
