//! Built-in synthetic scenes: what the demo and the tests run on.
//!
//! A scene spec (`scenes/*.toml`, [`SceneSpec`]) describes a textured static
//! street with real parallax, a handheld camera path and pedestrians walking
//! across the view. [`generate`] renders it with the software rasteriser in
//! [`raster`] and writes a scene folder in the layout of `docs/design.md`:
//! `images/` (training frames with pedestrians, then clean held-out
//! `test_NNN.png` views), `clean/` (each training frame without pedestrians),
//! `gt_motion/` (255 where pedestrians cover ≥ 50 % of a pixel's samples),
//! `sparse/0` (ground-truth poses and points, text and binary),
//! `transforms.json` and `split.json`. Deterministic from the spec's seed.

pub mod path;
pub mod raster;
pub mod spec;
pub mod texture;
pub mod world;

mod output;
#[cfg(test)]
mod tests;

pub use spec::{CameraPathSpec, PedestrianSpec, SceneSpec, WorldSpec, load_spec};

use crate::camera::{Intrinsics, Pose};
use crate::error::Result;
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use raster::{NONE, Passes, Resolved, Sample, Setup, View};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::Path;
use texture::mix64;
use world::World;

/// Summary of a generated scene.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GenerateReport {
    /// Scene name from the spec.
    pub name: String,
    /// Output folder.
    pub out_dir: String,
    /// Training frames written.
    pub frames: u32,
    /// Clean held-out test views written.
    pub test_views: u32,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Points in `sparse/0/points3D`.
    pub points3d: usize,
    /// Total 2D observations of those points over all images.
    pub observations: usize,
    /// Fraction of pixels marked moving in `gt_motion`, over training frames.
    pub coverage: CoverageStats,
    /// Wall-clock generation time, seconds.
    pub seconds: f64,
}

/// Per-frame distractor coverage statistics (fractions of the image).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CoverageStats {
    pub mean: f64,
    pub min: f64,
    pub max: f64,
    /// Fraction of training frames whose coverage lies in [0.10, 0.30].
    pub frames_in_10_30: f64,
}

/// Pinhole intrinsics of a spec: square pixels, centred principal point.
pub fn intrinsics(spec: &SceneSpec) -> Intrinsics {
    let (w, h) = (spec.width as f64, spec.height as f64);
    let f = 0.5 * w / (0.5 * spec.fov_x_deg.to_radians()).tan();
    Intrinsics {
        width: spec.width,
        height: spec.height,
        fx: f,
        fy: f,
        cx: 0.5 * w,
        cy: 0.5 * h,
    }
}

/// File name of training frame `i` (sorts in capture order, before test views).
pub fn frame_name(i: usize) -> String {
    format!("{i:05}.png")
}

/// File name of test view `k` (sorts after every training frame).
pub fn test_name(k: usize) -> String {
    format!("test_{k:03}.png")
}

/// A candidate 3D point on a static surface.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SurfacePoint {
    pub xyz: Vector3<f64>,
    pub rgb: [u8; 3],
    /// Index of the static triangle it lies on.
    pub tri: u32,
}

/// One rendered view: its name, pose and the candidate points it sees.
pub(crate) struct RenderedView {
    pub name: String,
    pub pose: Pose,
    /// (candidate index, x, y) of every visible candidate, in pixels.
    pub seen: Vec<(usize, f64, f64)>,
}

/// Sample `n` points uniformly by area on the static triangles.
fn sample_surface(world: &World, n: usize, seed: u64) -> Vec<SurfacePoint> {
    let areas: Vec<f64> = world
        .tris
        .iter()
        .map(|t| 0.5 * (t.v[1].p - t.v[0].p).cross(&(t.v[2].p - t.v[0].p)).norm())
        .collect();
    let mut cum = Vec::with_capacity(areas.len());
    let mut acc = 0.0;
    for a in &areas {
        acc += a;
        cum.push(acc);
    }
    let mut rng = Pcg64::seed_from_u64(mix64(seed ^ 0x9013_0003));
    let mut out = Vec::with_capacity(n);
    if acc <= 0.0 {
        return out;
    }
    for _ in 0..n {
        let r = rng.random_range(0.0..acc);
        let ti = cum.partition_point(|c| *c <= r).min(cum.len() - 1);
        let t = &world.tris[ti];
        let (mut a, mut b) = (rng.random_range(0.0..1.0f64), rng.random_range(0.0..1.0f64));
        if a + b > 1.0 {
            (a, b) = (1.0 - a, 1.0 - b);
        }
        let xyz = t.v[0].p + (t.v[1].p - t.v[0].p) * a + (t.v[2].p - t.v[0].p) * b;
        let uv = |k: usize| {
            t.v[0].uv[k] + (t.v[1].uv[k] - t.v[0].uv[k]) * a + (t.v[2].uv[k] - t.v[0].uv[k]) * b
        };
        let c = world
            .textures
            .get(t.material as usize)
            .map_or([0.0; 3], |tex| tex.sample(uv(0) as f32, uv(1) as f32, 0.0));
        let rgb = c
            .map(|v| (v * t.shade).clamp(0.0, 1.0) * 255.0)
            .map(|v| v.round() as u8);
        out.push(SurfacePoint {
            xyz,
            rgb,
            tri: ti as u32,
        });
    }
    out
}

/// Candidates visible in a view: inside the image, passing the depth test
/// against the static world (same triangle, or depth within 0.5 %), and not
/// hidden by a pedestrian.
fn visible_points(
    view: &View,
    pts: &[SurfacePoint],
    stat: (&[Sample], &[Setup]),
    dyn_buf: &[Sample],
) -> Vec<(usize, f64, f64)> {
    let (ws, hs) = view.sample_dims();
    let s = view.ss as f64;
    pts.par_iter()
        .enumerate()
        .filter_map(|(i, p)| {
            let pc = view.pose.transform(p.xyz);
            let (x, y) = view.intr.project(pc)?;
            if !(x >= 0.0 && y >= 0.0 && x < view.intr.width as f64 && y < view.intr.height as f64)
            {
                return None;
            }
            let (sx, sy) = (
                ((x * s) as usize).min(ws - 1),
                ((y * s) as usize).min(hs - 1),
            );
            let smp = &stat.0[sy * ws + sx];
            if smp.tri == NONE || dyn_buf[sy * ws + sx].tri != NONE {
                return None;
            }
            let same = stat
                .1
                .get(smp.tri as usize)
                .is_some_and(|st| st.src == p.tri);
            let close = (smp.depth as f64 - pc.z).abs() < 0.005 * pc.z;
            (same || close).then_some((i, x, y))
        })
        .collect()
}

/// Render one view: the static world, then (for training frames) the
/// pedestrians at time `t` over it.
fn render_view(
    world: &World,
    view: &View,
    t: Option<f64>,
    pts: &[SurfacePoint],
) -> (Resolved, Vec<(usize, f64, f64)>) {
    let (ws, _) = view.sample_dims();
    let stat_setups = raster::setup(view, &world.tris, &world.textures);
    let mut stat = raster::new_buffer(view);
    raster::rasterize(&stat_setups, &mut stat, ws, None);
    let dyn_tris = t.map(|t| world.pedestrian_tris(t)).unwrap_or_default();
    let dyn_setups = raster::setup(view, &dyn_tris, &world.textures);
    let mut dynb = raster::new_buffer(view);
    raster::rasterize(&dyn_setups, &mut dynb, ws, Some(&stat));
    let passes = Passes {
        static_buf: &stat,
        static_setups: &stat_setups,
        dyn_buf: &dynb,
        dyn_setups: &dyn_setups,
        textures: &world.textures,
    };
    let resolved = raster::resolve(view, &passes);
    let seen = visible_points(view, pts, (&stat, &stat_setups), &dynb);
    (resolved, seen)
}

/// Pixels whose distractor coverage is at least half the samples (→ 255).
pub fn motion_mask(coverage: &[u16], ss: u32) -> Vec<u8> {
    let n = (ss * ss) as u16;
    coverage
        .iter()
        .map(|&c| if 2 * c >= n { 255 } else { 0 })
        .collect()
}

/// Render `spec` into the scene folder `out_dir` (created if missing).
pub fn generate(spec: &SceneSpec, out_dir: impl AsRef<Path>) -> Result<GenerateReport> {
    let start = std::time::Instant::now();
    spec.validate()?;
    let out_dir = out_dir.as_ref();
    let world = World::build(spec);
    let intr = intrinsics(spec);
    let candidates = sample_surface(&world, (spec.points3d as usize * 6).max(64), spec.seed);
    let mut views: Vec<RenderedView> = Vec::new();
    let mut fractions = Vec::new();
    for (i, pose) in path::training_poses(spec).into_iter().enumerate() {
        let view = View {
            pose,
            intr,
            ss: spec.supersample,
        };
        let (resolved, seen) = render_view(&world, &view, Some(i as f64 / spec.fps), &candidates);
        let mask = motion_mask(&resolved.coverage, spec.supersample);
        fractions.push(mask.iter().filter(|m| **m > 0).count() as f64 / mask.len() as f64);
        output::write_frame(out_dir, &intr, &frame_name(i), &resolved, &mask, true)?;
        views.push(RenderedView {
            name: frame_name(i),
            pose,
            seen,
        });
    }
    for (k, pose) in path::test_poses(spec).into_iter().enumerate() {
        let view = View {
            pose,
            intr,
            ss: spec.supersample,
        };
        let (resolved, seen) = render_view(&world, &view, None, &candidates);
        let mask = vec![0u8; resolved.coverage.len()];
        output::write_frame(out_dir, &intr, &test_name(k), &resolved, &mask, false)?;
        views.push(RenderedView {
            name: test_name(k),
            pose,
            seen,
        });
    }
    let (points3d, observations) = output::write_model(out_dir, spec, &intr, &views, &candidates)?;
    let n = fractions.len().max(1) as f64;
    let coverage = CoverageStats {
        mean: fractions.iter().sum::<f64>() / n,
        min: fractions.iter().copied().fold(f64::INFINITY, f64::min),
        max: fractions.iter().copied().fold(0.0, f64::max),
        frames_in_10_30: fractions
            .iter()
            .filter(|f| (0.10..=0.30).contains(*f))
            .count() as f64
            / n,
    };
    Ok(GenerateReport {
        name: spec.name.clone(),
        out_dir: out_dir.display().to_string(),
        frames: spec.frames,
        test_views: spec.test_views,
        width: spec.width,
        height: spec.height,
        points3d,
        observations,
        coverage,
        seconds: start.elapsed().as_secs_f64(),
    })
}
