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
use super::eval_views::{Lpips, LpipsArgs, mean_std, score_views};
use super::train::{BackendKind, TrainFlags, TrainJob};
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
    pub steps: u32,
    /// Integer image downscale for training and scoring.
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    #[arg(long, value_enum, default_value_t = BackendKind::Auto)]
    pub backend: BackendKind,
    /// Training flags of `romosplat train` for every variant, as one string
    /// split on spaces, e.g. "--max-splats 20000 --strategy mcmc": the
    /// algorithm's options and `--sparse-adam` (steps, downscale, backend
    /// and masks are onthego's). Checked when the command line is parsed.
    #[arg(long, default_value = "", allow_hyphen_values = true, value_parser = parse_train_args)]
    pub train_args: TrainFlags,
    #[command(flatten)]
    pub lpips: LpipsArgs,
}

/// `--train-args`: the string's words parsed once into typed training flags.
fn parse_train_args(s: &str) -> Result<TrainFlags, String> {
    #[derive(clap::Parser)]
    #[command(no_binary_name = true)]
    struct Words {
        #[command(flatten)]
        flags: TrainFlags,
    }
    <Words as clap::Parser>::try_parse_from(s.split_whitespace())
        .map(|w| w.flags)
        .map_err(|e| {
            let msg = e.to_string();
            let first = msg.lines().next().unwrap_or_default();
            first.trim_start_matches("error: ").to_string()
        })
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

/// One variant: its folder name, its table label, whether it trains with masks.
struct Variant {
    key: &'static str,
    label: &'static str,
    use_masks: bool,
}

/// What the RoMo mask stage did.
struct MaskStage {
    frames: usize,
    minutes: f64,
    /// Mean J against `gt_motion/`, when the scene has it.
    j: Option<f64>,
}

pub fn run(args: &Args, ctx: &Ctx) -> Result<serde_json::Value> {
    let t_all = std::time::Instant::now();
    let (scene, clutter, extra) = load_scene(&args.scene)?;
    let mut net = args.lpips.load(ctx)?;
    let out = &args.out;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let (variants, masks) = prepare_variants(&scene, out, ctx)?;
    let mut rows = Vec::new();
    for v in &variants {
        let mut row = train_variant(args, v, net.as_mut(), ctx)?;
        row.mask_minutes = (v.key == "romo").then_some(masks.minutes);
        rows.push(row);
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
        "romo_masks": {"frames": masks.frames, "mean_j": masks.j, "minutes": masks.minutes},
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
        masks.minutes,
        masks
            .j
            .map_or(String::new(), |j| format!(", J {j:.3} against gt_motion/"))
    );
    write_text(&out.join("report.md"), &md)?;
    ctx.info(format!("wrote {}", out.join("report.md").display()));
    Ok(json)
}

/// The user's scene with its clutter and extra (clean held-out) views; every
/// frame must have a pose.
fn load_scene(root: &Path) -> Result<(Scene, Vec<usize>, Vec<usize>)> {
    let scene = Scene::load(root, &SceneOptions { downscale: 1 })
        .with_context(|| format!("loading scene {}", root.display()))?;
    let (clutter, extra) = (scene.split_indices("clutter"), scene.split_indices("extra"));
    if scene.split.is_none() || clutter.is_empty() || extra.is_empty() {
        bail!(
            "{}: the On-the-go protocol needs split.json with `clutter` (training) and `extra` (clean test) views",
            root.join("split.json").display()
        );
    }
    if let Some(f) = scene.frames.iter().find(|f| f.pose.is_none()) {
        bail!(
            "{}: frame {} has no pose (transforms.json or sparse/0 must cover every view)",
            root.display(),
            f.name
        );
    }
    Ok((scene, clutter, extra))
}

/// The variants' scene folders under `out/variants`: (a) always, (b) after
/// RoMo's masks, (c) when the scene has `gt_motion/`, (d) when it has `clean/`.
fn prepare_variants(scene: &Scene, out: &Path, ctx: &Ctx) -> Result<(Vec<Variant>, MaskStage)> {
    let vdir = |v: &str| out.join("variants").join(v);
    let mut variants = Vec::new();
    let mut add = |key, label, use_masks| {
        variants.push(Variant {
            key,
            label,
            use_masks,
        })
    };
    variant_dir(scene, &vdir("none"), None, None)?;
    add("none", "(a) no masks", false);

    let clutter = scene.split_indices("clutter");
    ctx.info(format!(
        "RoMo masks on {} clutter frames ({} held out)",
        clutter.len(),
        scene.split_indices("extra").len()
    ));
    let t_mask = std::time::Instant::now();
    let romo_opts = romo::RomoOptions {
        out: Some(out.join("romo")),
        ..Default::default()
    };
    let pb = ctx.progress(clutter.len() as u64, "mask");
    let romo_rep = romo::segment_scene(scene, &romo_opts, &|stage, done, total| {
        pb.set_message(stage.to_string());
        pb.set_length(total as u64);
        pb.set_position(done as u64);
    })?;
    pb.finish_and_clear();
    crate::memory::release_freed_memory();
    let mut masks = MaskStage {
        frames: romo_rep.frames.len(),
        minutes: t_mask.elapsed().as_secs_f64() / 60.0,
        j: None,
    };
    variant_dir(scene, &vdir("romo"), None, Some(&out.join("romo/masks")))?;
    add("romo", "(b) RoMo masks", true);

    if scene.frames.iter().any(|f| f.gt_motion_path.is_some()) {
        let n = gt_masks(scene, &out.join("gt/masks"))?;
        ctx.info(format!("ground-truth masks for {n} frames"));
        variant_dir(scene, &vdir("gt"), None, Some(&out.join("gt/masks")))?;
        add("gt", "(c) ground-truth masks", true);
        masks.j = Some(romo::scene::evaluate_scene_masks(scene, &out.join("romo/masks"))?.j_mean);
    }
    let clean_root = scene.root.join("clean");
    if clean_root.is_dir() {
        variant_dir(scene, &vdir("oracle"), Some(&clean_root), None)?;
        add("oracle", "(d) clean oracle", false);
    }
    Ok((variants, masks))
}

/// Train one variant into `out/runs/KEY` and score it on the user's scene
/// (the clean `extra` views), so all rows see the same references.
fn train_variant(args: &Args, v: &Variant, net: Option<&mut Lpips>, ctx: &Ctx) -> Result<Row> {
    ctx.info(format!("training {}: {} steps", v.label, args.steps));
    let run_dir = args.out.join("runs").join(v.key);
    let t0 = std::time::Instant::now();
    let job = TrainJob {
        scene: args.out.join("variants").join(v.key),
        poses: None,
        downscale: args.downscale,
        holdout_every: 0,
        backend: args.backend,
        sparse_adam: args.train_args.sparse_adam,
        resume: None,
        out: run_dir.clone(),
        test_renders: None,
        opts: args.train_args.train_options(args.steps, v.use_masks),
    };
    let res = train_and_eval(ctx, &job)?;
    let minutes = t0.elapsed().as_secs_f64() / 60.0;
    let views = super::render::ViewArgs {
        splats: run_dir.join("splats.ply"),
        scene: args.scene.clone(),
        split: "extra".into(),
        poses: None,
        downscale: args.downscale,
        backend: args.backend,
    };
    let s = score_views(&views, false, net, ctx)?;
    let psnr: Vec<f64> = s.report.views.iter().map(|v| v.psnr).collect();
    Ok(Row {
        variant: v.label.into(),
        psnr: s.report.mean_psnr,
        ssim: s.report.mean_ssim,
        lpips: s.lpips.as_deref().map(|l| mean_std(l).0),
        psnr_std: mean_std(&psnr).1,
        splats: res.splats,
        minutes,
        mask_minutes: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn train_args_parse_once_into_typed_flags() {
        let f = parse_train_args("--max-splats 20000  --strategy mcmc --sparse-adam").unwrap();
        let o = f.train_options(200, true);
        assert_eq!(o.strategy.max_splats, 20_000);
        assert_eq!(o.mcmc.cap_max, 20_000);
        assert_eq!(o.strategy_kind, splat::strategy::StrategyKind::Mcmc);
        assert_eq!((o.steps, o.use_masks, f.sparse_adam), (200, true, true));
        let none = parse_train_args("").unwrap();
        assert_eq!(
            none.train_options(1000, false),
            splat::train::TrainOptions {
                steps: 1000,
                use_masks: false,
                ..Default::default()
            }
        );
        // Flags that are onthego's own, and unknown ones, are refused by name.
        for (bad, named) in [("--steps 5", "--steps"), ("--max-splats x", "--max-splats")] {
            let e = parse_train_args(bad).unwrap_err();
            assert!(e.contains(named) && !e.contains('\n'), "{e}");
        }
    }

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
