//! `romosplat eval views --splats F --scene DIR [--split extra] [--mask-gt]
//! [--lpips-weights FILE | --lpips-onnx MODEL.onnx] [--output-path eval.json]`:
//! PSNR and SSIM (11×11 Gaussian window, σ = 1.5, as scikit-image / INRIA)
//! and LPIPS (Zhang et al. 2018; the built-in AlexNet v0.1,
//! `splat::lpips_alex`, when its weights are found, or any ONNX LPIPS model
//! with cargo feature `onnx`) per view and mean, optionally excluding
//! ground-truth moving pixels — the NeRF On-the-go metrics. The JSON has the
//! shape of nerfstudio's `ns-eval` output (`results.psnr`, `psnr_std`, …;
//! std is the sample standard deviation, as `torch.std_mean`), with the
//! per-view scores beside it; the CSV has one row per view and a mean row.

use super::train::make_backend;
use crate::Ctx;
use splat::lpips_alex::{LpipsAlex, WeightsLookup, find_weights, missing_weights_hint};
use splat::train::data::{View, load_views};
use splat::train::eval::{EvalReport, evaluate};
use splat::types::RenderOptions;
use std::path::{Path, PathBuf};

/// LPIPS source flags, shared by the commands that score views.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct LpipsArgs {
    /// LPIPS-Alex weights (safetensors from scripts/get_lpips_weights.py);
    /// default $ROMOSPLAT_LPIPS_WEIGHTS, then
    /// $XDG_DATA_HOME/romosplat/lpips-alex-v0.1.safetensors.
    #[arg(long)]
    pub lpips_weights: Option<PathBuf>,
    /// An ONNX LPIPS model instead (two [1,3,H,W] RGB inputs in [-1,1],
    /// distance output); needs a build with `--features onnx` and
    /// ORT_DYLIB_PATH.
    #[arg(long, alias = "lpips", conflicts_with = "lpips_weights")]
    pub lpips_onnx: Option<PathBuf>,
}

/// A loaded LPIPS metric.
pub enum Lpips {
    /// The built-in LPIPS-Alex.
    Alex(LpipsAlex, PathBuf),
    /// An ONNX model.
    #[cfg(feature = "onnx")]
    Onnx(splat::lpips::Lpips, PathBuf),
}

impl Lpips {
    /// The weights or model file.
    pub fn path(&self) -> &Path {
        match self {
            Lpips::Alex(_, p) => p,
            #[cfg(feature = "onnx")]
            Lpips::Onnx(_, p) => p,
        }
    }

    /// Distance between two RGB images in [0, 1] (`w × h × 3`).
    pub fn distance(&mut self, a: &[f32], b: &[f32], w: u32, h: u32) -> anyhow::Result<f64> {
        Ok(match self {
            Lpips::Alex(n, _) => n.distance(a, b, w, h)?,
            #[cfg(feature = "onnx")]
            Lpips::Onnx(n, _) => n.distance(a, b, w, h)?,
        })
    }

    /// LPIPS of each rendered view against its reference; pixels the view's
    /// mask excludes are copied from the reference first (LPIPS has no
    /// per-pixel weights).
    pub fn score_views(&mut self, views: &[View], images: &[Vec<f32>]) -> anyhow::Result<Vec<f64>> {
        views
            .iter()
            .zip(images)
            .map(|(v, img)| {
                let r = lpips_render(img, v);
                self.distance(&r, &v.image, v.camera.width, v.camera.height)
            })
            .collect()
    }
}

impl std::fmt::Debug for Lpips {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Lpips({})", self.path().display())
    }
}

#[cfg(feature = "onnx")]
fn load_onnx(model: &Path) -> anyhow::Result<Lpips> {
    Ok(Lpips::Onnx(
        splat::lpips::Lpips::load(model)?,
        model.to_path_buf(),
    ))
}

#[cfg(not(feature = "onnx"))]
fn load_onnx(model: &Path) -> anyhow::Result<Lpips> {
    anyhow::bail!(
        "--lpips-onnx {}: this romosplat was built without ONNX Runtime support; rebuild with \
         `cargo build --release -p romosplat --features onnx` and set ORT_DYLIB_PATH to libonnxruntime.so \
         (the built-in LPIPS-Alex needs neither: --lpips-weights)",
        model.display()
    )
}

/// The built-in LPIPS-Alex when its weights are found without being asked
/// for ($ROMOSPLAT_LPIPS_WEIGHTS, then the default location), for the
/// commands that add LPIPS to their tables when they can. A file named by
/// the variable that does not exist is an error; nothing found is `None`.
pub fn builtin_lpips() -> anyhow::Result<Option<Lpips>> {
    match find_weights(None) {
        WeightsLookup::Found(p) => Ok(Some(Lpips::Alex(LpipsAlex::load(&p)?, p))),
        WeightsLookup::MissingNamed(p) => anyhow::bail!(
            "{}: LPIPS weights not found; write them with `{}`",
            p.display(),
            splat::lpips_alex::GET_WEIGHTS
        ),
        WeightsLookup::Absent(_) => Ok(None),
    }
}

impl LpipsArgs {
    /// Load the metric. A file named by a flag or by $ROMOSPLAT_LPIPS_WEIGHTS
    /// must exist (error); with nothing named and nothing at the default
    /// location, one line says how to get the weights and `None` is
    /// returned, so the other metrics still run.
    pub fn load(&self, ctx: &Ctx) -> anyhow::Result<Option<Lpips>> {
        if let Some(m) = &self.lpips_onnx {
            return load_onnx(m).map(Some);
        }
        match find_weights(self.lpips_weights.as_deref()) {
            WeightsLookup::Found(p) => Ok(Some(Lpips::Alex(LpipsAlex::load(&p)?, p))),
            WeightsLookup::MissingNamed(p) => anyhow::bail!(
                "{}: LPIPS weights not found; write them with `{}`",
                p.display(),
                splat::lpips_alex::GET_WEIGHTS
            ),
            WeightsLookup::Absent(default) => {
                ctx.info(missing_weights_hint(default.as_deref()));
                Ok(None)
            }
        }
    }
}

/// `romosplat eval views`
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub views: super::render::ViewArgs,
    /// Exclude ground-truth moving pixels (gt_motion/) from the metrics.
    #[arg(long)]
    pub mask_gt: bool,
    #[command(flatten)]
    pub lpips: LpipsArgs,
    /// Write the scores here as JSON (nerfstudio `ns-eval` shape) and beside
    /// it, same name with `.csv`, as CSV.
    #[arg(long)]
    pub output_path: Option<PathBuf>,
}

/// Render with excluded pixels (keep weight < ½) replaced by the reference,
/// so LPIPS sees no difference there (LPIPS has no per-pixel weights).
pub fn lpips_render(render: &[f32], view: &View) -> Vec<f32> {
    match &view.mask {
        None => render.to_vec(),
        Some(m) => render
            .chunks_exact(3)
            .zip(view.image.chunks_exact(3))
            .zip(m)
            .flat_map(|((r, g), &k)| {
                if k < 0.5 {
                    [g[0], g[1], g[2]]
                } else {
                    [r[0], r[1], r[2]]
                }
            })
            .collect(),
    }
}

/// Mean and sample standard deviation (n − 1, as `torch.std_mean`; `None`
/// for fewer than two values).
pub fn mean_std(v: &[f64]) -> (f64, Option<f64>) {
    let n = v.len();
    let mean = v.iter().sum::<f64>() / n.max(1) as f64;
    let std = (n >= 2)
        .then(|| (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt());
    (mean, std)
}

/// The scores in nerfstudio's `ns-eval` shape plus per-view rows.
pub fn nerfstudio_json(
    experiment: &str,
    checkpoint: &Path,
    rep: &EvalReport,
    lpips: Option<&[f64]>,
) -> serde_json::Value {
    let col = |f: fn(&splat::train::eval::ViewScore) -> f64| -> Vec<f64> {
        rep.views.iter().map(f).collect()
    };
    let mut results = serde_json::Map::new();
    let mut put = |key: &str, v: &[f64]| {
        let (m, s) = mean_std(v);
        results.insert(key.into(), serde_json::json!(m));
        results.insert(format!("{key}_std"), serde_json::json!(s));
    };
    put("psnr", &col(|v| v.psnr));
    put("ssim", &col(|v| v.ssim));
    if let Some(l) = lpips {
        put("lpips", l);
    }
    results.insert("num_views".into(), serde_json::json!(rep.views.len()));
    let views: Vec<_> = rep
        .views
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let mut j = serde_json::json!({"name": v.name, "psnr": v.psnr, "ssim": v.ssim});
            if let Some(l) = lpips {
                j["lpips"] = serde_json::json!(l[i]);
            }
            j
        })
        .collect();
    serde_json::json!({
        "experiment_name": experiment,
        "method_name": "romosplat",
        "checkpoint": checkpoint,
        "results": results,
        "views": views,
    })
}

/// CSV: `view,psnr,ssim[,lpips]`, one row per view, then `mean` and `std`.
pub fn eval_csv(rep: &EvalReport, lpips: Option<&[f64]>) -> String {
    let mut s = String::from(if lpips.is_some() {
        "view,psnr,ssim,lpips\n"
    } else {
        "view,psnr,ssim\n"
    });
    let quote = |n: &str| {
        if n.contains([',', '"', '\n']) {
            format!("\"{}\"", n.replace('"', "\"\""))
        } else {
            n.to_string()
        }
    };
    for (i, v) in rep.views.iter().enumerate() {
        s += &format!("{},{:.6},{:.6}", quote(&v.name), v.psnr, v.ssim);
        if let Some(l) = lpips {
            s += &format!(",{:.6}", l[i]);
        }
        s.push('\n');
    }
    let psnr: Vec<f64> = rep.views.iter().map(|v| v.psnr).collect();
    let ssim: Vec<f64> = rep.views.iter().map(|v| v.ssim).collect();
    let mut cols = vec![mean_std(&psnr), mean_std(&ssim)];
    if let Some(l) = lpips {
        cols.push(mean_std(l));
    }
    let fmt = |x: Option<f64>| x.map_or(String::new(), |x| format!("{x:.6}"));
    s += "mean";
    for (m, _) in &cols {
        s += &format!(",{}", fmt(Some(*m)));
    }
    s += "\nstd";
    for (_, sd) in &cols {
        s += &format!(",{}", fmt(*sd));
    }
    s.push('\n');
    s
}

/// Write `path` (JSON) and `path` with extension `.csv` (CSV), atomically.
pub fn write_outputs(path: &Path, json: &serde_json::Value, csv: &str) -> anyhow::Result<PathBuf> {
    let text = serde_json::to_string_pretty(json)?;
    let write = |p: &Path, s: &str| {
        loader::io::write_atomic(p, |w| {
            w.write_all(s.as_bytes())
                .map_err(|e| loader::LoaderError::io(p, e))
        })
    };
    write(path, &text)?;
    let csv_path = path.with_extension("csv");
    write(&csv_path, csv)?;
    Ok(csv_path)
}

/// PSNR / SSIM (and LPIPS when a metric is given) of one split.
#[derive(Debug)]
pub struct Scored {
    pub report: EvalReport,
    pub lpips: Option<Vec<f64>>,
    /// Views whose ground-truth moving pixels were excluded.
    pub mask_gt_views: usize,
}

/// Render `views`' split from its splats and score it, optionally leaving
/// ground-truth moving pixels (gt_motion/) out.
pub fn score_views(
    views: &super::render::ViewArgs,
    mask_gt: bool,
    lpips: Option<&mut Lpips>,
    ctx: &Ctx,
) -> anyhow::Result<Scored> {
    let (splats, scene, idx) = views.load()?;
    let mut vs = load_views(&scene, &idx, false)?;
    let mut masked = 0;
    if mask_gt {
        for v in &mut vs {
            if let Some(m) = scene.load_gt_motion(v.index)? {
                v.mask = Some(
                    m.into_raw()
                        .into_iter()
                        .map(|x| if x >= 128 { 0.0 } else { 1.0 })
                        .collect(),
                );
                masked += 1;
            }
        }
    }
    let mut backend = make_backend(views.backend, ctx)?;
    let opts = RenderOptions {
        sh_degree: splats.sh_degree,
        ..Default::default()
    };
    let (report, images) = evaluate(backend.as_mut(), &splats, &vs, &opts)?;
    let lpips = match lpips {
        Some(n) => Some(n.score_views(&vs, &images)?),
        None => None,
    };
    Ok(Scored {
        report,
        lpips,
        mask_gt_views: masked,
    })
}

pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    if let Some(p) = &args.output_path
        && p.extension().is_some_and(|e| e == "csv")
    {
        anyhow::bail!(
            "--output-path {}: give the JSON path; the CSV is written beside it",
            p.display()
        );
    }
    let mut net = args.lpips.load(ctx)?;
    let scored = score_views(&args.views, args.mask_gt, net.as_mut(), ctx)?;
    let (rep, lpips, masked) = (scored.report, scored.lpips, scored.mask_gt_views);
    let scene_root = &args.views.scene;
    for (i, v) in rep.views.iter().enumerate() {
        let l = lpips
            .as_ref()
            .map_or(String::new(), |l| format!("  LPIPS {:.4}", l[i]));
        ctx.info(format!(
            "{:<24} PSNR {:6.2}  SSIM {:.4}{l}",
            v.name, v.psnr, v.ssim
        ));
    }
    let experiment = scene_root
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut v = nerfstudio_json(&experiment, &args.views.splats, &rep, lpips.as_deref());
    let r = &v["results"];
    ctx.info(format!(
        "mean ({} views, {masked} with GT motion excluded): PSNR {:.2}  SSIM {:.4}{}",
        rep.views.len(),
        rep.mean_psnr,
        rep.mean_ssim,
        r["lpips"]
            .as_f64()
            .map_or(String::new(), |l| format!("  LPIPS {l:.4}"))
    ));
    v["split"] = serde_json::json!(args.views.split);
    v["mask_gt_views"] = serde_json::json!(masked);
    v["lpips_weights"] = serde_json::json!(net.as_ref().map(Lpips::path));
    if let Some(p) = &args.output_path {
        let csv = write_outputs(p, &v, &eval_csv(&rep, lpips.as_deref()))?;
        ctx.info(format!("wrote {} and {}", p.display(), csv.display()));
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use splat::train::eval::ViewScore;
    use splat::types::RenderCamera;

    #[test]
    fn lpips_render_copies_reference_on_excluded_pixels() {
        let view = View {
            index: 0,
            name: "a".into(),
            camera: RenderCamera::at_origin(2, 1, 1.0),
            image: vec![0.1, 0.2, 0.3, 0.4, 0.5, 0.6],
            mask: Some(vec![1.0, 0.0]),
        };
        let r = [0.9, 0.8, 0.7, 0.6, 0.5, 0.4];
        assert_eq!(lpips_render(&r, &view), vec![0.9, 0.8, 0.7, 0.4, 0.5, 0.6]);
        let unmasked = View { mask: None, ..view };
        assert_eq!(lpips_render(&r, &unmasked), r.to_vec());
    }

    #[cfg(not(feature = "onnx"))]
    #[test]
    fn lpips_onnx_without_feature_says_how_to_build() {
        let e = load_onnx(Path::new("net.onnx")).unwrap_err().to_string();
        assert!(
            e.contains("net.onnx") && e.contains("--features onnx"),
            "{e}"
        );
        assert!(!e.contains('\n'));
    }

    fn report() -> EvalReport {
        EvalReport {
            views: vec![
                ViewScore {
                    name: "a,1.png".into(),
                    psnr: 20.0,
                    ssim: 0.5,
                },
                ViewScore {
                    name: "b.png".into(),
                    psnr: 24.0,
                    ssim: 0.7,
                },
                ViewScore {
                    name: "c.png".into(),
                    psnr: 25.0,
                    ssim: 0.9,
                },
            ],
            mean_psnr: 23.0,
            mean_ssim: 0.7,
        }
    }

    #[test]
    fn nerfstudio_shape_with_sample_std() {
        let l = [0.1, 0.2, 0.3];
        let j = nerfstudio_json("fox", Path::new("s.ply"), &report(), Some(&l));
        let r = &j["results"];
        assert_eq!(r["psnr"].as_f64().unwrap(), 23.0);
        // sample std of 20, 24, 25: sqrt((9 + 1 + 4) / 2)
        assert!((r["psnr_std"].as_f64().unwrap() - 7f64.sqrt()).abs() < 1e-12);
        assert!((r["ssim"].as_f64().unwrap() - 0.7).abs() < 1e-12);
        assert!((r["ssim_std"].as_f64().unwrap() - 0.2).abs() < 1e-12);
        assert!((r["lpips"].as_f64().unwrap() - 0.2).abs() < 1e-12);
        assert!((r["lpips_std"].as_f64().unwrap() - 0.1).abs() < 1e-12);
        assert_eq!(j["experiment_name"], "fox");
        assert_eq!(j["checkpoint"], "s.ply");
        assert_eq!(j["views"][2]["lpips"].as_f64().unwrap(), 0.3);
        let no = nerfstudio_json("fox", Path::new("s.ply"), &report(), None);
        assert!(no["results"].get("lpips").is_none());
        assert!(no["views"][0].get("lpips").is_none());
    }

    #[test]
    fn csv_rows_mean_and_std() {
        let csv = eval_csv(&report(), Some(&[0.1, 0.2, 0.3]));
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines[0], "view,psnr,ssim,lpips");
        assert_eq!(lines[1], "\"a,1.png\",20.000000,0.500000,0.100000");
        assert_eq!(lines[4], "mean,23.000000,0.700000,0.200000");
        assert!(lines[5].starts_with("std,2.645751,0.200000,0.100000"));
        assert_eq!(lines.len(), 6);
        let one = EvalReport {
            views: report().views[..1].to_vec(),
            ..report()
        };
        assert_eq!(eval_csv(&one, None).lines().last(), Some("std,,"));
    }

    #[test]
    fn outputs_are_written_side_by_side() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("sub/eval.json");
        let j = nerfstudio_json("x", Path::new("s.ply"), &report(), None);
        let csv = write_outputs(&p, &j, &eval_csv(&report(), None)).unwrap();
        assert_eq!(csv, d.path().join("sub/eval.csv"));
        let back: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
        assert_eq!(back, j);
        assert!(
            std::fs::read_to_string(csv)
                .unwrap()
                .starts_with("view,psnr,ssim\n")
        );
    }
}
