//! `romosplat inspect PATH`: summarise a scene folder, a COLMAP model, a
//! transforms.json or a splat file (see `loader::inspect`; `.spz`, `.splat`
//! and `.glb` are read with the splat crate's readers, the ones `export` uses).

use crate::Ctx;
use std::path::PathBuf;

/// `romosplat inspect PATH`
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A scene folder, a COLMAP model folder (or one holding sparse/0), a
    /// transforms.json or splats (.ply, .spz, .splat, .glb).
    pub path: PathBuf,
}

/// Run `romosplat inspect`.
pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    let r = match splat::export::ExportFormat::from_path(&args.path) {
        Some(f) if f != splat::export::ExportFormat::Ply && args.path.is_file() => {
            let s = splat::io::read_splats(&args.path)?;
            loader::inspect::InspectReport {
                kind: f.name().into(),
                path: args.path.display().to_string(),
                splats: Some(s.len()),
                sh_degree: Some(s.sh_degree),
                ..Default::default()
            }
        }
        _ => loader::inspect::inspect(&args.path)?,
    };
    ctx.info(format!("{}: {}", r.kind, r.path));
    if let Some(n) = r.images {
        ctx.info(format!("  images: {n}"));
    }
    if let Some(n) = r.registered_images {
        ctx.info(format!("  registered images: {n}"));
    }
    if let Some(src) = &r.pose_source {
        ctx.info(format!("  poses from: {src:?}"));
    }
    if let Some(n) = r.points3d {
        let tl = r
            .mean_track_length
            .map(|t| format!(" (mean track length {t:.2})"))
            .unwrap_or_default();
        ctx.info(format!("  3D points: {n}{tl}"));
    }
    for s in &r.image_sizes {
        ctx.info(format!(
            "  image size {}x{}: {} images",
            s.width, s.height, s.count
        ));
    }
    for c in &r.cameras {
        let p: Vec<String> = c.params.iter().map(|v| format!("{v:.6}")).collect();
        ctx.info(format!(
            "  camera {} {} {}x{} [{}] used by {} images",
            c.id,
            c.model,
            c.width,
            c.height,
            p.join(", "),
            c.images
        ));
    }
    if let Some(n) = r.masks {
        ctx.info(format!("  masks: {n}"));
    }
    if let Some(n) = r.gt_motion {
        ctx.info(format!("  gt_motion: {n}"));
    }
    if let Some(s) = &r.split {
        let parts: Vec<String> = s.iter().map(|(k, v)| format!("{k} {v}")).collect();
        ctx.info(format!("  split: {}", parts.join(", ")));
    }
    if let Some(n) = r.splats {
        ctx.info(format!(
            "  splats: {n}, SH degree {}",
            r.sh_degree.unwrap_or(0)
        ));
    }
    Ok(serde_json::to_value(&r)?)
}
