//! Benchmark: how many (tile, splat) intersections the binning produces with
//! the old circular 3σ radius (`ceil(3·sqrt(λ_max))`) versus the current
//! opacity-aware per-axis extents (gsplat style, `reference::project`), on
//! the initial splats of a scene, averaged over its first 8 views.
//! Scene: `TILE_BENCH_SCENE` (a scene folder, default `../shared/data/fox` from the repo root),
//! `TILE_BENCH_DOWNSCALE` (default 4). Prints one JSON object.
//! Run: `cargo bench -p splat --bench tile_bounds`.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use loader::scene::{Scene, SceneOptions};
use splat::reference::rasterize::tile_rect;
use splat::train::TrainOptions;
use splat::train::data::{camera_of, initial_splats, scene_extent};
use splat::types::RenderOptions;

fn main() {
    let root = std::env::var("TILE_BENCH_SCENE").unwrap_or_else(|_| {
        concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data/fox").into()
    });
    let downscale: u32 = std::env::var("TILE_BENCH_DOWNSCALE")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(4);
    let scene = Scene::load(std::path::Path::new(&root), &SceneOptions { downscale }).unwrap();
    let cams: Vec<_> = (0..scene.frames.len())
        .filter_map(|i| camera_of(&scene, i).ok())
        .collect();
    let extent = scene_extent(&cams);
    let (splats, _) = initial_splats(&scene, &cams, extent, &TrainOptions::default()).unwrap();
    let opts = RenderOptions {
        sh_degree: 3,
        ..Default::default()
    };
    let (mut circle, mut tight, mut views) = (0u64, 0u64, 0u64);
    for cam in cams.iter().take(8) {
        let grid = cam.tile_grid();
        let proj = splat::reference::project(&splats, cam, &opts);
        let area = |r: Option<[u32; 4]>| r.map_or(0, |r| ((r[2] - r[0]) * (r[3] - r[1])) as u64);
        for p in &proj {
            circle += area(tile_rect(p.mean2d, p.radius, [p.radius; 2], grid));
            let e = splat::reference::project::unpack_extent(p._pad);
            tight += area(tile_rect(p.mean2d, p.radius, e, grid));
        }
        views += 1;
    }
    let v = views.max(1) as f64;
    println!(
        "{}",
        serde_json::json!({
            "scene": root,
            "splats": splats.len(),
            "views": views,
            "intersections_circle_3sigma": circle as f64 / v,
            "intersections_tight": tight as f64 / v,
            "ratio": tight as f64 / circle.max(1) as f64,
        })
    );
}
