//! Measurement (not a test): RoMo on a generated scene folder `$SCENE`
//! (required; make one with `romosplat scene generate scenes/demo.toml
//! --out DIR`), masks into `$OUT` (default `$SCENE/romo_eval`), J /
//! precision / recall against `gt_motion/` (video frames only; the held-out
//! `extra` views are left out) and the run's per-frame U/L coverage as
//! JSON. `ROMO_OPTS` takes a partial `RomoOptions` JSON.
use std::path::PathBuf;

mod common;
use common::Res;

fn main() -> std::process::ExitCode {
    common::main("scene_eval", run)
}

fn run() -> Res<()> {
    let dir = std::env::var_os("SCENE")
        .map(PathBuf::from)
        .ok_or("set SCENE to a generated scene folder (romosplat scene generate scenes/demo.toml --out DIR)")?;
    let out = std::env::var_os("OUT").map_or_else(|| dir.join("romo_eval"), PathBuf::from);
    let mut opts = common::romo_options()?;
    opts.out = Some(out.clone());
    let downscale: u32 = common::env_or("DOWNSCALE", 1)?;
    let load = |downscale| {
        loader::scene::Scene::load(&dir, &loader::scene::SceneOptions { downscale })
            .map_err(|e| format!("{}: {e}", dir.display()))
    };
    let scene = load(downscale)?;
    let t = std::time::Instant::now();
    let rep = romo::segment_scene(&scene, &opts, &|_, _, _| {})?;
    let secs = t.elapsed().as_secs_f64();
    // Score the video frames only: split.json's `extra` views are clean
    // held-out images with empty ground truth and all-keep masks, which
    // would each count as a perfect J of 1.
    let s = if downscale == 1 {
        romo::evaluate_scene_masks(&scene, &out.join("masks"))?
    } else {
        romo::evaluate_scene_masks(&load(1)?, &out.join("masks"))?
    };
    let n = rep.frames.len().max(1) as f32;
    let u = rep.frames.iter().map(|f| f.u_coverage).sum::<f32>() / n;
    let l = rep.frames.iter().map(|f| f.l_coverage).sum::<f32>() / n;
    let nh = rep.pairs.iter().filter(|p| p.model == "H").count();
    eprintln!(
        "{}: J {:.3} P {:.3} R {:.3} U {u:.4} L {l:.3} H-pairs {nh}/{} {secs:.1}s",
        dir.display(),
        s.j_mean,
        s.precision,
        s.recall,
        rep.pairs.len()
    );
    println!(
        "{}",
        serde_json::json!({"j": s.j_mean, "precision": s.precision, "recall": s.recall,
            "u_cov": u, "l_cov": l, "h_pairs": nh, "seconds": secs, "timings_ms": rep.timings_ms,
            "rounds": rep.rounds})
    );
    Ok(())
}
