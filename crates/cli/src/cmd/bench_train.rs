//! `romosplat bench train [--scene DIR] [--steps N] [--backend all|cpu|wgpu]`:
//! training speed as JSON — median step time → steps/s, splats, megapixels/s —
//! at fixed settings (no densification, SH degree 3 active, D-SSIM on), for
//! each backend. Without `--scene` it generates `scenes/small.toml` in a
//! temporary folder.

use super::train::{BackendKind, make_backend, split_views};
use crate::Ctx;
use anyhow::Context;
use loader::{Scene, SceneOptions};
use splat::backend::LossConfig;
use splat::train::data::{initial_splats, load_views, scene_extent};
use splat::train::{TrainOptions, fresh_start};
use splat::types::RenderOptions;
use std::path::PathBuf;
use std::time::Instant;

/// Backends to measure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Which {
    All,
    Cpu,
    Wgpu,
}

/// `romosplat bench train`
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene folder (default: generate scenes/small.toml).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Timed steps per backend (after 3 warm-up steps).
    #[arg(long, default_value_t = 30)]
    pub steps: u32,
    /// Integer image downscale factor.
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    #[arg(long, value_enum, default_value_t = Which::All)]
    pub backend: Which,
    /// Also print a per-kernel profile of the wgpu step (timestamp queries,
    /// median ms per step) plus host sections.
    #[arg(long)]
    pub profile: bool,
}

pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    let tmp;
    let root = match &args.scene {
        Some(p) => p.clone(),
        None => {
            tmp =
                std::env::temp_dir().join(format!("romosplat-bench-train-{}", std::process::id()));
            let spec = loader::synth::spec::load_spec("scenes/small.toml")
                .context("scenes/small.toml (run from the repo root or pass --scene)")?;
            loader::synth::generate(&spec, &tmp)?;
            tmp.clone()
        }
    };
    let scene = Scene::load(
        &root,
        &SceneOptions {
            downscale: args.downscale,
        },
    )?;
    let (train_idx, _) = split_views(&scene, 0);
    let views = load_views(&scene, &train_idx, true)?;
    anyhow::ensure!(!views.is_empty(), "no posed views");
    let cams: Vec<_> = views.iter().map(|v| v.camera).collect();
    let extent = scene_extent(&cams);
    let opts = TrainOptions::default();
    let (init, _) = initial_splats(&scene, &cams, extent, &opts)?;
    let start = fresh_start(init);
    let kinds: Vec<BackendKind> = match args.backend {
        Which::All => vec![BackendKind::Cpu, BackendKind::Wgpu],
        Which::Cpu => vec![BackendKind::Cpu],
        Which::Wgpu => vec![BackendKind::Wgpu],
    };
    let mut results = Vec::new();
    for k in kinds {
        let mut b = match make_backend(k, ctx) {
            Ok(b) => b,
            Err(e) => {
                ctx.info(format!("skipping {k:?}: {e}"));
                results.push(serde_json::json!({ "backend": format!("{k:?}").to_lowercase(), "error": e.to_string() }));
                continue;
            }
        };
        b.upload(&start.splats, &start.adam)?;
        let mut times = Vec::new();
        for s in 0..args.steps + 3 {
            let v = &views[s as usize % views.len()];
            let input = v.step_input(
                opts.learning_rates(s, extent),
                LossConfig::default(),
                RenderOptions {
                    sh_degree: 3,
                    ..Default::default()
                },
            );
            let t = Instant::now();
            b.step(&input)?;
            if s >= 3 {
                times.push(t.elapsed().as_secs_f64());
            }
        }
        times.sort_by(f64::total_cmp);
        let med = times[times.len() / 2];
        let mp = (views[0].camera.width * views[0].camera.height) as f64 / 1e6;
        let r = serde_json::json!({
            "backend": b.name(),
            "median_step_s": med,
            "steps_per_sec": 1.0 / med,
            "megapixels_per_sec": mp / med,
            "splats": start.splats.len(),
            "width": views[0].camera.width,
            "height": views[0].camera.height,
            "steps": args.steps,
        });
        ctx.info(r.to_string());
        results.push(r);
    }
    let mut out = serde_json::json!({ "scene": root, "results": results });
    if args.profile && args.backend != Which::Cpu {
        let v = &views[0];
        let input = v.step_input(
            opts.learning_rates(0, extent),
            LossConfig::default(),
            RenderOptions {
                sh_degree: 3,
                ..Default::default()
            },
        );
        let prof = splat::gpu::profile_step(&start.splats, &input, 2, args.steps.max(1) as usize)?;
        let map: serde_json::Map<String, serde_json::Value> = prof
            .into_iter()
            .map(|(k, ms)| (k, serde_json::json!((ms * 1000.0).round() / 1000.0)))
            .collect();
        ctx.info(format!(
            "profile (ms per step, medians): {}",
            serde_json::Value::Object(map.clone())
        ));
        out["profile_ms"] = serde_json::Value::Object(map);
    }
    Ok(out)
}
