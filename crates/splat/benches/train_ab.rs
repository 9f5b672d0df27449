//! Benchmark: a whole `romosplat train` run of two builds side by side in one
//! run (the same load for both), printing JSON: per build the median
//! training steps/s (`report.steps_per_sec` of `summary.json`), held-out
//! PSNR / SSIM, final splat count, wall time and peak RSS (GNU
//! `/usr/bin/time -f %M`), and the speed ratio new / base.
//! Runs alternate base, new, base, new, … (`AB_REPS` each, default 1);
//! with `AB_PARALLEL=1` each base / new pair runs at the same time (on a
//! machine shared with other jobs both then see the same load; the faster
//! one finishes first and leaves the slower one more CPU, which favours the
//! slower build).
//!
//! `AB_BASE` and `AB_NEW`: the two `romosplat` binaries (e.g. one built from
//! an older commit in a separate worktree); `AB_ARGS`: the `train` options
//! (default the fox schedule, `--scene ../shared/data/fox --downscale 4
//! --holdout-every 8 --steps 2000 --backend wgpu`); `AB_OUT`: a scratch
//! folder (default a temporary one). Run from the repository root:
//! `AB_BASE=… AB_NEW=target/release/romosplat cargo bench -p splat --bench train_ab`.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

struct Run {
    steps_per_sec: f64,
    psnr: f64,
    ssim: f64,
    splats: u64,
    wall_s: f64,
    peak_rss_mb: f64,
}

fn run(bin: &str, args: &[String], out: &Path) -> Run {
    let rss_file = out.with_extension("rss");
    let t = Instant::now();
    let o = Command::new("/usr/bin/time")
        .arg("-f")
        .arg("%M")
        .arg("-o")
        .arg(&rss_file)
        .arg(bin)
        .arg("--json")
        .arg("train")
        .args(args)
        .arg("--out")
        .arg(out)
        .output()
        .expect("run /usr/bin/time (GNU time)");
    let wall_s = t.elapsed().as_secs_f64();
    assert!(
        o.status.success(),
        "{bin} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("train --json output");
    let f = |p: &str| v.pointer(p).and_then(|x| x.as_f64()).unwrap_or(f64::NAN);
    let rss_kb: f64 = std::fs::read_to_string(&rss_file)
        .ok()
        .and_then(|s| s.lines().last().and_then(|l| l.trim().parse().ok()))
        .unwrap_or(f64::NAN);
    Run {
        steps_per_sec: f("/report/steps_per_sec"),
        psnr: f("/test/mean_psnr"),
        ssim: f("/test/mean_ssim"),
        splats: v
            .pointer("/report/splats")
            .and_then(|x| x.as_u64())
            .unwrap_or(0),
        wall_s,
        peak_rss_mb: rss_kb / 1024.0,
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

fn summary(runs: &[Run]) -> serde_json::Value {
    let m = |f: fn(&Run) -> f64| median(runs.iter().map(f).collect());
    serde_json::json!({
        "steps_per_sec": m(|r| r.steps_per_sec),
        "heldout_psnr": m(|r| r.psnr),
        "heldout_ssim": m(|r| r.ssim),
        "splats": m(|r| r.splats as f64),
        "wall_s": m(|r| r.wall_s),
        "peak_rss_mb": m(|r| r.peak_rss_mb),
        "runs": runs.iter().map(|r| serde_json::json!({
            "steps_per_sec": r.steps_per_sec, "heldout_psnr": r.psnr,
            "heldout_ssim": r.ssim, "splats": r.splats, "wall_s": r.wall_s,
            "peak_rss_mb": r.peak_rss_mb,
        })).collect::<Vec<_>>(),
    })
}

fn main() {
    let base = std::env::var("AB_BASE").expect("AB_BASE: the baseline romosplat binary");
    let new = std::env::var("AB_NEW").expect("AB_NEW: the new romosplat binary");
    let args: Vec<String> = std::env::var("AB_ARGS")
        .unwrap_or_else(|_| {
            "--scene ../shared/data/fox --downscale 4 --holdout-every 8 --steps 2000 --backend wgpu"
                .into()
        })
        .split_whitespace()
        .map(String::from)
        .collect();
    let reps: usize = std::env::var("AB_REPS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1);
    let out = std::env::var("AB_OUT")
        .map(PathBuf::from)
        .unwrap_or_else(|_| std::env::temp_dir().join(format!("train_ab_{}", std::process::id())));
    std::fs::create_dir_all(&out).unwrap();
    let parallel = std::env::var("AB_PARALLEL").is_ok_and(|v| v == "1");
    let (mut rb, mut rn) = (Vec::new(), Vec::new());
    for rep in 0..reps {
        let (ob, on) = (
            out.join(format!("base{rep}")),
            out.join(format!("new{rep}")),
        );
        let (b, n) = if parallel {
            std::thread::scope(|s| {
                let hb = s.spawn(|| run(&base, &args, &ob));
                let hn = s.spawn(|| run(&new, &args, &on));
                (hb.join().unwrap(), hn.join().unwrap())
            })
        } else {
            let b = run(&base, &args, &ob);
            (b, run(&new, &args, &on))
        };
        for (name, r) in [("base", &b), ("new", &n)] {
            eprintln!(
                "{name} #{rep}: {:.3} steps/s, held-out {:.2} dB, {} splats, {:.0} MB",
                r.steps_per_sec, r.psnr, r.splats, r.peak_rss_mb
            );
        }
        rb.push(b);
        rn.push(n);
    }
    let (sb, sn) = (summary(&rb), summary(&rn));
    let ratio = sn["steps_per_sec"].as_f64().unwrap() / sb["steps_per_sec"].as_f64().unwrap();
    let dpsnr = sn["heldout_psnr"].as_f64().unwrap() - sb["heldout_psnr"].as_f64().unwrap();
    println!(
        "{}",
        serde_json::json!({
            "args": args, "reps": reps, "parallel": parallel,
            "base_bin": base, "new_bin": new,
            "base": sb, "new": sn,
            "speedup": ratio, "heldout_psnr_delta_db": dpsnr,
        })
    );
}
