//! `romosplat render --splats FILE --scene DIR [--split extra] --out DIR`:
//! render a split's cameras to PNGs (`DIR/<image name>.png`).

use super::train::{BackendKind, apply_poses, make_backend};
use crate::Ctx;
use anyhow::bail;
use loader::{Scene, SceneOptions};
use splat::io::read_ply;
use splat::train::data::camera_of;
use splat::types::RenderOptions;
use std::path::PathBuf;

/// `romosplat render`
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Splats (INRIA PLY).
    #[arg(long)]
    pub splats: PathBuf,
    /// Scene folder whose cameras to render.
    #[arg(long)]
    pub scene: PathBuf,
    /// Split to render: extra, clutter, clean, or all.
    #[arg(long, default_value = "extra")]
    pub split: String,
    /// COLMAP model folder whose poses replace the scene's.
    #[arg(long)]
    pub poses: Option<PathBuf>,
    /// Integer image downscale factor.
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    #[arg(long, value_enum, default_value_t = BackendKind::Auto)]
    pub backend: BackendKind,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
}

/// Frame indices of a split name ("all" = every posed frame).
pub fn split_frames(scene: &Scene, split: &str) -> anyhow::Result<Vec<usize>> {
    let idx: Vec<usize> = if split == "all" {
        (0..scene.len()).collect()
    } else {
        scene.split_indices(split)
    };
    let idx: Vec<usize> = idx
        .into_iter()
        .filter(|&i| scene.frames[i].pose.is_some())
        .collect();
    if idx.is_empty() {
        bail!(
            "{}: split '{split}' has no posed frames",
            scene.root.display()
        );
    }
    Ok(idx)
}

pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    let splats = read_ply(&args.splats)?;
    let mut scene = Scene::load(
        &args.scene,
        &SceneOptions {
            downscale: args.downscale,
        },
    )?;
    if let Some(p) = &args.poses {
        apply_poses(&mut scene, p)?;
    }
    let idx = split_frames(&scene, &args.split)?;
    let mut backend = make_backend(args.backend, ctx)?;
    let opts = RenderOptions {
        sh_degree: splats.sh_degree,
        ..Default::default()
    };
    let mut written = Vec::new();
    let pb = ctx.progress(idx.len() as u64, "render");
    for &i in &idx {
        let cam = camera_of(&scene, i)?;
        let out = backend.render(&splats, &cam, &opts)?;
        let img = image::Rgb32FImage::from_raw(cam.width, cam.height, out.image)
            .ok_or_else(|| anyhow::anyhow!("render size mismatch"))?;
        let path = args.out.join(format!("{}.png", scene.frames[i].name));
        loader::io::write_png_rgb32f(&path, &img)?;
        written.push(path);
        pb.inc(1);
    }
    pb.finish_and_clear();
    ctx.info(format!(
        "rendered {} views to {}",
        written.len(),
        args.out.display()
    ));
    Ok(serde_json::json!({ "split": args.split, "images": written, "backend": backend.name() }))
}
