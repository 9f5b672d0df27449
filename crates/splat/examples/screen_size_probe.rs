//! Measurement (not a test): how much of a model the INRIA screen-size
//! prune would remove. Projects MODEL (a splat PLY or a training
//! checkpoint) into every training view (split.json `clutter`) of SCENE,
//! prints how many splats ever exceed `PX` (default 20) pixels of 3σ radius
//! or 0.1 × EXTENT in the world, and writes the model without them to OUT,
//! to be scored with `romosplat eval views --splats OUT`.
//!
//! `cargo run --release -p splat --example screen_size_probe -- MODEL SCENE DOWNSCALE EXTENT OUT [PX]`
#![allow(clippy::unwrap_used, clippy::expect_used)]
use splat::RenderOptions;

fn main() {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 6 {
        eprintln!("usage: screen_size_probe MODEL SCENE DOWNSCALE EXTENT OUT [PX]");
        std::process::exit(2);
    }
    let (src, scene_dir, out) = (&a[1], &a[2], &a[5]);
    let downscale: u32 = a[3].parse().expect("DOWNSCALE");
    let extent: f32 = a[4].parse().expect("EXTENT");
    let px: f32 = a.get(6).map_or(20.0, |s| s.parse().expect("PX"));
    let s = if src.ends_with(".ply") {
        splat::io::read_ply(src).unwrap()
    } else {
        splat::io::read_checkpoint(src).unwrap().splats
    };
    let scene =
        loader::scene::Scene::load(scene_dir, &loader::scene::SceneOptions { downscale }).unwrap();
    let opts = RenderOptions {
        background: [0.0; 3],
        sh_degree: 3,
        low_pass: 0.3,
        antialiased: false,
    };
    let mut max_r = vec![0f32; s.len()];
    for i in scene.split_indices("clutter") {
        let cam = splat::train::data::camera_of(&scene, i).unwrap();
        for (m, p) in max_r
            .iter_mut()
            .zip(splat::reference::project::project(&s, &cam, &opts))
        {
            *m = m.max(p.radius);
        }
    }
    let big_screen: Vec<bool> = max_r.iter().map(|&r| r > px).collect();
    let big_world: Vec<bool> = s
        .log_scales
        .iter()
        .map(|l| l[0].max(l[1]).max(l[2]).exp() > 0.1 * extent)
        .collect();
    let keep: Vec<usize> = (0..s.len())
        .filter(|&i| !(big_screen[i] || big_world[i]))
        .collect();
    let count = |v: &[bool]| v.iter().filter(|&&b| b).count();
    let never_visible = max_r.iter().filter(|&&r| r <= 0.0).count();
    println!(
        "{}",
        serde_json::json!({"splats": s.len(), "screen_over_px": count(&big_screen), "px": px,
            "world_over": count(&big_world), "removed": s.len() - keep.len(),
            "never_visible": never_visible})
    );
    let mut st = splat::strategy::ModelState {
        splats: s.clone(),
        adam: splat::AdamState::zeros_like(&s),
        stats: Default::default(),
    };
    splat::strategy::retain(&mut st, &keep);
    splat::io::write_ply(out, &st.splats).unwrap();
}
