//! `romosplat mask --scene DIR [--out DIR]`: RoMo motion masks for a scene,
//! written as `masks/<image name>.png` (255 keep, 0 moving).

use crate::Ctx;
use anyhow::Context;
use std::path::{Path, PathBuf};

/// `romosplat mask ...`
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene folder (with `images/`).
    #[arg(long)]
    pub scene: PathBuf,
    /// Full options as a JSON file, or the JSON itself (`'{"seed": 1}'`):
    /// a partial `RomoOptions`; the flags override it.
    #[arg(long)]
    pub options: Option<PathBuf>,
    /// Integer downscale of the frames on load (masks are still written at
    /// the images' own size).
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    /// RoMo's options (`romo::RomoOptions`; each flag's default is its
    /// field's).
    #[command(flatten)]
    pub romo: romo::cli::Flags<romo::RomoOptions>,
}

/// Run `romosplat mask`.
pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    let opts = options(args)?;
    let (report, copy) = segment_with_copy(&args.scene, args.downscale, &opts, true, ctx)?;
    let mut out = serde_json::to_value(&report)?;
    if let Some(c) = &copy {
        ctx.info(format!(
            "nerfstudio transforms.json with mask_path: {}",
            c.display()
        ));
    }
    out["transforms_with_masks"] = serde_json::json!(copy);
    Ok(out)
}

/// A `RomoOptions` JSON file (a partial one: missing fields keep their defaults).
pub fn read_options(path: &Path) -> anyhow::Result<romo::RomoOptions> {
    let s = std::fs::read_to_string(path).with_context(|| format!("{}", path.display()))?;
    parse_options(&s).with_context(|| format!("{}: not a RomoOptions JSON", path.display()))
}

/// A partial `RomoOptions` from JSON text. Only an object: serde would also
/// fill a struct from an array, field by field in declaration order.
fn parse_options(s: &str) -> anyhow::Result<romo::RomoOptions> {
    let v: serde_json::Value = serde_json::from_str(s)?;
    anyhow::ensure!(v.is_object(), "expected a JSON object");
    Ok(serde_json::from_value(v)?)
}

/// `--options`: the JSON itself when the argument starts with `{`, else a
/// JSON file ([`read_options`]).
pub fn options_arg(arg: &Path) -> anyhow::Result<romo::RomoOptions> {
    match arg.to_str().map(str::trim_start) {
        Some(js) if js.starts_with('{') => {
            parse_options(js).context("--options: not a RomoOptions JSON")
        }
        _ => read_options(arg),
    }
}

/// The RoMo options these flags select (`--options`, then the flags).
pub fn options(args: &Args) -> anyhow::Result<romo::RomoOptions> {
    let base = match &args.options {
        Some(p) => options_arg(p)?,
        None => romo::RomoOptions::default(),
    };
    Ok(args.romo.over(base)?)
}

/// RoMo masks for the scene folder `scene_dir` (frames downscaled by
/// `downscale` on load), written where `opts.out` says (default the scene).
pub fn segment(
    scene_dir: &Path,
    downscale: u32,
    opts: &romo::RomoOptions,
    ctx: &Ctx,
) -> anyhow::Result<romo::RomoReport> {
    Ok(segment_with_copy(scene_dir, downscale, opts, false, ctx)?.0)
}

/// [`segment`], and with `nerfstudio_copy` also the scene's transforms.json
/// copy with every frame's `mask_path` ([`write_transforms_copy`]), staged
/// with the masks so that both appear or neither does. Returns the copy's
/// path when one was written.
fn segment_with_copy(
    scene_dir: &Path,
    downscale: u32,
    opts: &romo::RomoOptions,
    nerfstudio_copy: bool,
    ctx: &Ctx,
) -> anyhow::Result<(romo::RomoReport, Option<PathBuf>)> {
    let scene = loader::scene::Scene::load(scene_dir, &loader::scene::SceneOptions { downscale })
        .with_context(|| format!("loading scene {}", scene_dir.display()))?;
    // Masks (and overlays, probabilities) are staged and moved into place
    // together: a failure leaves no partial set behind.
    let out = opts.out.clone().unwrap_or_else(|| scene_dir.to_path_buf());
    let stage = loader::io::Staging::new(&out)?;
    let mut opts = opts.clone();
    opts.out = Some(stage.path().to_path_buf());
    ctx.info(format!(
        "romo: {} frames from {}",
        scene.frames.len(),
        scene_dir.display()
    ));
    let pb = ctx.progress(scene.frames.len() as u64, "mask");
    // Errors name the output folder, not the hidden staging folder.
    let staged = (|| -> anyhow::Result<_> {
        let report = romo::segment_scene(&scene, &opts, &|stage, done, total| {
            pb.set_message(stage.to_string());
            pb.set_length(total as u64);
            pb.set_position(done as u64);
        })?;
        pb.finish_and_clear();
        let copy = if nerfstudio_copy {
            write_transforms_copy(scene_dir, &out, stage.path())?
        } else {
            None
        };
        Ok((report, copy))
    })();
    // The stage's planes are freed; the next stage (pose, training) need not
    // keep them resident.
    crate::memory::release_freed_memory();
    let (report, copy) = staged.map_err(|e| anyhow::anyhow!(stage.public(&format!("{e:#}"))))?;
    stage.commit()?;
    let mut report = report;
    report.masks_dir = Some(out.join("masks"));
    for w in &report.warnings {
        ctx.info(format!("warning: {w}"));
    }
    if !report.image_fixed.is_empty() {
        ctx.info(format!(
            "content fixed in the image: {}",
            report.image_fixed
        ));
    }
    let moving: f32 = report.frames.iter().map(|f| f.moving_fraction).sum::<f32>()
        / report.frames.len().max(1) as f32;
    ctx.info(format!(
        "masks in {} ({} frames, {:.1}% moving on average, {} dropped from training)",
        report
            .masks_dir
            .as_deref()
            .map(|p| p.display().to_string())
            .unwrap_or_default(),
        report.frames.len(),
        100.0 * moving,
        report.dropped_frames.len()
    ));
    Ok((report, copy))
}

/// When the scene has a transforms.json, write a copy with every frame's
/// nerfstudio `mask_path` set to its mask into the mask output folder `out`
/// (`loader::transforms::write_with_masks_staged`: images outside it are
/// linked into it, the user's transforms.json is never replaced), through
/// the staging folder `stage` of `out`.
fn write_transforms_copy(
    scene: &Path,
    out: &Path,
    stage: &Path,
) -> anyhow::Result<Option<PathBuf>> {
    let src = scene.join("transforms.json");
    if !src.is_file() {
        return Ok(None);
    }
    Ok(Some(loader::transforms::write_with_masks_staged(
        &src,
        scene,
        out,
        &out.join("masks"),
        stage,
    )?))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `--options` takes the JSON itself or a file holding it; either way a
    /// bad one is a one-line error naming `--options` or the file.
    #[test]
    fn options_are_inline_json_or_a_file() {
        let inline = options_arg(Path::new(r#" {"seed": 7, "mlp": {"restarts": 3}}"#)).unwrap();
        assert_eq!((inline.seed, inline.mlp.restarts), (7, 3));
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("o.json");
        std::fs::write(&f, r#"{"seed": 7, "mlp": {"restarts": 3}}"#).unwrap();
        let file = options_arg(&f).unwrap();
        assert_eq!((file.seed, file.mlp.restarts), (7, 3));
        let e = format!("{:#}", options_arg(Path::new("{seed: 7}")).unwrap_err());
        assert!(e.starts_with("--options: not a RomoOptions JSON"), "{e}");
        // An array would fill the struct's fields in order.
        std::fs::write(&f, "[1]").unwrap();
        let e = format!("{:#}", options_arg(&f).unwrap_err());
        assert!(e.contains("o.json: not a RomoOptions JSON"), "{e}");
        std::fs::write(&f, r#"{"seed": "x"}"#).unwrap();
        let e = format!("{:#}", options_arg(&f).unwrap_err());
        assert!(e.contains("o.json: not a RomoOptions JSON"), "{e}");
        let e = format!(
            "{:#}",
            options_arg(&dir.path().join("missing.json")).unwrap_err()
        );
        assert!(e.contains("missing.json"), "{e}");
    }
}
