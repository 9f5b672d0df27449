//! `romosplat eval views --splats F --scene DIR [--split extra] [--mask-gt] [--lpips MODEL.onnx]`:
//! PSNR and SSIM (11×11 Gaussian window, σ = 1.5, as scikit-image / INRIA)
//! per image and mean, optionally excluding ground-truth moving pixels, and
//! LPIPS (Zhang et al. 2018) through a user-supplied ONNX model
//! (`splat::lpips`, cargo feature `onnx`) — the NeRF On-the-go metrics.

use super::train::make_backend;
use crate::Ctx;
use splat::train::data::{View, load_views};
use splat::train::eval::evaluate;
use splat::types::RenderOptions;
use std::path::{Path, PathBuf};

/// `romosplat eval views`
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub views: super::render::ViewArgs,
    /// Exclude ground-truth moving pixels (gt_motion/) from the metrics.
    #[arg(long)]
    pub mask_gt: bool,
    /// LPIPS model (ONNX: two [1,3,H,W] RGB inputs in [-1,1], distance
    /// output); needs a build with `--features onnx` and ORT_DYLIB_PATH.
    #[arg(long)]
    pub lpips: Option<PathBuf>,
}

/// Render with excluded pixels (keep weight < ½) replaced by the reference,
/// so LPIPS sees no difference there (LPIPS has no per-pixel weights).
#[cfg_attr(not(feature = "onnx"), allow(dead_code))]
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

/// The LPIPS network, loaded before rendering so a missing runtime or a bad
/// model fails fast.
#[cfg(feature = "onnx")]
type Net = splat::lpips::Lpips;
#[cfg(not(feature = "onnx"))]
type Net = std::convert::Infallible;

#[cfg(feature = "onnx")]
fn load_lpips(model: &Path) -> anyhow::Result<Net> {
    Ok(splat::lpips::Lpips::load(model)?)
}

#[cfg(not(feature = "onnx"))]
fn load_lpips(model: &Path) -> anyhow::Result<Net> {
    anyhow::bail!(
        "--lpips {}: this romosplat was built without ONNX Runtime support; rebuild with \
         `cargo build --release -p romosplat --features onnx` and set ORT_DYLIB_PATH to libonnxruntime.so",
        model.display()
    )
}

#[cfg(feature = "onnx")]
fn lpips_scores(net: &mut Net, views: &[View], images: &[Vec<f32>]) -> anyhow::Result<Vec<f64>> {
    let mut out = Vec::with_capacity(views.len());
    for (v, img) in views.iter().zip(images) {
        let r = lpips_render(img, v);
        out.push(net.distance(&r, &v.image, v.camera.width, v.camera.height)?);
    }
    Ok(out)
}

#[cfg(not(feature = "onnx"))]
fn lpips_scores(net: &mut Net, _: &[View], _: &[Vec<f32>]) -> anyhow::Result<Vec<f64>> {
    match *net {}
}

pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    let mut net = args.lpips.as_deref().map(load_lpips).transpose()?;
    let (splats, scene, idx) = args.views.load()?;
    let mut views = load_views(&scene, &idx, false)?;
    let mut masked = 0;
    if args.mask_gt {
        for v in &mut views {
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
    let mut backend = make_backend(args.views.backend, ctx)?;
    let opts = RenderOptions {
        sh_degree: splats.sh_degree,
        ..Default::default()
    };
    let (rep, images) = evaluate(backend.as_mut(), &splats, &views, &opts)?;
    let lpips = match &mut net {
        Some(n) => Some(lpips_scores(n, &views, &images)?),
        None => None,
    };
    for (i, v) in rep.views.iter().enumerate() {
        let l = lpips
            .as_ref()
            .map_or(String::new(), |l| format!("  LPIPS {:.4}", l[i]));
        ctx.info(format!(
            "{:<24} PSNR {:6.2}  SSIM {:.4}{l}",
            v.name, v.psnr, v.ssim
        ));
    }
    let mean_lpips = lpips
        .as_ref()
        .map(|l| l.iter().sum::<f64>() / l.len().max(1) as f64);
    ctx.info(format!(
        "mean ({} views, {masked} with GT motion excluded): PSNR {:.2}  SSIM {:.4}{}",
        rep.views.len(),
        rep.mean_psnr,
        rep.mean_ssim,
        mean_lpips.map_or(String::new(), |l| format!("  LPIPS {l:.4}"))
    ));
    let mut v = serde_json::to_value(&rep)?;
    if let (Some(l), Some(views)) = (&lpips, v["views"].as_array_mut()) {
        for (j, x) in views.iter_mut().zip(l) {
            j["lpips"] = serde_json::json!(x);
        }
    }
    if let Some(m) = mean_lpips {
        v["mean_lpips"] = serde_json::json!(m);
        v["lpips_model"] = serde_json::json!(args.lpips);
    }
    v["split"] = serde_json::json!(args.views.split);
    v["mask_gt_views"] = serde_json::json!(masked);
    Ok(v)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;
    use splat::types::RenderCamera;

    #[test]
    fn lpips_render_copies_reference_on_excluded_pixels() {
        let view = View {
            index: 0,
            name: "a".into(),
            camera: RenderCamera {
                width: 2,
                height: 1,
                fx: 1.0,
                fy: 1.0,
                cx: 1.0,
                cy: 0.5,
                rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                translation: [0.0; 3],
                near: 0.01,
                far: 100.0,
            },
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
    fn lpips_without_feature_says_how_to_build() {
        let e = load_lpips(Path::new("net.onnx")).unwrap_err().to_string();
        assert!(
            e.contains("net.onnx") && e.contains("--features onnx"),
            "{e}"
        );
        assert!(!e.contains('\n'));
    }
}
