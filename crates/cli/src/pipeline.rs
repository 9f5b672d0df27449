//! Stage freshness for `romosplat run`, by fingerprint. After a stage
//! succeeds it writes a manifest (`OUT/manifests/<stage>.json`) recording
//! what it read — every input file's size and modification time, plus a
//! content hash for inputs worth hashing (the video, options files) — the
//! resolved options that affect its result, the romosplat version, and its
//! typed result. A stage is up to date when its manifest matches all of that
//! now and its outputs exist; otherwise it runs, and so does every later
//! stage. `--from STAGE` forces that stage and every later one.
//!
//! Hashed inputs compare by size and content, so touching a file without
//! changing it does not rerun anything; an unchanged size and mtime reuse the
//! recorded hash (git's stat cache), so an unchanged rerun reads no file.

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::UNIX_EPOCH;

/// The version recorded in every manifest: a new romosplat reruns every stage.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// The stages of `romosplat run`, in order.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, clap::ValueEnum, Serialize, Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Stage {
    /// Video → frames (with `--scene`: the scene's files linked into OUT/scene).
    Frames,
    /// RoMo motion masks.
    Mask,
    /// Video keyframes: frames without texture, blurry frames and near-duplicates dropped.
    Keyframes,
    /// Masked COLMAP.
    Pose,
    /// Masked splat training.
    Train,
    /// The same training without masks, on the same poses and steps: the
    /// held-out scores the masks are compared with.
    Baseline,
    /// Cleaned export.
    Export,
    /// HTML report.
    Report,
}

impl Stage {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Frames => "frames",
            Stage::Mask => "mask",
            Stage::Keyframes => "keyframes",
            Stage::Pose => "pose",
            Stage::Train => "train",
            Stage::Baseline => "baseline",
            Stage::Export => "export",
            Stage::Report => "report",
        }
    }
}

/// An input a stage reads: a file or a folder (every file below it).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Input {
    /// Compared by size and modification time.
    Stat(PathBuf),
    /// Compared by size and content hash (cheap: a video, an options file).
    Hashed(PathBuf),
}

/// One file as a stage saw it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FilePrint {
    pub path: PathBuf,
    pub size: u64,
    /// Nanoseconds since the Unix epoch.
    pub mtime_ns: u64,
    /// FNV-1a 64 of the content, hex, for hashed inputs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hash: Option<String>,
}

/// What a stage read and how it was configured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Fingerprint {
    pub version: String,
    /// The resolved options that affect the result.
    pub options: serde_json::Value,
    /// Every input file, sorted by path within each input.
    pub inputs: Vec<FilePrint>,
}

/// The file a stage writes after it succeeds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Manifest {
    pub stage: Stage,
    #[serde(flatten)]
    pub fingerprint: Fingerprint,
    /// Wall time of the stage, seconds.
    pub seconds: f64,
    /// The stage's typed result, serialised.
    pub result: serde_json::Value,
}

/// FNV-1a 64 of a file's bytes (streamed).
pub fn hash_file(path: &Path) -> Result<String> {
    use std::io::Read;
    let mut f =
        std::fs::File::open(path).with_context(|| format!("{}: cannot open", path.display()))?;
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = f
            .read(&mut buf)
            .with_context(|| format!("{}: cannot read", path.display()))?;
        if n == 0 {
            break;
        }
        for &b in &buf[..n] {
            h ^= b as u64;
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    Ok(format!("{h:016x}"))
}

fn stat(path: &Path) -> Result<(u64, u64)> {
    let m = std::fs::metadata(path).with_context(|| format!("{}: cannot stat", path.display()))?;
    let mtime = m
        .modified()
        .ok()
        .and_then(|t| t.duration_since(UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_nanos() as u64);
    Ok((m.len(), mtime))
}

/// Every file at or below `path`, sorted (a missing path has none).
fn files_below(path: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    let Ok(meta) = std::fs::metadata(path) else {
        return Ok(());
    };
    if meta.is_file() {
        out.push(path.to_path_buf());
        return Ok(());
    }
    let mut entries: Vec<PathBuf> = std::fs::read_dir(path)
        .with_context(|| format!("{}: cannot list", path.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    entries.sort();
    for e in entries {
        files_below(&e, out)?;
    }
    Ok(())
}

/// Fingerprint the inputs. Hashed files whose size and mtime match `prev`
/// reuse its hash.
pub fn fingerprint(
    inputs: &[Input],
    options: serde_json::Value,
    prev: Option<&Fingerprint>,
) -> Result<Fingerprint> {
    let mut prints = Vec::new();
    for input in inputs {
        let (root, hashed) = match input {
            Input::Stat(p) => (p, false),
            Input::Hashed(p) => (p, true),
        };
        let mut files = Vec::new();
        files_below(root, &mut files)?;
        for path in files {
            let (size, mtime_ns) = stat(&path)?;
            let hash = if hashed {
                let cached = prev.and_then(|f| {
                    f.inputs
                        .iter()
                        .find(|p| p.path == path && p.size == size && p.mtime_ns == mtime_ns)
                        .and_then(|p| p.hash.clone())
                });
                Some(match cached {
                    Some(h) => h,
                    None => hash_file(&path)?,
                })
            } else {
                None
            };
            prints.push(FilePrint {
                path,
                size,
                mtime_ns,
                hash,
            });
        }
    }
    // Through text and back, as the recorded options were: serde_json's
    // float parsing may differ from the in-memory value in the last bit.
    let options = serde_json::from_str(&serde_json::to_string(&options)?)?;
    Ok(Fingerprint {
        version: VERSION.to_string(),
        options,
        inputs: prints,
    })
}

/// Why `now` differs from the recorded fingerprint, or `None` when it matches.
/// Hashed files compare by size and hash only (their mtime may change).
pub fn difference(recorded: &Fingerprint, now: &Fingerprint) -> Option<String> {
    if recorded.version != now.version {
        return Some(format!("romosplat {} → {}", recorded.version, now.version));
    }
    if recorded.options != now.options {
        return Some("options changed".into());
    }
    if recorded.inputs.len() != now.inputs.len() {
        return Some(format!(
            "{} input files, {} before",
            now.inputs.len(),
            recorded.inputs.len()
        ));
    }
    for (a, b) in recorded.inputs.iter().zip(&now.inputs) {
        let same = a.path == b.path
            && a.size == b.size
            && match (&a.hash, &b.hash) {
                (Some(x), Some(y)) => x == y,
                (None, None) => a.mtime_ns == b.mtime_ns,
                _ => false,
            };
        if !same {
            return Some(format!("{} changed", b.path.display()));
        }
    }
    None
}

/// Where a stage's manifest lives under the run's output folder.
pub fn manifest_path(out: &Path, stage: Stage) -> PathBuf {
    out.join("manifests").join(format!("{}.json", stage.name()))
}

/// The recorded manifest, if one exists and parses.
pub fn read_manifest(out: &Path, stage: Stage) -> Option<Manifest> {
    let text = std::fs::read_to_string(manifest_path(out, stage)).ok()?;
    serde_json::from_str(&text).ok()
}

/// Record a finished stage (atomically).
pub fn write_manifest(out: &Path, m: &Manifest) -> Result<()> {
    let path = manifest_path(out, m.stage);
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    loader::io::write_bytes_atomic(&path, serde_json::to_string_pretty(m)?.as_bytes())?;
    Ok(())
}

/// Forget a stage (before it runs, so an interrupted stage is not fresh).
pub fn remove_manifest(out: &Path, stage: Stage) -> Result<()> {
    let path = manifest_path(out, stage);
    match std::fs::remove_file(&path) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(e).with_context(|| format!("removing {}", path.display())),
    }
}

/// Whether a stage must run, and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Decision {
    /// Up to date: the recorded manifest matches.
    Fresh,
    /// Must run, for this reason.
    Run(String),
}

/// Decide a stage: forced (`--from`, or an earlier stage ran), no manifest,
/// an output missing, or a fingerprint difference make it run.
pub fn decide(
    recorded: Option<&Manifest>,
    now: &Fingerprint,
    outputs: &[PathBuf],
    forced: Option<&str>,
) -> Decision {
    if let Some(why) = forced {
        return Decision::Run(why.to_string());
    }
    let Some(m) = recorded else {
        return Decision::Run("no record of an earlier run".into());
    };
    if let Some(missing) = outputs.iter().find(|p| !p.exists()) {
        return Decision::Run(format!("{} missing", missing.display()));
    }
    match difference(&m.fingerprint, now) {
        Some(why) => Decision::Run(why),
        None => Decision::Fresh,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_mtime::set_mtime;
    use serde_json::json;
    use std::time::{Duration, SystemTime};

    fn write(p: &Path, bytes: &[u8]) {
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, bytes).unwrap();
    }

    /// Record a stage as done now, as `run` does.
    fn record(out: &Path, inputs: &[Input], options: serde_json::Value) -> Fingerprint {
        let f = fingerprint(inputs, options, None).unwrap();
        write_manifest(
            out,
            &Manifest {
                stage: Stage::Mask,
                fingerprint: f.clone(),
                seconds: 1.0,
                result: json!({ "frames": 3 }),
            },
        )
        .unwrap();
        f
    }

    fn decision(out: &Path, inputs: &[Input], options: serde_json::Value) -> Decision {
        let rec = read_manifest(out, Stage::Mask);
        let now = fingerprint(inputs, options, rec.as_ref().map(|m| &m.fingerprint)).unwrap();
        decide(rec.as_ref(), &now, &[out.join("masks")], None)
    }

    #[test]
    fn fnv1a_known_answers() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("f");
        write(&p, b"");
        assert_eq!(hash_file(&p).unwrap(), "cbf29ce484222325");
        write(&p, b"a");
        assert_eq!(hash_file(&p).unwrap(), "af63dc4c8601ec8c");
        write(&p, b"foobar");
        assert_eq!(hash_file(&p).unwrap(), "85944171f73967e8");
    }

    #[test]
    fn each_kind_of_change_reruns_and_nothing_else_does() {
        let d = tempfile::tempdir().unwrap();
        let out = d.path().join("out");
        let images = d.path().join("images");
        let opts_file = d.path().join("romo.json");
        write(&images.join("a.png"), b"aaaa");
        write(&images.join("b.png"), b"bbbb");
        write(&opts_file, br#"{"iterations": 2}"#);
        std::fs::create_dir_all(out.join("masks")).unwrap();
        let inputs = [
            Input::Stat(images.clone()),
            Input::Hashed(opts_file.clone()),
        ];
        let options = json!({ "iterations": 2 });
        record(&out, &inputs, options.clone());
        assert_eq!(decision(&out, &inputs, options.clone()), Decision::Fresh);

        // An option.
        assert_eq!(
            decision(&out, &inputs, json!({ "iterations": 3 })),
            Decision::Run("options changed".into())
        );

        // The version.
        let mut m = read_manifest(&out, Stage::Mask).unwrap();
        m.fingerprint.version = "0.0.0-old".into();
        write_manifest(&out, &m).unwrap();
        assert!(
            matches!(decision(&out, &inputs, options.clone()), Decision::Run(w) if w.contains("0.0.0-old"))
        );
        record(&out, &inputs, options.clone());

        // A stat input: same bytes, new mtime → rerun.
        let later = SystemTime::now() + Duration::from_secs(5);
        set_mtime(&images.join("a.png"), later);
        assert!(
            matches!(decision(&out, &inputs, options.clone()), Decision::Run(w) if w.contains("a.png"))
        );
        record(&out, &inputs, options.clone());
        // A new input file.
        write(&images.join("c.png"), b"c");
        assert!(matches!(
            decision(&out, &inputs, options.clone()),
            Decision::Run(_)
        ));
        std::fs::remove_file(images.join("c.png")).unwrap();
        assert_eq!(decision(&out, &inputs, options.clone()), Decision::Fresh);

        // A hashed input touched without changing it: fresh.
        set_mtime(&opts_file, later + Duration::from_secs(5));
        assert_eq!(decision(&out, &inputs, options.clone()), Decision::Fresh);
        // Same size, different content: rerun.
        write(&opts_file, br#"{"iterations": 3}"#);
        assert!(
            matches!(decision(&out, &inputs, options.clone()), Decision::Run(w) if w.contains("romo.json"))
        );
        record(&out, &inputs, options.clone());

        // A missing output.
        std::fs::remove_dir(out.join("masks")).unwrap();
        assert!(
            matches!(decision(&out, &inputs, options.clone()), Decision::Run(w) if w.contains("missing"))
        );
        // No manifest.
        std::fs::create_dir_all(out.join("masks")).unwrap();
        remove_manifest(&out, Stage::Mask).unwrap();
        assert!(matches!(decision(&out, &inputs, options), Decision::Run(_)));
    }

    #[test]
    fn unchanged_stat_cache_reuses_the_hash() {
        let d = tempfile::tempdir().unwrap();
        let f = d.path().join("video.mp4");
        write(&f, b"0123456789");
        let first = fingerprint(&[Input::Hashed(f.clone())], json!(null), None).unwrap();
        // A forged recorded hash is kept while size and mtime match: the
        // file was not read again.
        let mut forged = first.clone();
        forged.inputs[0].hash = Some("feedfacefeedface".into());
        let again = fingerprint(&[Input::Hashed(f.clone())], json!(null), Some(&forged)).unwrap();
        assert_eq!(again.inputs[0].hash.as_deref(), Some("feedfacefeedface"));
        // After a touch the file is hashed again.
        set_mtime(&f, SystemTime::now() + Duration::from_secs(9));
        let touched = fingerprint(&[Input::Hashed(f)], json!(null), Some(&forged)).unwrap();
        assert_eq!(touched.inputs[0].hash, first.inputs[0].hash);
    }

    #[test]
    fn float_options_compare_equal_after_a_round_trip() {
        let d = tempfile::tempdir().unwrap();
        let out = d.path();
        std::fs::create_dir_all(out.join("masks")).unwrap();
        let opts = json!({ "lr": 1.6e-4_f32, "low_pass": 0.3_f32, "x": 0.1_f64 });
        record(out, &[], opts.clone());
        assert_eq!(decision(out, &[], opts), Decision::Fresh);
    }

    #[test]
    fn forced_runs_say_why() {
        let now = fingerprint(&[], json!(null), None).unwrap();
        assert_eq!(
            decide(None, &now, &[], Some("--from mask")),
            Decision::Run("--from mask".into())
        );
    }
}
