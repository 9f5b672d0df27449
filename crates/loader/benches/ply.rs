//! PLY throughput benchmark: write and read N splats (SH degree 3, the
//! INRIA layout's 62 floats per splat) through a temp file several times and
//! print one JSON line with the median splats/s each way.
//!
//! Run: `cargo bench -p loader --bench ply` (env `PLY_BENCH_N`, `PLY_BENCH_RUNS`).

use loader::ply::{PlySplats, encode_ply, read_ply, read_ply_bytes, rest_len, write_ply};
use std::time::Instant;

fn sample(n: usize) -> PlySplats {
    let r = rest_len(3);
    let f = |i: usize, k: usize| ((i * 131 + k * 7) % 1000) as f32 * 0.001 - 0.5;
    PlySplats {
        means: (0..n).map(|i| [f(i, 0), f(i, 1), f(i, 2)]).collect(),
        normals: None,
        f_dc: (0..n).map(|i| [f(i, 3), f(i, 4), f(i, 5)]).collect(),
        f_rest: (0..n * r).map(|j| f(j / r, j % r)).collect(),
        opacities: (0..n).map(|i| f(i, 60)).collect(),
        scales: (0..n).map(|i| [f(i, 61), f(i, 62), f(i, 63)]).collect(),
        rotations: (0..n)
            .map(|i| [1.0, f(i, 64), f(i, 65), f(i, 66)])
            .collect(),
        sh_degree: 3,
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n: usize = std::env::var("PLY_BENCH_N")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1_000_000);
    let runs: usize = std::env::var("PLY_BENCH_RUNS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(5);
    let splats = sample(n);
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("bench.ply");
    let (mut w, mut r, mut e, mut d) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for _ in 0..runs {
        let t = Instant::now();
        write_ply(&path, &splats)?;
        w.push(n as f64 / t.elapsed().as_secs_f64());
        let t = Instant::now();
        let back = read_ply(&path)?;
        r.push(n as f64 / t.elapsed().as_secs_f64());
        let t = Instant::now();
        let bytes = encode_ply(&splats, &path)?;
        e.push(n as f64 / t.elapsed().as_secs_f64());
        let t = Instant::now();
        let again = read_ply_bytes(&bytes, &path)?;
        d.push(n as f64 / t.elapsed().as_secs_f64());
        if back.len() != n || again.len() != n {
            return Err("read back wrong count".into());
        }
    }
    let bytes = std::fs::metadata(&path)?.len();
    println!(
        "{}",
        serde_json::json!({
            "bench": "ply",
            "splats": n,
            "sh_degree": 3,
            "file_bytes": bytes,
            "runs": runs,
            "write_splats_per_s_median": median(w),
            "read_splats_per_s_median": median(r),
            "encode_in_memory_splats_per_s_median": median(e),
            "decode_in_memory_splats_per_s_median": median(d),
            "threads": rayon::current_num_threads(),
        })
    );
    Ok(())
}
