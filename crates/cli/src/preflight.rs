//! Preflight for `romosplat run`: before stage 1, check everything a later
//! stage needs — the input, ffmpeg for a video, colmap unless the scene's
//! poses are kept, a wgpu adapter (or say that the CPU backend will train),
//! free disk space for the planned outputs — and reject contradictory flags.
//! Every problem is one line; all of them are reported at once.

use crate::cmd::train::BackendKind;
use std::path::{Path, PathBuf};
use std::process::Command;

/// What preflight found.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Preflight {
    /// Each one stops the run before stage 1.
    pub problems: Vec<String>,
    /// Worth saying before the run starts (backend choice, disk estimate).
    pub notes: Vec<String>,
}

/// What preflight needs to know about the run.
#[derive(Debug, Clone)]
pub struct Request<'a> {
    pub video: Option<&'a Path>,
    pub scene: Option<&'a Path>,
    pub out: &'a Path,
    pub fps: Option<f64>,
    pub ffmpeg: &'a Path,
    pub colmap: &'a Path,
    pub keep_poses: bool,
    pub no_masks: bool,
    pub mask_options: Option<&'a Path>,
    /// `--from` stage name, if any.
    pub from: Option<&'a str>,
    /// Training backend.
    pub backend: BackendKind,
    /// Most splats training may make (for the disk estimate).
    pub max_splats: usize,
}

/// Flags that contradict each other, one line each.
pub fn contradictions(r: &Request) -> Vec<String> {
    let mut p = Vec::new();
    if r.video.is_some() && r.keep_poses {
        p.push("--keep-poses needs --scene: a video has no poses to keep".to_string());
    }
    if r.scene.is_some() && r.fps.is_some() {
        p.push(
            "--fps applies to --video only (a scene folder's frames are used as they are)".into(),
        );
    }
    if r.no_masks && r.mask_options.is_some() {
        p.push("--mask-options with --no-masks: no masks are computed".into());
    }
    if r.no_masks && r.from == Some("mask") {
        p.push("--from mask with --no-masks: the mask stage does not run".into());
    }
    if r.keep_poses && r.from == Some("pose") {
        p.push("--from pose with --keep-poses: the pose stage does not run".into());
    }
    p
}

/// `program arg` runs and exits 0.
fn runs(program: &Path, arg: &str) -> bool {
    Command::new(program)
        .arg(arg)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// Bytes free on the file system holding `dir` (its nearest existing
/// ancestor), from POSIX `df -Pk`.
pub fn free_bytes(dir: &Path) -> Option<u64> {
    let mut d = dir.to_path_buf();
    while !d.exists() {
        d = d.parent()?.to_path_buf();
        if d.as_os_str().is_empty() {
            d = PathBuf::from(".");
        }
    }
    let out = Command::new("df").arg("-Pk").arg(&d).output().ok()?;
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().nth(1)?;
    let avail_kb: u64 = line.split_whitespace().nth(3)?.parse().ok()?;
    Some(avail_kb * 1024)
}

/// Bytes of every file below `dir`.
fn dir_bytes(dir: &Path) -> u64 {
    std::fs::read_dir(dir)
        .map(|rd| {
            rd.flatten()
                .filter_map(|e| e.metadata().ok())
                .filter(|m| m.is_file())
                .map(|m| m.len())
                .sum()
        })
        .unwrap_or(0)
}

/// Rough bytes the run will write: the frames as PNG (about half of RGB8),
/// COLMAP's undistorted copy of them, masks, renders, and the splats
/// (≤ 248 bytes each at SH degree 3) as PLY, checkpoint and export.
pub fn planned_bytes(r: &Request) -> u64 {
    let frames = match (r.video, r.scene) {
        (Some(v), _) => match crate::plan::probe_video(r.ffmpeg, v) {
            Ok(i) => u64::from(i.width) * u64::from(i.height) * 3 / 2 * i.frames as u64,
            // Decoded frames are tens of times the size of a compressed video.
            Err(_) => std::fs::metadata(v).map_or(0, |m| m.len() * 30),
        },
        // A scene's frames are linked, not copied; the undistorted copy is made.
        (None, Some(s)) => dir_bytes(&s.join("images")),
        _ => 0,
    };
    let copies = if r.keep_poses { 1 } else { 2 };
    frames * copies + frames / 4 + 4 * 248 * r.max_splats as u64
}

/// Whether a wgpu adapter exists, and why not.
fn wgpu_adapter() -> Result<String, String> {
    splat::gpu::context::GpuContext::new(&splat::gpu::context::GpuOptions::default())
        .map(|c| format!("{c:?}"))
        .map_err(|e| e.to_string())
}

/// Run every check.
pub fn check(r: &Request) -> Preflight {
    let mut pf = Preflight {
        problems: contradictions(r),
        notes: Vec::new(),
    };
    if let Some(v) = r.video {
        if !v.is_file() {
            pf.problems
                .push(format!("{}: video not found", v.display()));
        }
        if !runs(r.ffmpeg, "-version") {
            pf.problems.push(format!(
                "ffmpeg (`{}`) does not run: install it (apt-get install ffmpeg) or pass --ffmpeg PATH",
                r.ffmpeg.display()
            ));
        }
    }
    if let Some(s) = r.scene {
        if !s.join("images").is_dir() {
            pf.problems
                .push(format!("{}: no images/ folder", s.display()));
        } else if r.keep_poses
            && !s.join("sparse/0").is_dir()
            && !s.join("transforms.json").is_file()
        {
            pf.problems.push(format!(
                "{}: --keep-poses but the scene has neither sparse/0 nor transforms.json",
                s.display()
            ));
        }
    }
    if let Some(m) = r.mask_options
        && !m.is_file()
    {
        pf.problems
            .push(format!("{}: mask options file not found", m.display()));
    }
    if !r.keep_poses && !runs(r.colmap, "-h") {
        pf.problems.push(format!(
            "colmap (`{}`) does not run: install it (apt-get install colmap), pass --colmap PATH, or --keep-poses with a posed scene",
            r.colmap.display()
        ));
    }
    match r.backend {
        BackendKind::Cpu => pf.notes.push(format!(
            "training on the CPU reference backend ({} threads); wgpu on Mesa's lavapipe is as fast on small scenes and faster with many splats",
            rayon::current_num_threads()
        )),
        backend => match wgpu_adapter() {
            Ok(_) => {}
            Err(e) if backend == BackendKind::Wgpu => {
                pf.problems.push(format!("--backend wgpu: no usable adapter ({e})"))
            }
            Err(e) => pf.notes.push(format!(
                "no usable wgpu adapter ({e}): training uses the CPU reference backend ({} threads), as fast as lavapipe on small scenes and slower with many splats",
                rayon::current_num_threads()
            )),
        },
    }
    let need = planned_bytes(r);
    if let Some(free) = free_bytes(r.out) {
        let gb = |b: u64| b as f64 / 1e9;
        if free < need {
            pf.problems.push(format!(
                "{}: {:.1} GB free, the run needs about {:.1} GB",
                r.out.display(),
                gb(free),
                gb(need)
            ));
        }
    }
    pf
}

/// Check everything the stages need before stage 1; every problem is one line.
pub fn for_run(args: &crate::cmd::run::Args, ctx: &crate::Ctx) -> anyhow::Result<()> {
    let steps = args.steps.unwrap_or(crate::plan::MAX_STEPS as u32);
    let max_splats = crate::cmd::train_common::short_schedule(steps, true)
        .strategy
        .max_splats;
    let pf = check(&Request {
        video: args.input.video.as_deref(),
        scene: args.input.scene.as_deref(),
        out: &args.out,
        fps: args.fps,
        ffmpeg: &args.ffmpeg,
        colmap: args
            .pose
            .colmap
            .as_deref()
            .unwrap_or(std::path::Path::new("colmap")),
        keep_poses: args.keep_poses,
        no_masks: args.no_masks,
        mask_options: args.mask_options.as_deref(),
        from: args.from.map(crate::pipeline::Stage::name),
        backend: args.backend,
        max_splats,
    });
    for n in &pf.notes {
        ctx.info(format!("preflight: {n}"));
    }
    match pf.problems.len() {
        0 => Ok(()),
        1 => anyhow::bail!("{}", pf.problems[0]),
        n => anyhow::bail!(
            "{n} problems before the run:\n  {}",
            pf.problems.join("\n  ")
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request<'a>(out: &'a Path) -> Request<'a> {
        Request {
            video: None,
            scene: None,
            out,
            fps: None,
            ffmpeg: Path::new("ffmpeg"),
            colmap: Path::new("colmap"),
            keep_poses: false,
            no_masks: false,
            mask_options: None,
            from: None,
            backend: BackendKind::Cpu,
            max_splats: 1000,
        }
    }

    #[test]
    fn contradictory_flags_are_one_line_each() {
        let out = Path::new("/tmp/x");
        let mut r = request(out);
        assert!(contradictions(&r).is_empty());
        r.video = Some(Path::new("a.mp4"));
        r.keep_poses = true;
        r.no_masks = true;
        r.mask_options = Some(Path::new("romo.json"));
        r.from = Some("pose");
        let p = contradictions(&r);
        assert_eq!(p.len(), 3, "{p:?}");
        assert!(p[0].contains("--keep-poses needs --scene"));
        assert!(p.iter().all(|l| !l.contains('\n')));
        let mut s = request(out);
        s.scene = Some(Path::new("scene"));
        s.fps = Some(5.0);
        assert_eq!(contradictions(&s).len(), 1);
    }

    #[test]
    fn missing_tools_are_named() {
        let d = std::env::temp_dir();
        let mut r = request(&d);
        r.video = Some(Path::new("/nonexistent/v.mp4"));
        r.ffmpeg = Path::new("/nonexistent/ffmpeg");
        r.colmap = Path::new("/nonexistent/colmap");
        let pf = check(&r);
        assert!(
            pf.problems
                .iter()
                .any(|l| l.contains("v.mp4: video not found"))
        );
        assert!(
            pf.problems
                .iter()
                .any(|l| l.starts_with("ffmpeg (`/nonexistent/ffmpeg`)"))
        );
        assert!(
            pf.problems
                .iter()
                .any(|l| l.starts_with("colmap (`/nonexistent/colmap`)"))
        );
        // --keep-poses needs no colmap.
        r.keep_poses = true;
        r.video = None;
        assert!(!check(&r).problems.iter().any(|l| l.contains("colmap")));
    }

    #[test]
    fn free_space_of_a_missing_folder_is_its_parents() {
        let d = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let free = free_bytes(&d.path().join("not/yet/made"));
        assert!(free.is_some_and(|b| b > 0));
    }
}
