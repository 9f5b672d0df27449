//! `romosplat bench mask [--scene DIR | --images DIR | --frames N]`: speed
//! of the whole mask stage with the built-in backends; prints per-stage
//! medians (ms, total and per frame) and frames per second as JSON. `--images`
//! takes a folder of frames (e.g. a DAVIS sequence,
//! `JPEGImages/480p/car-roundabout`); without either it generates a
//! synthetic 854×480 textured sequence with a moving block in a temp folder.

use crate::Ctx;
use anyhow::Context;
use std::path::PathBuf;

/// `romosplat bench mask ...`
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene folder to time (default: generated 854×480 frames).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Folder of video frames (jpg/png, sorted by name), e.g. a DAVIS
    /// sequence; `--max-frames` limits how many are used.
    #[arg(long, conflicts_with = "scene")]
    pub images: Option<PathBuf>,
    /// Use at most this many frames of `--images`.
    #[arg(long)]
    pub max_frames: Option<usize>,
    /// Options as a (partial) RomoOptions JSON, e.g. '{"grid_max_side": 192}',
    /// or a file holding one.
    #[arg(long)]
    pub options: Option<String>,
    /// Frames to generate when no scene is given.
    #[arg(long, default_value_t = 30)]
    pub frames: usize,
    /// Repetitions (medians are reported).
    #[arg(long, default_value_t = 3)]
    pub reps: usize,
}

fn synthetic(dir: &std::path::Path, n: usize) -> anyhow::Result<()> {
    let (w, h) = (854u32, 480u32);
    let tex = |x: f32, y: f32| {
        let v = 0.5
            + 0.15 * (0.11 * x + 0.07 * y).sin()
            + 0.1 * (0.031 * x - 0.13 * y + 1.0).sin()
            + 0.08 * (0.23 * x + 0.19 * y).sin();
        (v.clamp(0.0, 1.0) * 255.0) as u8
    };
    for t in 0..n {
        let pan = 2.0 * t as f32;
        let (bx, by) = (200.0 + 6.0 * t as f32, 180.0);
        let img = image::RgbImage::from_fn(w, h, |x, y| {
            let (xf, yf) = (x as f32, y as f32);
            if xf > bx && xf < bx + 120.0 && yf > by && yf < by + 160.0 {
                let v = tex(3.0 * (xf - bx) + 500.0, 3.0 * (yf - by));
                image::Rgb([v, v / 2, 40])
            } else {
                let v = tex(xf + pan, yf);
                image::Rgb([v, v, v / 2 + 60])
            }
        });
        loader::io::write_png_rgb8(dir.join("images").join(format!("{t:05}.png")), &img)?;
    }
    Ok(())
}

fn image_files(dir: &std::path::Path, max: Option<usize>) -> anyhow::Result<Vec<PathBuf>> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("{}: cannot list frames", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "jpg" | "jpeg" | "png"))
        })
        .collect();
    v.sort();
    if let Some(m) = max {
        v.truncate(m);
    }
    if v.len() < 2 {
        anyhow::bail!("{}: need at least 2 image frames", dir.display());
    }
    Ok(v)
}

/// Run `romosplat bench mask`.
pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    let out = std::env::temp_dir().join(format!("romosplat-bench-mask-out-{}", std::process::id()));
    let mut opts: romo::RomoOptions = match &args.options {
        Some(js) => super::mask::options_arg(std::path::Path::new(js))?,
        None => Default::default(),
    };
    opts.out = Some(out.clone());
    if let Some(dir) = &args.images {
        let paths = image_files(dir, args.max_frames)?;
        let names: Vec<String> = paths
            .iter()
            .map(|p| {
                p.file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default()
            })
            .collect();
        let first = loader::io::read_rgb8(&paths[0])?;
        let (w, h) = (first.width(), first.height());
        let res = time_reps(args, ctx, paths.len(), (w, h), &opts, || {
            Ok(romo::segment_paths(
                &paths,
                &names,
                &out,
                &opts,
                &|_, _, _| {},
            )?)
        });
        let _ = std::fs::remove_dir_all(&out);
        return res.map(|mut v| {
            v["source"] = serde_json::json!(dir.display().to_string());
            v
        });
    }
    let tmp;
    let root = match &args.scene {
        Some(s) => s.clone(),
        None => {
            tmp = std::env::temp_dir().join(format!("romosplat-bench-mask-{}", std::process::id()));
            synthetic(&tmp, args.frames.max(2))?;
            tmp.clone()
        }
    };
    let scene = loader::scene::Scene::load(&root, &loader::scene::SceneOptions::default())
        .with_context(|| format!("loading {}", root.display()))?;
    let n = scene.frames.len();
    let size = scene.full_size(0).unwrap_or((0, 0));
    let res = time_reps(args, ctx, n, size, &opts, || {
        Ok(romo::segment_scene(&scene, &opts, &|_, _, _| {})?)
    });
    let _ = std::fs::remove_dir_all(&out);
    if args.scene.is_none() {
        let _ = std::fs::remove_dir_all(&root);
    }
    res.map(|mut v| {
        v["source"] = serde_json::json!(root.display().to_string());
        v
    })
}

/// Run `f` `reps` times; per-stage and total medians as JSON.
fn time_reps(
    args: &Args,
    ctx: &Ctx,
    n: usize,
    (w, h): (u32, u32),
    opts: &romo::RomoOptions,
    f: impl Fn() -> anyhow::Result<romo::RomoReport>,
) -> anyhow::Result<serde_json::Value> {
    let mut per_stage: std::collections::BTreeMap<String, Vec<f64>> = Default::default();
    let mut totals = Vec::new();
    for r in 0..args.reps.max(1) {
        let t = std::time::Instant::now();
        let rep = f()?;
        let total = t.elapsed().as_secs_f64() * 1e3;
        ctx.info(format!(
            "rep {}: {:.0} ms, {:.2} frames/s",
            r + 1,
            total,
            n as f64 / total * 1e3
        ));
        totals.push(total);
        for (k, v) in rep.timings_ms {
            per_stage.entry(k).or_default().push(v);
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(|a, b| a.total_cmp(b));
        v[v.len() / 2]
    };
    let total = median(&mut totals);
    let stages: serde_json::Map<String, serde_json::Value> = per_stage
        .iter_mut()
        .map(|(k, v)| {
            (
                k.clone(),
                serde_json::json!({"ms": median(v), "ms_per_frame": median(v) / n as f64}),
            )
        })
        .collect();
    let load = std::fs::read_to_string("/proc/loadavg").ok().and_then(|s| {
        s.split_whitespace()
            .next()
            .and_then(|v| v.parse::<f64>().ok())
    });
    Ok(serde_json::json!({
        "frames": n, "width": w, "height": h, "threads": rayon::current_num_threads(),
        "reps": args.reps.max(1), "load_average_1min": load,
        "grid_max_side": opts.grid_max_side, "flow_scale": opts.flow_scale,
        "total_ms_median": total, "ms_per_frame_median": total / n as f64,
        "frames_per_second": n as f64 / total * 1e3, "stages": stages,
    }))
}
