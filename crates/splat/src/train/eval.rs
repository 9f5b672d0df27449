//! Novel-view evaluation: render held-out views and score them with PSNR and
//! SSIM (scikit-image conventions, [`crate::metrics`]), optionally excluding
//! ground-truth moving pixels (NeRF On-the-go style).

use super::data::View;
use crate::backend::TrainBackend;
use crate::error::Result;
use crate::metrics::{psnr, ssim};
use crate::types::{RenderOptions, Splats};
use serde::{Deserialize, Serialize};

/// Scores of one view.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ViewScore {
    pub name: String,
    pub psnr: f64,
    pub ssim: f64,
}

/// Per-view and mean scores.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct EvalReport {
    pub views: Vec<ViewScore>,
    pub mean_psnr: f64,
    pub mean_ssim: f64,
}

/// Render every view and score it against its image; `View::mask` (keep
/// weights) restricts the metrics when present. Returns the report and the
/// rendered images.
pub fn evaluate(
    backend: &mut dyn TrainBackend,
    splats: &Splats,
    views: &[View],
    opts: &RenderOptions,
) -> Result<(EvalReport, Vec<Vec<f32>>)> {
    let mut rep = EvalReport::default();
    let mut images = Vec::with_capacity(views.len());
    for v in views {
        let out = backend.render(splats, &v.camera, opts)?;
        let (w, h) = (v.camera.width as usize, v.camera.height as usize);
        let m = v.mask.as_deref();
        let p = psnr(&out.image, &v.image, m).unwrap_or(f64::NAN);
        let s = ssim(&out.image, &v.image, w, h, m).unwrap_or(f64::NAN);
        rep.views.push(ViewScore {
            name: v.name.clone(),
            psnr: p,
            ssim: s,
        });
        images.push(out.image);
    }
    let n = rep.views.len().max(1) as f64;
    rep.mean_psnr = rep.views.iter().map(|v| v.psnr).sum::<f64>() / n;
    rep.mean_ssim = rep.views.iter().map(|v| v.ssim).sum::<f64>() / n;
    Ok((rep, images))
}
