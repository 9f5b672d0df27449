//! Host for `shaders/splat/ssim.wgsl`: the masked D-SSIM loss term and its
//! gradient on the device (Kerbl et al. 2023 eq. 7, INRIA 11×11 Gaussian
//! window, σ = 1.5, zero padding), the same formulation as the CPU
//! `train::loss::loss_and_grad`, so a training step needs no image readback.
//! Separable filters: 15 maps (x, y, x², y², xy per channel) are blurred
//! horizontally, then vertically together with the per-pixel SSIM terms
//! into weighted derivative maps (9), which are blurred again the same way
//! (the window is self-adjoint), the vertical pass adding dL/d image to the
//! L1 gradient already in `v_image`.

use super::kernel::{Recorder, groups_1d, kernel};
use super::{GpuContext, GpuError};
use crate::metrics::{SSIM_RADIUS, SSIM_SIGMA, gaussian_kernel};
use bytemuck::{Pod, Zeroable};

/// Invocations per workgroup.
pub const WORKGROUP_SIZE: u32 = 256;
/// Outputs per invocation of the horizontal and vertical filters (`SEG` in the shader).
pub const BLUR_SEGMENT: u32 = 32;
/// Planar maps per scratch buffer (5 statistics × 3 channels).
pub const SCRATCH_MAPS: u64 = 15;

/// Uniforms (80 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct SsimUniforms {
    pub width: u32,
    pub height: u32,
    /// Maps (× channels) that `blur_h` processes.
    pub n_maps: u32,
    pub has_mask: u32,
    /// 1 / (3 · Σ mask).
    pub norm: f32,
    /// D-SSIM weight λ.
    pub lambda: f32,
    pub pad: [f32; 2],
    /// The 11 Gaussian taps (offsets −5..5), padded to 12.
    pub taps: [f32; 12],
}

kernel! {
    /// The compiled kernel.
    pub struct Ssim;
    decl DECL = "ssim";
    bindings SsimBindings {
        u: uniform SsimUniforms,
        image: read "array<f32>",
        target_rgb: read "array<f32>",
        mask: read "array<f32>",
        src: read "array<f32>",
        dst: read_write "array<f32>",
        v_image: read_write "array<f32>",
        partials: read_write "array<f32>",
    }
    entry_points {
        products: [WORKGROUP_SIZE],
        blur_h: [WORKGROUP_SIZE],
        blur_v_terms: [WORKGROUP_SIZE],
        blur_v_grad: [WORKGROUP_SIZE],
    }
    constants { WORKGROUP_SIZE, SEG = BLUR_SEGMENT }
}

/// Buffers of one D-SSIM evaluation.
pub struct SsimArgs<'a> {
    pub image: &'a wgpu::Buffer,
    pub target: &'a wgpu::Buffer,
    /// Per-pixel weights; any buffer when `has_mask` is false.
    pub mask: &'a wgpu::Buffer,
    pub has_mask: bool,
    /// dL/d image (`3·w·h`), holding the L1 gradient; the D-SSIM gradient is added.
    pub v_image: &'a wgpu::Buffer,
    /// [`partial_blocks`]`(w, h)` f32 out: Σ g·S per block (Σ over blocks =
    /// mean SSIM).
    pub partials: &'a wgpu::Buffer,
    /// Two scratch buffers of at least `SCRATCH_MAPS · w · h` f32.
    pub scratch: [&'a wgpu::Buffer; 2],
    pub width: u32,
    pub height: u32,
    /// 1 / (3 · kept).
    pub norm: f32,
    pub lambda: f32,
}

/// Invocations of the vertical passes: one per (channel, segment of
/// `BLUR_SEGMENT` rows, column).
fn vertical_items(width: u32, height: u32) -> u32 {
    3 * width * height.div_ceil(BLUR_SEGMENT)
}

/// Partial sums of g·S that [`Ssim::dispatch`] writes for a `width × height`
/// image (one per workgroup of `blur_v_terms`).
pub fn partial_blocks(width: u32, height: u32) -> u32 {
    let g = groups_1d(vertical_items(width, height), WORKGROUP_SIZE);
    g[0] * g[1]
}

/// The 11 Gaussian taps of the SSIM window as f32, padded to 12.
fn window_taps() -> [f32; 12] {
    let k = gaussian_kernel(SSIM_SIGMA, SSIM_RADIUS);
    let mut taps = [0.0f32; 12];
    for (t, v) in taps.iter_mut().zip(&k) {
        *t = *v as f32;
    }
    taps
}

impl Ssim {
    /// Record the five dispatches.
    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        a: &SsimArgs,
    ) -> Result<(), GpuError> {
        let n = a.width * a.height;
        let need = SCRATCH_MAPS * n as u64 * 4;
        if a.scratch.iter().any(|b| b.size() < need) {
            return Err(GpuError::InvalidInput(format!(
                "SSIM scratch buffers smaller than {need} bytes"
            )));
        }
        let base = SsimUniforms {
            width: a.width,
            height: a.height,
            n_maps: 0,
            has_mask: a.has_mask as u32,
            norm: a.norm,
            lambda: a.lambda,
            pad: [0.0; 2],
            taps: window_taps(),
        };
        let [s0, s1] = a.scratch;
        // (entry, maps for the blurs, src, dst)
        let plan: [(&'static str, u32, &wgpu::Buffer, &wgpu::Buffer); 5] = [
            ("products", 0, s1, s0),
            ("blur_h", 15, s0, s1),
            ("blur_v_terms", 0, s1, s0),
            ("blur_h", 9, s0, s1),
            ("blur_v_grad", 0, s1, s0),
        ];
        for (entry, maps, src, dst) in plan {
            let u = ctx.uniform(
                "ssim_u",
                &SsimUniforms {
                    n_maps: maps,
                    ..base
                },
            );
            let items = match entry {
                "blur_h" => maps * a.height * a.width.div_ceil(BLUR_SEGMENT),
                "blur_v_terms" | "blur_v_grad" => vertical_items(a.width, a.height),
                _ => n,
            };
            let b = SsimBindings {
                u: &u,
                image: a.image,
                target_rgb: a.target,
                mask: a.mask,
                src,
                dst,
                v_image: a.v_image,
                partials: a.partials,
            };
            self.record(ctx, rec, entry, &b, groups_1d(items, WORKGROUP_SIZE))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::loss::{Loss, LossArgs, LossUniforms, blocks};

    fn img(w: usize, h: usize, phase: f64) -> Vec<f32> {
        crate::train::loss::test_image(w, h, phase, 0.05)
    }

    /// GPU masked L1 + D-SSIM loss and gradient vs the CPU `loss_and_grad`.
    #[test]
    fn gpu_loss_with_ssim_matches_cpu() {
        let Some(ctx) = crate::gpu::tests::ctx() else {
            return;
        };
        // The second size spans several filter segments in both directions.
        for (w, h) in [(37usize, 29usize), (41, 75)] {
            check_loss_with_ssim(ctx, w, h);
        }
    }

    fn check_loss_with_ssim(ctx: &GpuContext, w: usize, h: usize) {
        let n = w * h;
        let a = img(w, h, 0.0);
        let b = img(w, h, 0.9);
        let mask: Vec<f32> = (0..n)
            .map(|i| if i % 7 == 3 || (i % w) < 4 { 0.0 } else { 1.0 })
            .collect();
        let lambda = 0.2f64;
        for use_mask in [true, false] {
            let m = use_mask.then_some(mask.as_slice());
            let (lv, grad) = crate::train::loss::loss_and_grad(&a, &b, m, (w, h), lambda);
            let kept = lv.kept;
            let image = ctx.upload("image", &a);
            let target = ctx.upload("target", &b);
            let maskb = ctx.upload("mask", &mask);
            let v_image = ctx.storage("v_image", n as u64 * 12);
            let l1_parts = ctx.storage("l1_parts", blocks(n as u32) as u64 * 8);
            let n_parts = partial_blocks(w as u32, h as u32) as usize;
            let parts = ctx.storage("ssim_parts", n_parts as u64 * 4);
            let s0 = ctx.storage("s0", SCRATCH_MAPS * n as u64 * 4);
            let s1 = ctx.storage("s1", SCRATCH_MAPS * n as u64 * 4);
            let loss = Loss::new(ctx);
            let ssim = Ssim::new(ctx);
            let mut rec = Recorder::new(ctx, false);
            loss.dispatch(
                ctx,
                &mut rec,
                &LossArgs {
                    image: &image,
                    target: &target,
                    mask: &maskb,
                    v_image: &v_image,
                    partials: &l1_parts,
                    uniforms: LossUniforms {
                        n_pixels: n as u32,
                        has_mask: use_mask as u32,
                        pad: [0; 2],
                        scale: ((1.0 - lambda) / (3.0 * kept)) as f32,
                        pad2: [0.0; 3],
                    },
                },
            )
            .unwrap();
            ssim.dispatch(
                ctx,
                &mut rec,
                &SsimArgs {
                    image: &image,
                    target: &target,
                    mask: &maskb,
                    has_mask: use_mask,
                    v_image: &v_image,
                    partials: &parts,
                    scratch: [&s0, &s1],
                    width: w as u32,
                    height: h as u32,
                    norm: (1.0 / (3.0 * kept)) as f32,
                    lambda: lambda as f32,
                },
            )
            .unwrap();
            rec.finish().unwrap();
            let g: Vec<f32> = ctx.read(&v_image, n * 3).unwrap();
            let p: Vec<f32> = ctx.read(&parts, n_parts).unwrap();
            let ssim_gpu: f64 = p.iter().map(|&v| v as f64).sum();
            assert!(
                (ssim_gpu - lv.ssim).abs() <= 1e-4,
                "SSIM {ssim_gpu} vs CPU {} (mask {use_mask}, {w}×{h})",
                lv.ssim
            );
            let gmax = grad.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            let worst = g
                .iter()
                .zip(&grad)
                .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()));
            assert!(
                worst <= 1e-4 * gmax,
                "gradient max abs error {worst} (max |grad| {gmax}, mask {use_mask}, {w}×{h})"
            );
        }
    }
}
