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
    pad: f32,
}

// Linear invocation index for 1D work spread over a 2D grid of workgroups
// (see `kernel::groups_1d`).
fn linear_index(wid: vec3<u32>, nwg: vec3<u32>, lid: u32, wg_size: u32) -> u32 {
    return (wid.y * nwg.x + wid.x) * wg_size + lid;
}

// Tiles touched by a projected splat: [min.xy, max.zw) in tile units, clamped
// to the grid. Radius 0 (culled) gives an empty rectangle.
fn tile_rect(p: ProjectedSplat, grid: vec2<u32>) -> vec4<u32> {
    if (!(p.radius > 0.0)) {
        return vec4<u32>(0u, 0u, 0u, 0u);
    }
    let ts = f32(TILE_SIZE);
    let lo = vec2<f32>(p.mean_x - p.radius, p.mean_y - p.radius) / ts;
    let hi = vec2<f32>(p.mean_x + p.radius, p.mean_y + p.radius) / ts;
    let gmax = vec2<f32>(grid);
    let mn = clamp(floor(lo), vec2<f32>(0.0), gmax);
    let mx = clamp(ceil(hi), vec2<f32>(0.0), gmax);
    return vec4<u32>(vec2<u32>(mn), vec2<u32>(mx));
}

fn tile_count(p: ProjectedSplat, grid: vec2<u32>) -> u32 {
    let r = tile_rect(p, grid);
    if (r.z <= r.x || r.w <= r.y) {
        return 0u;
    }
    return (r.z - r.x) * (r.w - r.y);
}
