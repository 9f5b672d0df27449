//! `romosplat onthego --scene DIR --out DIR [--steps N] [--downscale N]`:
//! the NeRF On-the-go protocol (Ren et al., CVPR 2024; the tables of
//! SpotLessSplats, RobustNeRF, WildGaussians) on a scene folder in its
//! layout — `images/`, `split.json` (`clutter` = training views with
//! distractors, `extra` = clean held-out views), poses in `transforms.json`
//! or `sparse/0`, optionally `gt_motion/` (255 moving) and `clean/` (each
//! clutter frame without distractors). The variants train side by side on
//! the same poses and the same steps and are scored on the `extra` views:
//! (a) no masks, (b) RoMo masks, (c) ground-truth masks (with `gt_motion/`),
//! (d) the clean oracle (with `clean/`). Prints one table (PSNR, SSIM,
//! LPIPS, splats, minutes) and writes it to `OUT/onthego.json`,
//! `OUT/onthego.csv` and `OUT/report.md`. The user's folder is only read.

use super::demo::link;
use super::eval_views::{LpipsArgs, mean_std, score_views};
use super::train::BackendKind;
use super::train_common::train_and_eval;
use crate::Ctx;
use anyhow::{Context, Result, bail};
use loader::scene::{Scene, SceneOptions};
use std::path::{Path, PathBuf};

/// `romosplat onthego`
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene folder in the On-the-go layout (images/, split.json, poses).
    #[arg(long)]
    pub scene: PathBuf,
    /// Output folder (variant scenes, masks, trained splats, the tables).
    #[arg(long)]
    pub out: PathBuf,
    /// Training steps per variant (the same for all).
    #[arg(long, default_value_t = 1000)]
    pub steps: usize,
    /// Integer image downscale for training and scoring.
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    #[arg(long, value_enum, default_value_t = BackendKind::Auto)]
    pub backend: BackendKind,
    /// Extra `romosplat train` options for every variant, e.g.
    /// "--max-splats 20000" (one string, split on spaces).
    #[arg(long, default_value = "")]
    pub train_args: String,
    #[command(flatten)]
    pub lpips: LpipsArgs,
}

#[derive(Debug, clap::Parser)]
struct TrainCli {
    #[command(flatten)]
    args: super::train::Args,
}

/// One row of the table.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Row {
    pub variant: String,
    pub psnr: f64,
    pub ssim: f64,
    pub lpips: Option<f64>,
    pub psnr_std: Option<f64>,
    pub splats: usize,
    pub minutes: f64,
    /// For the RoMo row: minutes of the mask stage (not in `minutes`).
    pub mask_minutes: Option<f64>,
}

/// Where a clutter frame's clean version is: `clean/<name>`, else
/// `clean/<stem>.<ext>` with the same extension.
fn clean_file(clean: &Path, name: &str) -> Option<PathBuf> {
    let direct = clean.join(name);
    if direct.is_file() {
        return Some(direct);
    }
    let (stem, ext) = name.rsplit_once('.')?;
    let p = clean.join(format!("{stem}.{}", ext.to_ascii_lowercase()));
    p.is_file().then_some(p)
}

/// A variant's scene folder: every image (clutter ones from the `clean`
/// folder when given), the poses, split.json and `masks` when given — all
/// links.
fn variant_dir(
    scene: &Scene,
    dir: &Path,
    clean: Option<&Path>,
    masks: Option<&Path>,
) -> Result<()> {
    if dir.exists() {
        std::fs::remove_dir_all(dir).with_context(|| format!("clearing {}", dir.display()))?;
    }
    std::fs::create_dir_all(dir.join("images"))
        .with_context(|| format!("creating {}", dir.display()))?;
    let root = &scene.root;
    let clutter = scene.split_indices("clutter");
    for (i, f) in scene.frames.iter().enumerate() {
        let src = match clean {
            Some(c) if clutter.contains(&i) => clean_file(c, &f.name).with_context(|| {
                format!(
                    "{}: no clean version of {}",
                    root.join("clean").display(),
                    f.name
                )
            })?,
            _ => root.join("images").join(&f.name),
        };
        link(&src, &dir.join("images").join(&f.name))?;
    }
    for f in ["split.json", "transforms.json"] {
        if root.join(f).is_file() {
            link(&root.join(f), &dir.join(f))?;
        }
    }
    if let Some(m) = loader::colmap::find_model_dir(root) {
        std::fs::create_dir_all(dir.join("sparse"))?;
        link(&m, &dir.join("sparse/0"))?;
    }
    if let Some(m) = masks {
        link(m, &dir.join("masks"))?;
    }
    Ok(())
}

/// Ground-truth keep-masks (255 − gt_motion) for every frame with a
/// `gt_motion/` file; the others get none.
fn gt_masks(scene: &Scene, dir: &Path) -> Result<usize> {
    std::fs::create_dir_all(dir)?;
    let mut n = 0;
    for f in &scene.frames {
        if let Some(p) = &f.gt_motion_path {
            let keep = loader::masks::keep_from_moving(&loader::masks::read_moving(p)?);
            loader::masks::write_mask(loader::masks::mask_path(dir, &f.name), &keep)?;
            n += 1;
        }
    }
    Ok(n)
}

/// One row's cells: variant, PSNR, SSIM, LPIPS (`missing` when absent),
/// splats, minutes, with `extra` more decimals than the Markdown table's.
fn cells(r: &Row, extra: usize, missing: &str) -> [String; 6] {
    [
        r.variant.clone(),
        format!("{:.*}", 2 + extra, r.psnr),
        format!("{:.*}", 3 + extra, r.ssim),
        r.lpips
            .map_or(missing.into(), |l| format!("{:.*}", 3 + extra, l)),
        r.splats.to_string(),
        format!("{:.*}", 1 + extra, r.minutes),
    ]
}

/// The table as Markdown.
pub fn markdown(rows: &[Row]) -> String {
    let mut s = String::from(
        "| variant | PSNR ↑ | SSIM ↑ | LPIPS ↓ | splats | minutes |\n|---|---|---|---|---|---|\n",
    );
    for r in rows {
        s += &format!("| {} |\n", cells(r, 0, "—").join(" | "));
    }
    s
}

/// The table as CSV.
pub fn csv(rows: &[Row]) -> String {
    let mut s = String::from("variant,psnr,ssim,lpips,splats,minutes\n");
    for r in rows {
        s += &format!("{}\n", cells(r, 2, "").join(","));
    }
    s
}

fn write_text(p: &Path, s: &str) -> Result<()> {
    loader::io::write_atomic(p, |w| {
        w.write_all(s.as_bytes())
            .map_err(|e| loader::LoaderError::io(p, e))
    })?;
    Ok(())
}

pub fn run(args: &Args, ctx: &Ctx) -> Result<serde_json::Value> {
    let t_all = std::time::Instant::now();
    let scene = Scene::load(&args.scene, &SceneOptions { downscale: 1 })
        .with_context(|| format!("loading scene {}", args.scene.display()))?;
    let (clutter, extra) = (scene.split_indices("clutter"), scene.split_indices("extra"));
    if scene.split.is_none() || clutter.is_empty() || extra.is_empty() {
        bail!(
            "{}: the On-the-go protocol needs split.json with `clutter` (training) and `extra` (clean test) views",
            args.scene.join("split.json").display()
        );
    }
    if let Some(f) = scene.frames.iter().find(|f| f.pose.is_none()) {
        bail!(
            "{}: frame {} has no pose (transforms.json or sparse/0 must cover every view)",
            args.scene.display(),
            f.name
        );
    }
    let mut net = args.lpips.load(ctx)?;
    let out = &args.out;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let vdir = |v: &str| out.join("variants").join(v);

    // The variants and their scene folders.
    let mut variants: Vec<(&str, &str, Vec<String>)> = Vec::new();
    variant_dir(&scene, &vdir("none"), None, None)?;
    variants.push(("none", "(a) no masks", vec!["--no-masks".into()]));

    ctx.info(format!(
        "RoMo masks on {} clutter frames ({} held out)",
        clutter.len(),
        extra.len()
    ));
    let t_mask = std::time::Instant::now();
    let romo_opts = romo::RomoOptions {
        out: Some(out.join("romo")),
        ..Default::default()
    };
    let pb = ctx.progress(clutter.len() as u64, "mask");
    let romo_rep = romo::segment_scene(&scene, &romo_opts, &|stage, done, total| {
        pb.set_message(stage.to_string());
        pb.set_length(total as u64);
        pb.set_position(done as u64);
    })?;
    pb.finish_and_clear();
    let mask_minutes = t_mask.elapsed().as_secs_f64() / 60.0;
    variant_dir(&scene, &vdir("romo"), None, Some(&out.join("romo/masks")))?;
    variants.push(("romo", "(b) RoMo masks", vec![]));

    let mut mask_j = None;
    if scene.frames.iter().any(|f| f.gt_motion_path.is_some()) {
        let n = gt_masks(&scene, &out.join("gt/masks"))?;
        ctx.info(format!("ground-truth masks for {n} frames"));
        variant_dir(&scene, &vdir("gt"), None, Some(&out.join("gt/masks")))?;
        variants.push(("gt", "(c) ground-truth masks", vec![]));
        mask_j = Some(romo::scene::evaluate_scene_masks(&scene, &out.join("romo/masks"))?.j_mean);
    }
    let clean_root = scene.root.join("clean");
    if clean_root.is_dir() {
        variant_dir(&scene, &vdir("oracle"), Some(&clean_root), None)?;
        variants.push(("oracle", "(d) clean oracle", vec!["--no-masks".into()]));
    }

    let extra_train: Vec<String> = args
        .train_args
        .split_whitespace()
        .map(String::from)
        .collect();
    let mut rows = Vec::new();
    for (key, label, mut targs) in variants {
        targs.extend(["--downscale".into(), args.downscale.to_string()]);
        targs.extend(extra_train.iter().cloned());
        ctx.info(format!("training {label}: {} steps", args.steps));
        let run_dir = out.join("runs").join(key);
        let t0 = std::time::Instant::now();
        let mut argv: Vec<String> = vec![
            "train".into(),
            "--scene".into(),
            vdir(key).display().to_string(),
            "--out".into(),
            run_dir.display().to_string(),
            "--steps".into(),
            args.steps.to_string(),
        ];
        argv.extend(targs);
        let mut job = <TrainCli as clap::Parser>::try_parse_from(&argv)
            .context("train options (--train-args)")?
            .args
            .job();
        job.backend = args.backend;
        let res = train_and_eval(ctx, &job)?;
        let minutes = t0.elapsed().as_secs_f64() / 60.0;
        // Score every variant against the user's scene (the clean `extra`
        // views), so all rows see the same references.
        let views = super::render::ViewArgs {
            splats: run_dir.join("splats.ply"),
            scene: args.scene.clone(),
            split: "extra".into(),
            poses: None,
            downscale: args.downscale,
            backend: args.backend,
        };
        let s = score_views(&views, false, net.as_mut(), ctx)?;
        let psnr: Vec<f64> = s.report.views.iter().map(|v| v.psnr).collect();
        rows.push(Row {
            variant: label.into(),
            psnr: s.report.mean_psnr,
            ssim: s.report.mean_ssim,
            lpips: s.lpips.as_deref().map(|l| mean_std(l).0),
            psnr_std: mean_std(&psnr).1,
            splats: res.splats,
            minutes,
            mask_minutes: (key == "romo").then_some(mask_minutes),
        });
    }

    let table = markdown(&rows);
    ctx.info(format!(
        "\nOn-the-go protocol: {} ({} clutter / {} clean test views, {} steps, downscale {})\n{table}",
        args.scene.display(),
        clutter.len(),
        extra.len(),
        args.steps,
        args.downscale
    ));
    if net.is_none() {
        ctx.info(splat::lpips_alex::missing_weights_hint(
            splat::lpips_alex::default_weights_path().as_deref(),
        ));
    }
    let json = serde_json::json!({
        "scene": args.scene,
        "clutter_views": clutter.len(),
        "test_views": extra.len(),
        "steps": args.steps,
        "downscale": args.downscale,
        "romo_masks": {"frames": romo_rep.frames.len(), "mean_j": mask_j, "minutes": mask_minutes},
        "lpips_weights": net.as_ref().map(|n| n.path().to_path_buf()),
        "rows": rows,
        "total_minutes": t_all.elapsed().as_secs_f64() / 60.0,
    });
    write_text(
        &out.join("onthego.json"),
        &serde_json::to_string_pretty(&json)?,
    )?;
    write_text(&out.join("onthego.csv"), &csv(&rows))?;
    let md = format!(
        "# On-the-go protocol: {}\n\n{} clutter (training) views, {} clean held-out (`extra`) views; \
         {} steps per variant at downscale {}, same poses; scored on the `extra` views.\n\n{table}\n\
         RoMo mask stage: {:.1} min{}.\n",
        args.scene.display(),
        clutter.len(),
        extra.len(),
        args.steps,
        args.downscale,
        mask_minutes,
        mask_j.map_or(String::new(), |j| format!(", J {j:.3} against gt_motion/"))
    );
    write_text(&out.join("report.md"), &md)?;
    ctx.info(format!("wrote {}", out.join("report.md").display()));
    Ok(json)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    #[test]
    fn table_shapes() {
        let rows = vec![
            Row {
                variant: "(a) no masks".into(),
                psnr: 18.5,
                ssim: 0.51,
                lpips: Some(0.4123),
                psnr_std: None,
                splats: 1000,
                minutes: 2.04,
                mask_minutes: None,
            },
            Row {
                variant: "(d) clean oracle".into(),
                psnr: 20.0,
                ssim: 0.6,
                lpips: None,
                psnr_std: Some(1.0),
                splats: 12,
                minutes: 1.0,
                mask_minutes: None,
            },
        ];
        let md = markdown(&rows);
        assert!(
            md.contains("| (a) no masks | 18.50 | 0.510 | 0.412 | 1000 | 2.0 |"),
            "{md}"
        );
        assert!(
            md.contains("| (d) clean oracle | 20.00 | 0.600 | — | 12 | 1.0 |"),
            "{md}"
        );
        let c = csv(&rows);
        assert_eq!(
            c.lines().nth(2),
            Some("(d) clean oracle,20.0000,0.60000,,12,1.000")
        );
    }

    #[test]
    fn clean_file_same_name_or_stem() {
        let d = tempfile::tempdir().unwrap();
        std::fs::write(d.path().join("a.png"), b"x").unwrap();
        std::fs::write(d.path().join("b.jpg"), b"x").unwrap();
        assert_eq!(clean_file(d.path(), "a.png"), Some(d.path().join("a.png")));
        assert_eq!(clean_file(d.path(), "b.JPG"), Some(d.path().join("b.jpg")));
        assert_eq!(clean_file(d.path(), "c.png"), None);
    }
}
