//! The CPU training backend: the reference stages + masked loss + Adam, so
//! `--backend cpu` trains without an adapter and tests can compare a GPU
//! step with it. Deterministic: every reduction has a fixed order.

use super::project::ProjectedT;
use super::project::project_t;
use super::project_backward::project_backward_t;
use super::rasterize::rasterize_t;
use super::rasterize_backward::{ProjGradT, RasterRef, rasterize_backward_t};
use crate::backend::{
    MeansNoise, Regularization, StepInput, StepStats, TrainBackend, check_step_input,
};
use crate::error::{Result, check_splats};
use crate::train::adam::{AdamConfig, adam_step};
use crate::train::loss::loss_and_grad;
use crate::types::{
    AdamState, DensifyStats, RenderCamera, RenderOptions, RenderOutput, SplatGrads, Splats,
};

/// CPU training backend.
#[derive(Debug, Clone, Default)]
pub struct CpuBackend {
    params: Splats,
    adam: AdamState,
    stats: DensifyStats,
    /// Adam hyper-parameters.
    pub adam_config: AdamConfig,
    /// MCMC regularisers added to every step's gradients.
    reg: Regularization,
}

impl CpuBackend {
    pub fn new() -> Self {
        Self::default()
    }
}

impl TrainBackend for CpuBackend {
    fn name(&self) -> String {
        "cpu".into()
    }

    fn upload(&mut self, params: &Splats, adam: &AdamState) -> Result<()> {
        check_splats(params)?;
        if adam.m.len() != params.len()
            || adam.v.len() != params.len()
            || adam.m.sh.len() != params.sh.len()
        {
            return Err(crate::SplatError::Invalid(
                "Adam state does not match the splats".into(),
            ));
        }
        self.params = params.clone();
        self.adam = adam.clone();
        self.stats = DensifyStats::zeros(params.len());
        Ok(())
    }

    fn step(&mut self, input: &StepInput<'_>) -> Result<StepStats> {
        check_step_input(input)?;
        let cam = input.camera;
        let opts = &input.render;
        let proj: Vec<ProjectedT<f32>> = project_t(&self.params, cam, opts);
        let r = rasterize_t(&proj, cam, opts);
        let (w, h) = (cam.width as usize, cam.height as usize);
        let (lv, v_image) = loss_and_grad(
            &r.image,
            input.target,
            input.mask,
            (w, h),
            input.loss.ssim_weight as f64,
        );
        let rr = RasterRef {
            final_transmittance: &r.final_transmittance,
            last_contrib: &r.last_contrib,
            tile_ranges: &r.tile_ranges,
            tile_splats: &r.tile_splats,
        };
        let vp: Vec<ProjGradT<f32>> = rasterize_backward_t(&proj, rr, cam, opts, &v_image);
        let g = project_backward_t(&self.params, cam, opts, &vp);
        let mut grads = SplatGrads {
            means: g.means,
            log_scales: g.log_scales,
            rotations: g.rotations,
            opacity_logits: g.opacity_logits,
            sh: g.sh,
            mean2d_abs: Vec::new(),
        };
        let mut visible = 0u32;
        let (hw, hh) = (cam.width as f32 * 0.5, cam.height as f32 * 0.5);
        for (i, p) in proj.iter().enumerate() {
            if p.radius > 0.0 {
                visible += 1;
                let gx = vp[i].mean2d[0] * hw;
                let gy = vp[i].mean2d[1] * hh;
                self.stats.grad_accum[i] += gx.hypot(gy);
                self.stats.count[i] += 1;
                self.stats.max_radius[i] = self.stats.max_radius[i].max(p.radius);
            }
        }
        if self.reg != Regularization::default() {
            super::mcmc::add_regularization_grads(&self.params, &mut grads, &self.reg);
        }
        adam_step(
            &mut self.params,
            &grads,
            &mut self.adam,
            &input.lr,
            &self.adam_config,
        );
        Ok(StepStats {
            loss: lv.loss as f32,
            l1: lv.l1 as f32,
            ssim: lv.ssim as f32,
            psnr: (10.0 * (1.0 / lv.mse.max(1e-20)).log10()) as f32,
            visible,
        })
    }

    fn set_regularization(&mut self, reg: Regularization) -> Result<()> {
        self.reg = reg;
        Ok(())
    }

    fn perturb_means(&mut self, noise: &MeansNoise) -> Result<()> {
        super::mcmc::perturb_means(&mut self.params, noise);
        Ok(())
    }

    fn download(&mut self) -> Result<(Splats, AdamState, DensifyStats)> {
        Ok((self.params.clone(), self.adam.clone(), self.stats.clone()))
    }

    fn render(
        &mut self,
        splats: &Splats,
        cam: &RenderCamera,
        opts: &RenderOptions,
    ) -> Result<RenderOutput> {
        super::render(splats, cam, opts)
    }
}
