//! Measurement (not a test): RoMo on the DAVIS-2016 sequences in
//! `$DAVIS_DIR` (default `../shared/data/davis2016` beside the repository),
//! masks into `$OUT` (default `romo_davis` in the temporary folder), J /
//! precision / recall per sequence as JSON. Options may be overridden with
//! a partial JSON `RomoOptions` in `$ROMO_OPTS`; `$SEQS` restricts to a
//! comma-separated list. `$FRAME_STEP` N (default 1) keeps every N-th frame
//! (0, N, 2N, …), N times the motion per pair; `$MAXF` N keeps the first N
//! of those (a short clip); J is scored on the frames kept.
use std::path::PathBuf;

mod common;
use common::Res;

fn main() -> std::process::ExitCode {
    common::main("davis", run)
}

/// The files of `dir`, sorted by name.
fn sorted_entries(dir: &std::path::Path) -> Res<Vec<PathBuf>> {
    let mut v = std::fs::read_dir(dir)
        .map_err(|e| format!("{}: {e}", dir.display()))?
        .map(|e| e.map(|e| e.path()))
        .collect::<std::io::Result<Vec<_>>>()?;
    v.sort();
    Ok(v)
}

fn run() -> Res<()> {
    let davis = common::davis_dir();
    let out = std::env::var_os("OUT")
        .map_or_else(|| std::env::temp_dir().join("romo_davis"), PathBuf::from);
    let opts = common::romo_options()?;
    let only = common::sequences();
    let step = common::frame_step()?;
    let maxf: usize = common::max_frames()?;
    let mut rows = vec![];
    let mut js = vec![];
    let imgs = davis.join("JPEGImages/480p");
    for dir in sorted_entries(&imgs)? {
        let s = common::file_name(&dir);
        if only.as_ref().is_some_and(|o| !o.contains(&s)) {
            continue;
        }
        let paths: Vec<PathBuf> = sorted_entries(&dir)?
            .into_iter()
            .step_by(step)
            .take(maxf)
            .collect();
        let names: Vec<String> = paths.iter().map(|p| common::file_name(p)).collect();
        let t = std::time::Instant::now();
        let rep = romo::segment_paths(&paths, &names, &out.join(&s), &opts, &|_, _, _| {})?;
        let secs = t.elapsed().as_secs_f64();
        // Only this run's frames are scored: `OUT` may hold masks of other
        // frames from an earlier run (another `FRAME_STEP`).
        let ann = davis.join("Annotations/480p").join(&s);
        let stem = |p: &PathBuf| {
            p.file_stem()
                .map(|x| x.to_string_lossy().into_owned())
                .unwrap_or_default()
        };
        let ours: Vec<String> = paths.iter().map(stem).collect();
        let others: Vec<String> = sorted_entries(&ann)?
            .iter()
            .map(stem)
            .filter(|x| !ours.contains(x))
            .collect();
        let m = romo::metrics::evaluate_sequence_excluding(
            &out.join(&s).join("masks"),
            &ann,
            &s,
            &others,
        )?;
        let mean = |f: &dyn Fn(&romo::FrameReport) -> f32| {
            rep.frames.iter().map(|x| f(x) as f64).sum::<f64>() / rep.frames.len() as f64
        };
        let nh = rep.pairs.iter().filter(|p| p.model == "H").count();
        eprintln!(
            "{s}: J {:.3} P {:.3} R {:.3} U {:.3} L {:.3} H-pairs {nh}/{} dropped {} {:.1}s fps {:.2} collapsed {:?}",
            m.j_mean,
            m.precision,
            m.recall,
            mean(&|f| f.u_coverage),
            mean(&|f| f.l_coverage),
            rep.pairs.len(),
            rep.dropped_frames.len(),
            secs,
            names.len() as f64 / secs,
            rep.rounds.iter().map(|r| r.collapsed).collect::<Vec<_>>()
        );
        js.push(m.j_mean);
        rows.push(serde_json::json!({"sequence": s, "j": m.j_mean, "precision": m.precision, "recall": m.recall, "j_recall": m.j_recall,
            "u_cov": mean(&|f| f.u_coverage), "l_cov": mean(&|f| f.l_coverage), "h_pairs": nh, "dropped": rep.dropped_frames.len(),
            "frames": names.len(), "seconds": secs, "skipped_pairs": rep.skipped_pairs, "no_evidence_frames": rep.no_evidence_frames, "timings_ms": rep.timings_ms,
            "rounds": rep.rounds,
            "pairs": rep.pairs.iter().map(|p| format!("{} {:.3} {:.3}", p.model, p.u_fraction_f, p.sigma_px)).collect::<Vec<_>>()}));
    }
    let mj = js.iter().sum::<f64>() / js.len().max(1) as f64;
    eprintln!("mean J {mj:.3}");
    println!(
        "{}",
        serde_json::to_string_pretty(
            &serde_json::json!({"mean_j": mj, "options": opts, "sequences": rows})
        )?
    );
    Ok(())
}
