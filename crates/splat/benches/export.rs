//! Benchmark: export encoders and the clean pass on a random splat set
//! (`N` splats, default 200 000, SH degree 3; `EXPORT_BENCH_N` overrides).
//! Prints one JSON object: per format the file size, bytes per splat and the
//! median encode time of 3 runs (in memory, no disk), plus the clean pass.
//! Run: `cargo bench -p splat --bench export`.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use splat::Splats;
use splat::export::{self, CleanOptions, GlbOptions, SceneGeometry, SpzOptions};
use std::time::Instant;

fn random_splats(n: usize) -> Splats {
    let mut rng = Pcg64::seed_from_u64(1);
    let mut s = Splats {
        sh_degree: 3,
        ..Default::default()
    };
    for _ in 0..n {
        s.means
            .push([0; 3].map(|_| rng.random_range(-10.0f32..10.0)));
        s.log_scales
            .push([0; 3].map(|_| rng.random_range(-6.0f32..-1.0)));
        s.rotations
            .push([0; 4].map(|_| rng.random_range(-1.0f32..1.0)));
        s.opacity_logits.push(rng.random_range(-4.0f32..4.0));
        for j in 0..16 {
            let r = if j == 0 { 1.5f32 } else { 0.3 };
            for _ in 0..3 {
                s.sh.push(rng.random_range(-r..r));
            }
        }
    }
    s
}

fn median_secs<T>(mut f: impl FnMut() -> T) -> (f64, T) {
    let mut times = Vec::new();
    let mut out = None;
    for _ in 0..3 {
        let t = Instant::now();
        out = Some(f());
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    (times[1], out.unwrap())
}

fn main() {
    let n: usize = std::env::var("EXPORT_BENCH_N")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(200_000);
    let s = random_splats(n);
    let mut formats = serde_json::Map::new();
    let mut record = |name: &str, secs: f64, bytes: usize| {
        formats.insert(
            name.into(),
            serde_json::json!({
                "bytes": bytes,
                "bytes_per_splat": bytes as f64 / n as f64,
                "encode_s": secs,
                "splats_per_s": n as f64 / secs,
            }),
        );
    };
    let (t, b) = median_secs(|| export::encode_splat(&s).unwrap());
    record("splat", t, b.len());
    let (t, b) = median_secs(|| export::encode_spz(&s, &SpzOptions::default()).unwrap());
    record("spz_v3", t, b.len());
    let (t, b) = median_secs(|| export::encode_glb(&s, &GlbOptions::default()).unwrap());
    record("glb", t, b.len());
    let (t, rep) = median_secs(|| {
        export::clean(&s, &SceneGeometry::default(), &CleanOptions::default())
            .unwrap()
            .1
    });
    let out = serde_json::json!({
        "bench": "export",
        "splats": n,
        "sh_degree": 3,
        "formats": formats,
        "clean": { "seconds": t, "report": rep },
    });
    println!("{}", serde_json::to_string_pretty(&out).unwrap());
}
