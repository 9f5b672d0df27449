//! `OUT/report.html` of `romosplat run`: the settings it ran with, stage
//! times, COLMAP's result, held-out scores, training curves, frames with
//! their masks and held-out renders.

use super::run::{Plan, Results, Source};
use super::train::TrainOutcome;
use crate::report::{self, Chart, Figure, Report, Series, Table};
use anyhow::{Context, Result};

/// `report.html`: settings, stage times, COLMAP, held-out scores, curves,
/// frames with their masks, held-out renders.
pub fn write_report(plan: &Plan, r: &Results) -> Result<()> {
    let source = match &plan.source {
        Source::Video(p) | Source::Scene(p) => p.display().to_string(),
    };
    let mut rep = Report {
        title: format!("romosplat run — {source}"),
        timings: r.timings.clone(),
        ..Default::default()
    };
    let (w, h) = train_resolution(plan).unwrap_or((0, 0));
    rep.tables.push(Table {
        caption: "Settings".into(),
        header: vec![
            "frames".into(),
            "masks".into(),
            "poses".into(),
            "training".into(),
        ],
        rows: vec![vec![
            match (&r.frames, &r.keyframes) {
                (Some(f), Some(k)) => format!("{} of {} kept ({})", k.kept, f.frames, k.dropped),
                (Some(f), None) => f.frames.to_string(),
                _ => "-".into(),
            },
            if plan.no_masks {
                "off (--no-masks)".into()
            } else {
                format!("RoMo, {} rounds", plan.romo.iterations)
            },
            if plan.keep_poses {
                "the scene's own".into()
            } else {
                format!(
                    "COLMAP {:?}, {}",
                    plan.colmap.matcher,
                    plan.colmap.camera_model.name()
                )
            },
            format!("{w}×{h}, {} steps", plan.train.steps),
        ]],
    });
    rep.tables.push(Table {
        caption: format!(
            "Plan for the {:.0}-minute budget (flags given override it)",
            plan.budget.budget_s / 60.0
        ),
        header: vec!["estimate".into()],
        rows: plan.budget.lines().into_iter().map(|l| vec![l]).collect(),
    });
    if let Some(p) = &r.pose {
        rep.tables.push(Table {
            caption: "COLMAP".into(),
            header: vec![
                "registered".into(),
                "total".into(),
                "points".into(),
                "mean reprojection error (px)".into(),
            ],
            rows: vec![vec![
                p.registered.to_string(),
                p.total.to_string(),
                p.model.points.to_string(),
                format!("{:.3}", p.model.mean_reprojection_error),
            ]],
        });
    }
    if let Some(t) = &r.train {
        held_out(&mut rep, plan, t, r.baseline.as_ref())?;
    }
    let images = plan.images();
    let names = loader::scene::list_images(&images)?;
    let step = (names.len() / 8).max(1);
    for n in names.iter().step_by(step).take(8) {
        let img = image::open(images.join(n))
            .with_context(|| format!("{n}: cannot read"))?
            .to_rgb8();
        let over = match image::open(plan.masks().join(format!("{n}.png"))) {
            Ok(m) if !plan.no_masks => report::overlay_mask(&img, &m.to_luma8()),
            _ => img,
        };
        rep.contact_sheet.push(Figure {
            caption: n.clone(),
            png: report::png_rgb8(&report::thumbnail(&over, 320))?,
        });
    }
    rep.write(&plan.report_path())
}

/// Held-out scores of the model (and of the unmasked baseline when it was
/// trained), training curves, and held-out renders side by side.
fn held_out(
    rep: &mut Report,
    plan: &Plan,
    t: &TrainOutcome,
    baseline: Option<&TrainOutcome>,
) -> Result<()> {
    let main_name = if plan.no_masks {
        "no masks"
    } else {
        "RoMo masks"
    };
    let mut outcomes = vec![(main_name, t)];
    if let Some(b) = baseline {
        outcomes.push(("no masks (baseline)", b));
    }
    let lpips = |l: Option<f64>| l.map_or("-".into(), |l| format!("{l:.4}"));
    let statics = t.test_static.as_ref().map_or(0, |s| s.masked_views);
    let mut header = ["training", "PSNR", "SSIM", "LPIPS"]
        .map(String::from)
        .to_vec();
    if statics > 0 {
        header.extend(["static PSNR", "static SSIM", "static LPIPS"].map(String::from));
    }
    header.push("splats".into());
    rep.tables.push(Table {
        caption: format!(
            "Held-out views ({}), {} steps each{}",
            t.test.as_ref().map_or(0, |e| e.views.len()),
            t.options.steps,
            if statics > 0 {
                format!(
                    "; static: the moving pixels of {statics} held-out frames (RoMo's masks) \
                     left out, the same pixels for every model"
                )
            } else {
                String::new()
            }
        ),
        header,
        rows: outcomes
            .iter()
            .map(|(name, o)| {
                let (psnr, ssim) = o
                    .test
                    .as_ref()
                    .map_or((f64::NAN, f64::NAN), |e| (e.mean_psnr, e.mean_ssim));
                let mut row = vec![
                    (*name).into(),
                    format!("{psnr:.2}"),
                    format!("{ssim:.4}"),
                    lpips(o.test_lpips),
                ];
                if statics > 0 {
                    match &o.test_static {
                        Some(s) => row.extend([
                            format!("{:.2}", s.mean_psnr),
                            format!("{:.4}", s.mean_ssim),
                            lpips(s.lpips),
                        ]),
                        None => row.extend(["-".into(), "-".into(), "-".into()]),
                    }
                }
                row.push(o.report.splats.to_string());
                row
            })
            .collect(),
    });
    for (title, y, curve) in [
        ("training loss", "loss", TrainOutcome::loss_curve as Curve),
        ("training PSNR", "dB", TrainOutcome::psnr_curve),
    ] {
        rep.charts.push(Chart {
            title: title.into(),
            x_label: "step".into(),
            y_label: y.into(),
            series: outcomes
                .iter()
                .map(|(name, o)| Series {
                    name: (*name).into(),
                    points: curve(o),
                })
                .collect(),
        });
    }
    for i in 0..t.test_renders.len().min(4) {
        let mut row = Vec::new();
        for (name, o) in &outcomes {
            let Some(p) = o.test_renders.get(i) else {
                continue;
            };
            let img = image::open(p)
                .with_context(|| format!("{}: cannot read", p.display()))?
                .to_rgb8();
            row.push(Figure {
                caption: format!("{name}: {}", p.display()),
                png: report::png_rgb8(&report::thumbnail(&img, 320))?,
            });
        }
        rep.renders.push(row);
    }
    Ok(())
}

type Curve = fn(&TrainOutcome) -> Vec<(f64, f64)>;

/// The training image size: the first frame's, downscaled.
fn train_resolution(plan: &Plan) -> Option<(u32, u32)> {
    let dir = plan.train_scene().join("images");
    let first = loader::scene::list_images(&dir).ok()?.into_iter().next()?;
    let (w, h) = image::image_dimensions(dir.join(first)).ok()?;
    Some((w / plan.downscale, h / plan.downscale))
}
