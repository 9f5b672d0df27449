// tile_ranges.wgsl — after the tile sort, the [start, end) of each tile's
// run of keys: ranges[2 t] = start, ranges[2 t + 1] = end. The host clears
// `ranges` to zero first, so empty tiles read as [0, 0).

struct RangeUniforms {
    n: u32,
    num_tiles: u32,
    pad0: u32,
    pad1: u32,
}

// Bindings and injected constants: the `kernel!` declaration in
// crates/splat/src/gpu/tile_ranges.rs.

@compute @workgroup_size(WORKGROUP_SIZE)
fn ranges_main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
               @builtin(local_invocation_index) lid: u32) {
    let i = linear_index(wid, nwg, lid, WORKGROUP_SIZE);
    if (i >= u.n) {
        return;
    }
    let t = tile_keys[i];
    if (t >= u.num_tiles) {
        return;
    }
    if (i == 0u || tile_keys[i - 1u] != t) {
        ranges[2u * t] = i;
    }
    if (i + 1u == u.n || tile_keys[i + 1u] != t) {
        ranges[2u * t + 1u] = i + 1u;
    }
}
