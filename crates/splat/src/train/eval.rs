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
    let images = views
        .iter()
        .map(|v| Ok(backend.render(splats, &v.camera, opts)?.image))
        .collect::<Result<Vec<_>>>()?;
    Ok((score_images(views, &images), images))
}

/// Score rendered `images` against their `views` (in the same order);
/// `View::mask` restricts the metrics when present, so one render can be
/// scored on all pixels and on its static pixels.
pub fn score_images(views: &[View], images: &[Vec<f32>]) -> EvalReport {
    let mut rep = EvalReport::default();
    for (v, image) in views.iter().zip(images) {
        let (w, h) = (v.camera.width as usize, v.camera.height as usize);
        let m = v.mask.as_deref();
        rep.views.push(ViewScore {
            name: v.name.clone(),
            psnr: psnr(image, &v.image, m).unwrap_or(f64::NAN),
            ssim: ssim(image, &v.image, w, h, m).unwrap_or(f64::NAN),
        });
    }
    let n = rep.views.len().max(1) as f64;
    rep.mean_psnr = rep.views.iter().map(|v| v.psnr).sum::<f64>() / n;
    rep.mean_ssim = rep.views.iter().map(|v| v.ssim).sum::<f64>() / n;
    rep
}
