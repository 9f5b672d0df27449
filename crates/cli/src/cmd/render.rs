//! `romosplat render --splats FILE --scene DIR [--split extra] --out DIR`:
//! render a split's cameras to PNGs (`DIR/<image name>.png`).

use super::train::{BackendKind, apply_poses, make_backend};
use crate::Ctx;
use anyhow::bail;
use loader::{Scene, SceneOptions};
use splat::io::read_ply;
use splat::train::data::camera_of;
use splat::types::{RenderOptions, Splats};
use std::path::PathBuf;

/// What `render` and `eval views` share: the splats, the scene and which of
/// its views, with optional replacement poses.
#[derive(Debug, clap::Args)]
pub struct ViewArgs {
    /// Splats (INRIA PLY).
    #[arg(long)]
    pub splats: PathBuf,
    /// Scene folder whose cameras (and reference images) to use.
    #[arg(long)]
    pub scene: PathBuf,
    /// Split: extra, clutter, clean, or all.
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
}

impl ViewArgs {
    /// Read the splats and the scene (with replacement poses) and pick the
    /// split's posed frames.
    pub fn load(&self) -> anyhow::Result<(Splats, Scene, Vec<usize>)> {
        let splats = read_ply(&self.splats)?;
        let mut scene = Scene::load(
            &self.scene,
            &SceneOptions {
                downscale: self.downscale,
            },
        )?;
        if let Some(p) = &self.poses {
            apply_poses(&mut scene, p)?;
        }
        let idx = split_frames(&scene, &self.split)?;
        Ok((splats, scene, idx))
    }
}

/// `romosplat render`
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub views: ViewArgs,
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

/// A frame name without its extension (`0001.jpg` → `0001`): renders are
/// named `<stem>.png`.
pub fn stem(name: &str) -> &str {
    std::path::Path::new(name)
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or(name)
}

pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    let (splats, scene, idx) = args.views.load()?;
    let mut backend = make_backend(args.views.backend, ctx)?;
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
        // Named by the frame's stem: `0001.jpg` renders to `0001.png`.
        let path = args
            .out
            .join(format!("{}.png", stem(&scene.frames[i].name)));
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
    Ok(
        serde_json::json!({ "split": args.views.split, "images": written, "backend": backend.name() }),
    )
}
