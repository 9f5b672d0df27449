//! Per-kernel profile of GPU training steps with timestamp queries (they work
//! on lavapipe), for `romosplat bench train` and the performance note.
//! Each dispatch is its own compute pass with begin/end timestamps; times of
//! dispatches sharing an entry point are summed per step, then the median
//! over the measured steps is reported.

use super::backend::GpuBackend;
use super::{GpuError, GpuOptions};
use crate::backend::{StepInput, TrainBackend};
use crate::types::{AdamState, Splats};
use std::collections::BTreeMap;

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

/// Run `warmup` + `steps` training steps of `splats` on `input` and return
/// `(kernel entry point, median ms per step)` sorted by time (largest first),
/// plus `"kernels_total"` (Σ of the kernel medians) and `"step_wall"`: the
/// median wall-clock time of a whole step. Entries named `host:*` are
/// wall-clock host sections (submit + wait, readbacks, CPU work) of a step;
/// `count:intersections` is the median number of (tile, splat) pairs (not a
/// time, left out of `kernels_total`).
/// Fails with `GpuError::InvalidInput` when the device lacks timestamp queries.
pub fn profile_step(
    splats: &Splats,
    input: &StepInput<'_>,
    warmup: usize,
    steps: usize,
) -> Result<Vec<(String, f64)>, GpuError> {
    let mut b = GpuBackend::new(&GpuOptions {
        timestamps: true,
        ..Default::default()
    })?;
    if !b.ctx.timestamps {
        return Err(GpuError::InvalidInput(
            "the adapter has no timestamp queries".into(),
        ));
    }
    b.upload(splats, &AdamState::zeros_like(splats))
        .map_err(|e| GpuError::InvalidInput(e.to_string()))?;
    for _ in 0..warmup {
        b.step(input)
            .map_err(|e| GpuError::InvalidInput(e.to_string()))?;
    }
    b.profile = true;
    let mut per: BTreeMap<&'static str, Vec<f64>> = BTreeMap::new();
    let mut wall = Vec::with_capacity(steps);
    let mut inter = Vec::with_capacity(steps);
    for s in 0..steps {
        let t0 = std::time::Instant::now();
        b.step(input)
            .map_err(|e| GpuError::InvalidInput(e.to_string()))?;
        wall.push(t0.elapsed().as_secs_f64() * 1e3);
        inter.push(b.last_intersections() as f64);
        let mut this: BTreeMap<&'static str, f64> = BTreeMap::new();
        for (name, ms) in b.last_timings() {
            *this.entry(name).or_insert(0.0) += ms;
        }
        for (name, ms) in this {
            let v = per.entry(name).or_default();
            v.resize(s, 0.0);
            v.push(ms);
        }
    }
    let mut out: Vec<(String, f64)> = per
        .into_iter()
        .map(|(k, mut v)| {
            v.resize(steps, 0.0);
            (k.to_string(), median(&mut v))
        })
        .collect();
    out.sort_by(|a, b| b.1.total_cmp(&a.1));
    let kernels: f64 = out
        .iter()
        .filter(|(k, _)| !k.starts_with("host:") && !k.starts_with("count:"))
        .map(|(_, v)| v)
        .sum();
    out.push(("kernels_total".to_string(), kernels));
    out.push(("step_wall".to_string(), median(&mut wall)));
    out.push(("count:intersections".to_string(), median(&mut inter)));
    Ok(out)
}
