// emit_keys.wgsl — tile binning. `depth_keys` makes (depth, splat) pairs for
// the depth sort; `gather_counts` lists tile counts in depth order for the
// scan; `emit` writes one (tile id, splat) pair per touched tile at the
// scanned offset. Counts and emission both use `tile_rect` from common.wgsl,
// so they can never disagree.

struct BinUniforms {
    n: u32,
    grid_x: u32,
    grid_y: u32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> u: BinUniforms;
@group(0) @binding(1) var<storage, read> projected: array<ProjectedSplat>;
@group(0) @binding(2) var<storage, read_write> depth_keys_out: array<u32>;
@group(0) @binding(3) var<storage, read_write> order: array<u32>;
@group(0) @binding(4) var<storage, read_write> counts: array<u32>;
@group(0) @binding(5) var<storage, read> offsets: array<u32>;
@group(0) @binding(6) var<storage, read_write> tile_keys: array<u32>;
@group(0) @binding(7) var<storage, read_write> tile_values: array<u32>;

@compute @workgroup_size(256)
fn depth_keys(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
              @builtin(local_invocation_index) lid: u32) {
    let i = linear_index(wid, nwg, lid, 256u);
    if (i >= u.n) {
        return;
    }
    let p = projected[i];
    var key = 0xffffffffu;
    if (p.radius > 0.0 && p.depth > 0.0) {
        key = bitcast<u32>(p.depth);
    }
    depth_keys_out[i] = key;
    order[i] = i;
}

@compute @workgroup_size(256)
fn gather_counts(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
                 @builtin(local_invocation_index) lid: u32) {
    let i = linear_index(wid, nwg, lid, 256u);
    if (i >= u.n) {
        return;
    }
    counts[i] = tile_count(projected[order[i]], vec2<u32>(u.grid_x, u.grid_y));
}

@compute @workgroup_size(256)
fn emit(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = linear_index(wid, nwg, lid, 256u);
    if (i >= u.n) {
        return;
    }
    let s = order[i];
    let r = tile_rect(projected[s], vec2<u32>(u.grid_x, u.grid_y));
    var off = offsets[i];
    for (var ty = r.y; ty < r.w; ty++) {
        for (var tx = r.x; tx < r.z; tx++) {
            tile_keys[off] = ty * u.grid_x + tx;
            tile_values[off] = s;
            off++;
        }
    }
}
