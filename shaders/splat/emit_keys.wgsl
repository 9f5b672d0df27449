// emit_keys.wgsl — tile binning. `depth_keys` makes (depth, splat) pairs for
// the depth sort; `gather_counts` lists tile counts in depth order for the
// scan; `emit` writes one (tile id, splat) pair per touched tile at the
// scanned offset. Counts and emission both use `tile_rect` and `tile_hit`
// from common.wgsl, so they can never disagree.

struct BinUniforms {
    n: u32,
    grid_x: u32,
    grid_y: u32,
    pad: u32,
}

// Bindings and injected constants: the `kernel!` declaration in
// crates/splat/src/gpu/emit_keys.rs.

@compute @workgroup_size(WORKGROUP_SIZE)
fn depth_keys(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
              @builtin(local_invocation_index) lid: u32) {
    let i = linear_index(wid, nwg, lid, WORKGROUP_SIZE);
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

@compute @workgroup_size(WORKGROUP_SIZE)
fn gather_counts(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
                 @builtin(local_invocation_index) lid: u32) {
    let i = linear_index(wid, nwg, lid, WORKGROUP_SIZE);
    if (i >= u.n) {
        return;
    }
    counts[i] = tile_count(projected[order[i]], vec2<u32>(u.grid_x, u.grid_y));
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn emit(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = linear_index(wid, nwg, lid, WORKGROUP_SIZE);
    if (i >= u.n) {
        return;
    }
    let s = order[i];
    let p = projected[s];
    let r = tile_rect(p, vec2<u32>(u.grid_x, u.grid_y));
    let k2 = tile_k2(p.opacity);
    var off = offsets[i];
    for (var ty = r.y; ty < r.w; ty++) {
        for (var tx = r.x; tx < r.z; tx++) {
            if (tile_hit(p, k2, vec2<u32>(tx, ty))) {
                tile_keys[off] = ty * u.grid_x + tx;
                tile_values[off] = s;
                off++;
            }
        }
    }
}
