//! Benchmark: built-in DIS flow against OpenCV's DIS MEDIUM on the MPI
//! Sintel pairs in `../shared/data/sintel-flow` (or `$SINTEL_DIR`), in one
//! run. Prints one JSON object: per pair EPE over all and non-occluded
//! pixels and median times of both methods, per-stage median times of ours
//! (pyramid, and per level upsampling, preparation, patch search,
//! densification, variational refinement), and `ratio` = our median time /
//! OpenCV's. OpenCV runs in a `python3 benches/opencv_dis.py --serve`
//! subprocess; each repetition runs ours and OpenCV's back to back
//! (alternating which goes first) so both see the same machine load. When
//! `cv2` cannot be imported the JSON says so and only ours is measured.
//!
//! Environment: `REPS` (default 5), `PAIRS` (comma-separated name
//! prefixes), `PRESET=large` (`DisOptions::large_motion()`), `DIS_OPTS` (a
//! partial `DisOptions` JSON over the mask stage's preset), `OPENCV=0` (skip OpenCV), `DUMP_DIR` (write
//! our `.flo` files), `SIMD=baseline` (run our kernels' baseline x86-64
//! copies even on an AVX2 CPU; `simd` in the JSON says which ran),
//! `SIMD=both` (each repetition also runs the baseline copies right before
//! the AVX2 ones, asserts equal flows, and reports `baseline_ms` and
//! `simd_speedup` = baseline / AVX2 time, medians paired per pair),
//! `PRESET=masks` (`DisOptions::masks()`, the mask stage's),
//! `ONNX_FLOW=a.onnx[,b.onnx]` (needs `--features onnx` and
//! `ORT_DYLIB_PATH`: also runs each ONNX flow model once per pair on the RGB
//! frames through `romo::onnx::OnnxFlow`, padded or shrunk to its input
//! size; the forward flow's EPE and the time of both directions, `ms`,
//! go under `onnx` per pair and in the summaries).
//! Skips (prints a note) when the data is absent.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use romo::flow::dis::{Dis, DisOptions, DisTimings};
use romo::flow::{Flow, FlowEstimator, epe};
use romo::plane::Plane;
use serde_json::{Value, json};
use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};

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

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// OpenCV DIS in a Python subprocess (`opencv_dis.py --serve`).
struct OpenCv {
    child: Child,
    tx: ChildStdin,
    rx: BufReader<ChildStdout>,
    version: String,
}

impl OpenCv {
    /// Start the server; `Err(reason)` when python3 or cv2 is unavailable.
    fn start(dir: &Path) -> Result<Self, String> {
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/opencv_dis.py");
        let mut child = Command::new("python3")
            .arg(&script)
            .arg("--serve")
            .arg(dir)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|e| format!("python3: {e}"))?;
        let tx = child.stdin.take().ok_or("no stdin")?;
        let mut rx = BufReader::new(child.stdout.take().ok_or("no stdout")?);
        let mut line = String::new();
        rx.read_line(&mut line).map_err(|e| e.to_string())?;
        match line.trim().strip_prefix("ready ") {
            Some(v) => Ok(Self {
                version: v.to_string(),
                child,
                tx,
                rx,
            }),
            None => {
                let _ = child.wait();
                Err(format!("OpenCV not available ({})", line.trim()))
            }
        }
    }

    /// One timed run on a pair: `{"ms", "epe_all", "epe_noc"}`.
    fn run(&mut self, pair: &str) -> Value {
        writeln!(self.tx, "run {pair}").unwrap();
        self.tx.flush().unwrap();
        let mut line = String::new();
        self.rx.read_line(&mut line).unwrap();
        serde_json::from_str(&line).unwrap_or_else(|e| panic!("opencv_dis.py: {e}: {line}"))
    }

    fn stop(mut self) {
        let _ = writeln!(self.tx, "quit");
        let _ = self.child.wait();
    }
}

/// Per-stage medians over repetitions of one pair, as a flat JSON object
/// (`pyramid`, `final_resize`, `total`, and per stage the sum over levels
/// plus `L<level>_<stage>`).
fn stage_medians(ts: &[DisTimings]) -> serde_json::Map<String, Value> {
    type Key = (String, Box<dyn Fn(&DisTimings) -> f64>);
    let mut keys: Vec<Key> = vec![
        ("pyramid".into(), Box::new(|t| t.pyramid_ms)),
        ("final_resize".into(), Box::new(|t| t.final_resize_ms)),
        ("total".into(), Box::new(|t| t.total_ms)),
    ];
    type Get = fn(&romo::flow::dis::LevelTimings) -> f64;
    let stages: [(&str, Get); 5] = [
        ("upsample", |l| l.upsample_ms),
        ("prepare", |l| l.prepare_ms),
        ("search", |l| l.search_ms),
        ("densify", |l| l.densify_ms),
        ("variational", |l| l.variational_ms),
    ];
    for (name, get) in stages {
        keys.push((
            format!("{name}_all_levels"),
            Box::new(move |t| t.levels.iter().map(get).sum()),
        ));
        for (i, l) in ts[0].levels.iter().enumerate() {
            keys.push((
                format!("L{}_{name}", l.level),
                Box::new(move |t| t.levels.get(i).map_or(f64::NAN, get)),
            ));
        }
    }
    keys.into_iter()
        .map(|(k, f)| (k, json!(median(ts.iter().map(&f).collect()))))
        .collect()
}

/// The ONNX flow models `ONNX_FLOW` names, by file name.
#[cfg(feature = "onnx")]
fn onnx_models() -> Vec<(String, Box<dyn FlowEstimator>)> {
    let Ok(list) = std::env::var("ONNX_FLOW") else {
        return Vec::new();
    };
    list.split(',')
        .filter(|s| !s.is_empty())
        .map(|p| {
            let path = Path::new(p);
            let net = romo::onnx::OnnxFlow::load(path, 1.0)
                .unwrap_or_else(|e| panic!("ONNX_FLOW {p}: {e}"));
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            (name, Box::new(net) as Box<dyn FlowEstimator>)
        })
        .collect()
}

#[cfg(not(feature = "onnx"))]
fn onnx_models() -> Vec<(String, Box<dyn FlowEstimator>)> {
    assert!(
        std::env::var_os("ONNX_FLOW").is_none(),
        "ONNX_FLOW needs `cargo bench -p romo --features onnx`"
    );
    Vec::new()
}

/// One run of an ONNX model on a pair's RGB frames: EPE and time.
fn onnx_row(net: &dyn FlowEstimator, d: &Path, gt: &Flow, noc: &[bool]) -> Value {
    let rgb = |f: &str| romo::plane::Rgb::from_image(&image::open(d.join(f)).unwrap().to_rgb32f());
    let (a, b) = (rgb("frame1.png"), rgb("frame2.png"));
    let t = std::time::Instant::now();
    let (f, _) = net.flow_pair(&a, &b).unwrap();
    let ms = t.elapsed().as_secs_f64() * 1e3;
    json!({"epe_all": epe(&f, gt, None), "epe_noc": epe(&f, gt, Some(noc)), "ms": ms})
}

fn main() {
    // Default: `../shared/data/sintel-flow` beside the repository.
    let dir = std::env::var("SINTEL_DIR").unwrap_or_else(|_| {
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../../shared/data/sintel-flow"
        )
        .into()
    });
    let dir = Path::new(&dir).to_path_buf();
    if !dir.exists() {
        println!("{{\"skipped\": \"no sintel-flow data\"}}");
        return;
    }
    let simd_mode = std::env::var("SIMD").unwrap_or_default();
    if simd_mode == "baseline" {
        romo::flow::simd::force_baseline(true);
    }
    let both = simd_mode == "both";
    let reps: usize = std::env::var("REPS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(5)
        .max(1);
    let opts = options_from_env();
    let filter: Vec<String> = std::env::var("PAIRS")
        .map(|s| s.split(',').map(String::from).collect())
        .unwrap_or_default();
    let mut cv = if std::env::var("OPENCV").as_deref() == Ok("0") {
        Err("disabled (OPENCV=0)".to_string())
    } else {
        OpenCv::start(&dir)
    };
    let dis = Dis::new(opts.clone());
    let onnx = onnx_models();
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
        let mut ours = Vec::new();
        let mut theirs = Vec::new();
        let mut est = None;
        let mut base_ms = Vec::new();
        for rep in 0..reps {
            let mut run_ours = || {
                if both {
                    romo::flow::simd::force_baseline(true);
                    let (f, t) = dis.compute_timed(&a, &b).unwrap();
                    romo::flow::simd::force_baseline(false);
                    base_ms.push(t.total_ms);
                    est = Some(f);
                }
                let (f, t) = dis.compute_timed(&a, &b).unwrap();
                if let Some(e) = &est {
                    assert!(e == &f, "baseline and AVX2 flows differ");
                }
                est = Some(f);
                ours.push(t);
            };
            match (&mut cv, rep % 2) {
                (Ok(cv), 0) => {
                    run_ours();
                    theirs.push(cv.run(&n));
                }
                (Ok(cv), _) => {
                    theirs.push(cv.run(&n));
                    run_ours();
                }
                (Err(_), _) => run_ours(),
            }
        }
        let est = est.unwrap();
        if let Ok(dump) = std::env::var("DUMP_DIR") {
            write_flo(&Path::new(&dump).join(format!("{n}.flo")), &est);
        }
        let ms = median(ours.iter().map(|t| t.total_ms).collect());
        let mut row = json!({
            "pair": n, "small_motion": n.starts_with("alley") || n.starts_with("cave"),
            "gt_mean_mag": gt.mean_magnitude(),
            "epe_all": epe(&est, &gt, None), "epe_noc": epe(&est, &gt, Some(&noc)),
            "ms_median": ms, "stages_ms": stage_medians(&ours),
        });
        if both {
            row["baseline_ms_median"] = json!(median(base_ms));
        }
        if let Some(last) = theirs.last() {
            let cms = median(theirs.iter().map(|r| r["ms"].as_f64().unwrap()).collect());
            row["opencv"] =
                json!({"epe_all": last["epe_all"], "epe_noc": last["epe_noc"], "ms_median": cms});
            row["ratio"] = json!(ms / cms);
        }
        let mut by_model = serde_json::Map::new();
        for (name, model) in &onnx {
            by_model.insert(name.clone(), onnx_row(model.as_ref(), &d, &gt, &noc));
        }
        if !by_model.is_empty() {
            row["onnx"] = Value::Object(by_model);
        }
        eprintln!("{row}");
        rows.push(row);
    }
    let out = json!({
        "method": "romo DIS vs OpenCV DIS MEDIUM (interleaved, per-pair medians, means over pairs)",
        "options": opts, "threads": rayon::current_num_threads(), "reps": reps,
        "simd": if romo::flow::simd::avx2_active() { "avx2" } else { "baseline" },
        "opencv": match &cv { Ok(c) => json!({"available": true, "version": c.version, "threads": 2}),
                              Err(e) => json!({"available": false, "reason": e}) },
        "small": summary(&rows, &onnx, true), "large": summary(&rows, &onnx, false),
        "pairs": rows,
    });
    if let Ok(c) = cv {
        c.stop();
    }
    println!("{}", serde_json::to_string_pretty(&out).unwrap());
}

/// `DIS_OPTS` (a `DisOptions` JSON) or `PRESET` (`large`, `masks`), else
/// OpenCV's MEDIUM preset.
fn options_from_env() -> DisOptions {
    match std::env::var("DIS_OPTS") {
        Ok(s) => match serde_json::from_str(&s) {
            Ok(o) => o,
            Err(e) => {
                eprintln!("DIS_OPTS: not a DisOptions JSON ({e})");
                std::process::exit(2);
            }
        },
        Err(_) if std::env::var("PRESET").as_deref() == Ok("large") => DisOptions::large_motion(),
        Err(_) if std::env::var("PRESET").as_deref() == Ok("masks") => DisOptions::masks(),
        Err(_) => DisOptions::opencv_medium(),
    }
}

/// Means over the small- (or large-) motion pairs' rows: EPE and time of
/// ours, OpenCV's and each ONNX model's, the SIMD speed-up, stage times.
fn summary(rows: &[Value], onnx: &[(String, Box<dyn FlowEstimator>)], small: bool) -> Value {
    let mean = |get: &dyn Fn(&Value) -> Option<f64>| {
        let v: Vec<f64> = rows
            .iter()
            .filter(|r| r["small_motion"] == small)
            .filter_map(get)
            .collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
    };
    let ours_ms = mean(&|r| r["ms_median"].as_f64());
    let cv_ms = mean(&|r| r["opencv"]["ms_median"].as_f64());
    let base_ms = mean(&|r| r["baseline_ms_median"].as_f64());
    let mut stages = serde_json::Map::new();
    if let Some(first) = rows.iter().find(|r| r["small_motion"] == small) {
        for k in first["stages_ms"].as_object().unwrap().keys() {
            let v = mean(&|r| r["stages_ms"][k].as_f64());
            stages.insert(k.clone(), json!(v));
        }
    }
    let mut onnx_summary = serde_json::Map::new();
    for (name, _) in onnx {
        let get = |k: &'static str| mean(&|r| r["onnx"][name.as_str()][k].as_f64());
        onnx_summary.insert(
            name.clone(),
            json!({"epe_all": get("epe_all"), "epe_noc": get("epe_noc"), "ms": get("ms")}),
        );
    }
    json!({
        "onnx": onnx_summary,
        "romo": {"epe_all": mean(&|r| r["epe_all"].as_f64()),
                 "epe_noc": mean(&|r| r["epe_noc"].as_f64()), "ms": ours_ms},
        "opencv": {"epe_all": mean(&|r| r["opencv"]["epe_all"].as_f64()),
                   "epe_noc": mean(&|r| r["opencv"]["epe_noc"].as_f64()), "ms": cv_ms},
        "ratio": ours_ms.zip(cv_ms).map(|(a, b)| a / b),
        "baseline_ms": base_ms,
        "simd_speedup": base_ms.zip(ours_ms).map(|(a, b)| a / b),
        "romo_stages_ms": stages,
    })
}
