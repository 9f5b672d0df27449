//! How much of a trained model INRIA's screen-size prune would remove (a
//! measurement, not a test; it backs the trainer's default of no
//! screen-size prune, as gsplat's `refine_scale2d_stop_iter = 0`).
//!
//! Projects MODEL (a splat PLY or a training checkpoint) into every training
//! view (split.json `clutter`) of SCENE loaded at 1/DOWNSCALE, prints as JSON
//! how many splats ever exceed PX (default 20) pixels of 3σ radius or
//! 0.1 × EXTENT world units of scale, and writes the model without them to
//! OUT, to be scored with `romosplat eval views --splats OUT`.
//!
//! `cargo run --release -p splat --example screen_size_probe -- MODEL SCENE DOWNSCALE EXTENT OUT [PX]`

use splat::RenderOptions;

const USAGE: &str = "usage: screen_size_probe MODEL SCENE DOWNSCALE EXTENT OUT [PX]";

/// A positional argument parsed as `T`, or a one-line error naming it.
fn arg<T: std::str::FromStr>(args: &[String], i: usize, name: &str) -> Result<T, String> {
    let s = args
        .get(i)
        .ok_or_else(|| format!("missing {name}; {USAGE}"))?;
    s.parse()
        .map_err(|_| format!("{name}: cannot parse {s:?}; {USAGE}"))
}

fn run(args: &[String]) -> Result<(), Box<dyn std::error::Error>> {
    if args.len() < 6 || args.len() > 7 {
        return Err(USAGE.into());
    }
    let (src, scene_dir, out) = (&args[1], &args[2], &args[5]);
    let downscale: u32 = arg(args, 3, "DOWNSCALE")?;
    let extent: f32 = arg(args, 4, "EXTENT")?;
    let px: f32 = if args.len() == 7 {
        arg(args, 6, "PX")?
    } else {
        20.0
    };
    let positive = |v: f32| v.is_finite() && v > 0.0;
    if downscale == 0 || !positive(extent) || !positive(px) {
        return Err(format!("DOWNSCALE, EXTENT and PX must be positive; {USAGE}").into());
    }
    let s = if src.ends_with(".ply") {
        splat::io::read_ply(src)?
    } else {
        splat::io::read_checkpoint(src)?.splats
    };
    let scene = loader::scene::Scene::load(scene_dir, &loader::scene::SceneOptions { downscale })?;
    let opts = RenderOptions {
        background: [0.0; 3],
        sh_degree: 3,
        low_pass: 0.3,
        antialiased: false,
    };
    let mut max_r = vec![0f32; s.len()];
    for i in scene.split_indices("clutter") {
        let cam = splat::train::data::camera_of(&scene, i)?;
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
    splat::io::write_ply(out, &st.splats)?;
    Ok(())
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Err(e) = run(&args) {
        eprintln!("screen_size_probe: {e}");
        std::process::exit(2);
    }
}
