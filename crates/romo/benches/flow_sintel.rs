//! Benchmark: built-in DIS flow on the MPI Sintel pairs in
//! `../shared/data/sintel-flow` (or `$SINTEL_DIR`). Prints one JSON object:
//! per pair EPE over all pixels and non-occluded pixels, and the median time
//! of `reps` runs. Compare with `crates/romo/benches/opencv_dis.py`, which
//! runs OpenCV's DIS MEDIUM on the same pairs. Skips (prints a note) when
//! the data is absent.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use romo::flow::dis::Dis;
use romo::flow::{Flow, epe};
use romo::plane::Plane;
use std::path::Path;
use std::time::Instant;

fn read_flo(p: &Path) -> Flow {
    let b = std::fs::read(p).unwrap();
    assert_eq!(&b[0..4], b"PIEH");
    let w = u32::from_le_bytes(b[4..8].try_into().unwrap()) as usize;
    let h = u32::from_le_bytes(b[8..12].try_into().unwrap()) as usize;
    let f = |i: usize| f32::from_le_bytes(b[12 + 4 * i..16 + 4 * i].try_into().unwrap());
    Flow {
        u: Plane::from_fn(w, h, |x, y| f(2 * (y * w + x))),
        v: Plane::from_fn(w, h, |x, y| f(2 * (y * w + x) + 1)),
    }
}

/// Middlebury .flo writer (for looking at results; `DUMP_DIR`).
fn write_flo(p: &Path, f: &Flow) {
    let mut b = b"PIEH".to_vec();
    b.extend((f.w() as u32).to_le_bytes());
    b.extend((f.h() as u32).to_le_bytes());
    for i in 0..f.u.data.len() {
        b.extend(f.u.data[i].to_le_bytes());
        b.extend(f.v.data[i].to_le_bytes());
    }
    std::fs::write(p, b).unwrap();
}

fn gray(p: &Path) -> Plane {
    let img = image::open(p).unwrap().to_rgb32f();
    romo::plane::Rgb::from_image(&img).gray()
}

fn main() {
    let dir =
        std::env::var("SINTEL_DIR").unwrap_or_else(|_| "../../../shared/data/sintel-flow".into());
    let dir = Path::new(&dir);
    let dir = if dir.exists() {
        dir.to_path_buf()
    } else {
        Path::new("/work/shared/data/sintel-flow").to_path_buf()
    };
    if !dir.exists() {
        println!("{{\"skipped\": \"no sintel-flow data\"}}");
        return;
    }
    let reps: usize = std::env::var("REPS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3);
    // DIS_OPTS: a partial DisOptions JSON (experiments); PAIRS: a
    // comma-separated list of name prefixes to run.
    // PRESET=large selects DisOptions::large_motion().
    let opts: romo::flow::dis::DisOptions = match std::env::var("DIS_OPTS") {
        Ok(s) => serde_json::from_str(&s).unwrap(),
        Err(_) if std::env::var("PRESET").as_deref() == Ok("large") => {
            romo::flow::dis::DisOptions::large_motion()
        }
        Err(_) => Default::default(),
    };
    let filter: Vec<String> = std::env::var("PAIRS")
        .map(|s| s.split(',').map(String::from).collect())
        .unwrap_or_default();
    let dis = Dis::new(opts.clone());
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.retain(|n| filter.is_empty() || filter.iter().any(|f| n.starts_with(f.as_str())));
    names.sort();
    let mut rows = Vec::new();
    for n in names {
        let d = dir.join(&n);
        let (a, b) = (gray(&d.join("frame1.png")), gray(&d.join("frame2.png")));
        let gt = read_flo(&d.join("flow.flo"));
        let occ = image::open(d.join("occlusions.png")).unwrap().to_luma8();
        let noc: Vec<bool> = occ.as_raw().iter().map(|v| *v < 128).collect();
        let mut times = Vec::new();
        let mut est = None;
        for _ in 0..reps {
            let t = Instant::now();
            est = Some(dis.compute(&a, &b).unwrap());
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        times.sort_by(|x, y| x.partial_cmp(y).unwrap());
        let est = est.unwrap();
        if let Ok(dump) = std::env::var("DUMP_DIR") {
            write_flo(&Path::new(&dump).join(format!("{n}.flo")), &est);
        }
        let small = n.starts_with("alley") || n.starts_with("cave");
        rows.push(serde_json::json!({
            "pair": n, "small_motion": small,
            "epe_all": epe(&est, &gt, None), "epe_noc": epe(&est, &gt, Some(&noc)),
            "gt_mean_mag": gt.mean_magnitude(), "ms_median": times[times.len() / 2],
        }));
    }
    let mean = |small: bool, k: &str| {
        let v: Vec<f64> = rows
            .iter()
            .filter(|r| r["small_motion"] == small)
            .map(|r| r[k].as_f64().unwrap())
            .collect();
        v.iter().sum::<f64>() / v.len().max(1) as f64
    };
    let out = serde_json::json!({
        "method": "romo DIS", "options": opts, "threads": rayon::current_num_threads(),
        "small": {"epe_all": mean(true, "epe_all"), "epe_noc": mean(true, "epe_noc"), "ms": mean(true, "ms_median")},
        "large": {"epe_all": mean(false, "epe_all"), "epe_noc": mean(false, "epe_noc"), "ms": mean(false, "ms_median")},
        "pairs": rows,
    });
    println!("{}", serde_json::to_string_pretty(&out).unwrap());
}
