//! Measurement (not a test): RoMo on the DAVIS-2016 sequences in
//! `$DAVIS_DIR` (required), masks into
//! `$OUT` (default /tmp/romo_davis), J / precision / recall per sequence as
//! JSON. Options may be overridden with a partial JSON `RomoOptions` in
//! `$ROMO_OPTS`; `$SEQS` restricts to a comma-separated list.
#![allow(clippy::unwrap_used, clippy::expect_used)]
use std::path::PathBuf;
fn main() {
    let Some(davis) = std::env::var_os("DAVIS_DIR").map(PathBuf::from) else {
        eprintln!("set DAVIS_DIR to the DAVIS-2016 folder (JPEGImages/480p, Annotations/480p)");
        std::process::exit(2);
    };
    let out = PathBuf::from(std::env::var("OUT").unwrap_or("/tmp/romo_davis".into()));
    let opts: romo::RomoOptions =
        serde_json::from_str(&std::env::var("ROMO_OPTS").unwrap_or("{}".into())).unwrap();
    let only: Option<Vec<String>> = std::env::var("SEQS")
        .ok()
        .map(|s| s.split(',').map(String::from).collect());
    let mut rows = vec![];
    let mut js = vec![];
    let imgs = davis.join("JPEGImages/480p");
    let mut seqs: Vec<_> = std::fs::read_dir(&imgs)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    seqs.sort();
    for s in seqs {
        if only.as_ref().is_some_and(|o| !o.contains(&s)) {
            continue;
        }
        let mut paths: Vec<PathBuf> = std::fs::read_dir(imgs.join(&s))
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        paths.sort();
        let names: Vec<String> = paths
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        let t = std::time::Instant::now();
        let rep = romo::segment_paths(&paths, &names, &out.join(&s), &opts, &|_, _, _| {}).unwrap();
        let secs = t.elapsed().as_secs_f64();
        let m = romo::metrics::evaluate_sequence(
            &out.join(&s).join("masks"),
            &davis.join("Annotations/480p").join(&s),
            &s,
        )
        .unwrap();
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
            "pairs": rep.pairs.iter().map(|p| format!("{} {:.3}", p.model, p.u_fraction_f)).collect::<Vec<_>>()}));
    }
    let mj = js.iter().sum::<f64>() / js.len().max(1) as f64;
    eprintln!("mean J {mj:.3}");
    println!(
        "{}",
        serde_json::to_string_pretty(
            &serde_json::json!({"mean_j": mj, "options": opts, "sequences": rows})
        )
        .unwrap()
    );
}
