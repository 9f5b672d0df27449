//! Benchmark: how many (tile, splat) intersections the binning produces with
//! the old circular 3σ radius (`ceil(3·sqrt(λ_max))`), the opacity-aware
//! per-axis extents (gsplat style, `reference::project`) and the tiles of
//! those rectangles that the ellipse meets (`tile_hit`, what binning uses), on
//! the initial splats of a scene, averaged over its first 8 views.
//! Scene: `TILE_BENCH_SCENE` (a scene folder, default `../shared/data/fox` from the repo root),
//! `TILE_BENCH_DOWNSCALE` (default 4). Prints one JSON object.
//! Run: `cargo bench -p splat --bench tile_bounds`.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use loader::scene::{Scene, SceneOptions};
use splat::reference::rasterize::{tile_hit, tile_k2, tile_rect};
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
    let (mut circle, mut tight, mut ellipse, mut views) = (0u64, 0u64, 0u64, 0u64);
    // (tile, splat, 8-column half) triples, and those where the splat's α ≥ 1/255
    // box (`alpha_box` in common.wgsl, without its margins) misses the half.
    let (mut halves, mut missed) = (0u64, 0u64);
    for cam in cams.iter().take(8) {
        let grid = cam.tile_grid();
        let proj = splat::reference::project(&splats, cam, &opts);
        let area = |r: Option<[u32; 4]>| r.map_or(0, |r| ((r[2] - r[0]) * (r[3] - r[1])) as u64);
        for p in &proj {
            circle += area(tile_rect(p.mean2d, p.radius, [p.radius; 2], grid));
            let e = splat::reference::project::unpack_extent(p.tile_extent);
            let rect = tile_rect(p.mean2d, p.radius, e, grid);
            tight += area(rect);
            let Some(r) = rect else { continue };
            let k2 = tile_k2(p.opacity);
            for ty in r[1]..r[3] {
                for tx in r[0]..r[2] {
                    ellipse += tile_hit(p.mean2d, p.conic, k2, (tx, ty)) as u64;
                }
            }
            let [a, b, c] = p.conic.map(|v| v as f64);
            let th = 255.0 * p.opacity as f64;
            let det = a * c - b * b;
            let half = if th > 1.0 {
                let k2 = 2.0 * th.ln();
                [(k2 * c / det).sqrt(), (k2 * a / det).sqrt()]
            } else {
                [-1.0, -1.0]
            };
            let m = p.mean2d.map(|v| v as f64);
            for ty in r[1]..r[3] {
                for tx in r[0]..r[2] {
                    for h in 0..2u32 {
                        let x0 = (tx * 16 + h * 8) as f64 + 0.5;
                        let y0 = (ty * 16) as f64 + 0.5;
                        let gx = (x0 - m[0]).max(m[0] - (x0 + 7.0)).max(0.0);
                        let gy = (y0 - m[1]).max(m[1] - (y0 + 15.0)).max(0.0);
                        halves += 1;
                        if gx > half[0] || gy > half[1] {
                            missed += 1;
                        }
                    }
                }
            }
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
            "intersections_ellipse": ellipse as f64 / v,
            "ratio": tight as f64 / circle.max(1) as f64,
            "ellipse_ratio": ellipse as f64 / tight.max(1) as f64,
            "half_tile_blocks_missed_by_alpha_box": missed as f64 / halves.max(1) as f64,
        })
    );
}
