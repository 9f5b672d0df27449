//! Video → frames through an `ffmpeg` subprocess: the scene's `images/`
//! folder (`%05d.png`, sorted = capture order) from any video ffmpeg can
//! decode, optionally resampled to a frame rate.
//!
//! Frames are 8-bit RGB whatever the video's pixel format: a 10-bit video
//! (a phone's HDR HEVC) would otherwise give 16-bit PNGs, which COLMAP 3.8
//! cannot read (its feature extractor skips them with "Failed to read image
//! file format"); HDR values are converted, not tone mapped. Without `fps`
//! every decoded frame is written once (`-fps_mode passthrough`, `-vsync
//! passthrough` on an ffmpeg before 5.1): a phone's variable-frame-rate
//! video would otherwise get duplicated frames wherever its frame interval
//! grows. Anamorphic frames are widened to square pixels.

use crate::error::{LoaderError, Result};
use std::path::{Path, PathBuf};
use std::process::Command;

/// Frames are written as `out_dir/images/%05d.png`, numbered from 00001.
pub const FRAME_PATTERN: &str = "%05d.png";

/// ffmpeg filters that widen an anamorphic video's frames to square pixels
/// (width × sample aspect ratio; a no-op at 1:1 or an unknown ratio): the
/// pose stage's camera models have one focal length for both axes.
const SQUARE_PIXELS: &str = "scale='if(gt(sar,0)*not(eq(sar,1)),round(iw*sar),iw)':ih,setsar=1";

/// Extract every frame (or `fps` frames per second) of `video` into
/// `out_dir/images/`. Frames are decoded into a temp folder next to it and
/// renamed into place when ffmpeg succeeds; an existing non-empty `images/`
/// is an error (never overwritten). Returns the frame paths in order.
pub fn extract_frames(
    video: impl AsRef<Path>,
    out_dir: impl AsRef<Path>,
    fps: Option<f64>,
) -> Result<Vec<PathBuf>> {
    extract_frames_with("ffmpeg", video.as_ref(), out_dir.as_ref(), fps)
}

/// [`extract_frames`] with an explicit ffmpeg program (name or path).
pub fn extract_frames_with(
    program: &str,
    video: &Path,
    out_dir: &Path,
    fps: Option<f64>,
) -> Result<Vec<PathBuf>> {
    if let Some(f) = fps
        && !(f.is_finite() && f > 0.0)
    {
        return Err(LoaderError::Invalid(format!(
            "fps must be a positive number, got {f}"
        )));
    }
    if !video.is_file() {
        return Err(LoaderError::Missing {
            path: video.to_path_buf(),
            context: "video".into(),
        });
    }
    if let (Some(f), Some(rate)) = (fps, video_frame_rate(program, video)) {
        // Asking for more frames per second than the video has would only
        // duplicate frames (ffmpeg's fps filter repeats them).
        if f > rate * (1.0 + 1e-6) {
            return Err(LoaderError::Invalid(format!(
                "--fps {f} is above the frame rate of {} ({rate:.3} fps); use 0 < fps <= {rate:.3}",
                video.display()
            )));
        }
    }
    let images = out_dir.join("images");
    if images.is_dir()
        && std::fs::read_dir(&images)
            .map(|mut d| d.next().is_some())
            .unwrap_or(false)
    {
        return Err(LoaderError::format(
            &images,
            "already exists and is not empty; choose another --out",
        ));
    }
    let tmp = out_dir.join(format!(".images.tmp.{}", std::process::id()));
    std::fs::create_dir_all(&tmp).map_err(|e| LoaderError::io(&tmp, e))?;
    let result = run_ffmpeg(program, video, &tmp, fps);
    let result = result.and_then(|()| {
        if images.is_dir() {
            std::fs::remove_dir(&images).map_err(|e| LoaderError::io(&images, e))?;
        }
        std::fs::rename(&tmp, &images).map_err(|e| LoaderError::io(&images, e))?;
        let mut v: Vec<PathBuf> = std::fs::read_dir(&images)
            .map_err(|e| LoaderError::io(&images, e))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "png"))
            .collect();
        v.sort();
        if v.is_empty() {
            return Err(LoaderError::format(video, "ffmpeg produced no frames"));
        }
        Ok(v)
    });
    if result.is_err() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
    result
}

fn run_ffmpeg(program: &str, video: &Path, out: &Path, fps: Option<f64>) -> Result<()> {
    let output = ffmpeg_frames(program, video, out, fps, "-fps_mode")?;
    // ffmpeg before 5.1 has no -fps_mode; its -vsync (deprecated since)
    // takes the same value.
    let output = if !output.status.success()
        && String::from_utf8_lossy(&output.stderr).contains("Unrecognized option 'fps_mode'")
    {
        ffmpeg_frames(program, video, out, fps, "-vsync")?
    } else {
        output
    };
    if !output.status.success() {
        let err = String::from_utf8_lossy(&output.stderr);
        let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
        let tail = lines[lines.len().saturating_sub(5)..].join(" | ");
        return Err(LoaderError::External(format!(
            "{program} failed on {} ({}): {tail}",
            video.display(),
            output.status
        )));
    }
    Ok(())
}

/// One ffmpeg run writing `video`'s frames into `out`; without `fps` each
/// decoded frame once, through `sync_option` (`-fps_mode` or `-vsync`).
fn ffmpeg_frames(
    program: &str,
    video: &Path,
    out: &Path,
    fps: Option<f64>,
    sync_option: &str,
) -> Result<std::process::Output> {
    let mut cmd = Command::new(program);
    cmd.args(["-hide_banner", "-loglevel", "error", "-nostdin", "-y", "-i"])
        .arg(video);
    let filters = match fps {
        Some(f) => format!("fps={f},{SQUARE_PIXELS}"),
        None => {
            cmd.args([sync_option, "passthrough"]);
            SQUARE_PIXELS.to_string()
        }
    };
    cmd.arg("-vf").arg(filters);
    cmd.args(["-pix_fmt", "rgb24"]).arg(out.join(FRAME_PATTERN));
    cmd.output().map_err(|e| {
        if e.kind() == std::io::ErrorKind::NotFound {
            LoaderError::External(format!(
                "{program} not found on PATH; install it (Debian/Ubuntu: apt-get install -y ffmpeg)"
            ))
        } else {
            LoaderError::External(format!("could not run {program}: {e}"))
        }
    })
}

/// The video's frame rate from `ffprobe` (next to `program`), or `None`
/// when ffprobe is missing or reports none (the check is then skipped and
/// ffmpeg has the last word).
fn video_frame_rate(program: &str, video: &Path) -> Option<f64> {
    let probe = match program.strip_suffix("ffmpeg") {
        Some(prefix) => format!("{prefix}ffprobe"),
        None => "ffprobe".into(),
    };
    let out = Command::new(probe)
        .args(["-v", "error", "-select_streams", "v:0"])
        .args(["-show_entries", "stream=avg_frame_rate,r_frame_rate"])
        .args(["-of", "default=noprint_wrappers=1:nokey=1"])
        .arg(video)
        .output()
        .ok()?;
    if !out.status.success() {
        return None;
    }
    // The larger of the average and the base rate: variable-rate videos
    // may legitimately be sampled up to their base rate.
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| {
            let (n, d) = l.trim().split_once('/')?;
            let (n, d) = (n.parse::<f64>().ok()?, d.parse::<f64>().ok()?);
            (n > 0.0 && d > 0.0).then_some(n / d)
        })
        .reduce(f64::max)
}

/// True when `ffmpeg -version` runs.
pub fn ffmpeg_available() -> bool {
    Command::new("ffmpeg")
        .arg("-version")
        .output()
        .is_ok_and(|o| o.status.success())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Skip only when ffmpeg is absent and `CI` is unset; under CI it must exist.
    fn need_ffmpeg() -> bool {
        if ffmpeg_available() {
            return true;
        }
        assert!(
            std::env::var_os("CI").is_none(),
            "CI is set but ffmpeg is missing (apt-get install -y ffmpeg)"
        );
        eprintln!("skipping: ffmpeg not installed");
        false
    }

    fn make_video(dir: &Path) -> PathBuf {
        make_video_as(dir, "test.mkv", "testsrc=size=64x48:rate=10", &[])
    }

    /// `source` (an ffmpeg lavfi graph) encoded with FFV1 into `dir/name`,
    /// `extra` arguments before the output.
    fn make_video_as(dir: &Path, name: &str, source: &str, extra: &[&str]) -> PathBuf {
        let v = dir.join(name);
        let st = Command::new("ffmpeg")
            .args([
                "-hide_banner",
                "-loglevel",
                "error",
                "-nostdin",
                "-y",
                "-f",
                "lavfi",
                "-i",
            ])
            .arg(source)
            .args(["-t", "1", "-c:v", "ffv1"])
            .args(extra)
            .arg(&v)
            .status()
            .unwrap();
        assert!(st.success());
        v
    }

    #[test]
    fn extracts_all_frames_and_resampled() {
        if !need_ffmpeg() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let v = make_video(dir.path());
        let out = dir.path().join("all");
        let frames = extract_frames(&v, &out, None).unwrap();
        assert_eq!(frames.len(), 10);
        assert_eq!(frames[0], out.join("images/00001.png"));
        assert_eq!(image::image_dimensions(&frames[9]).unwrap(), (64, 48));
        let frames = extract_frames(&v, dir.path().join("slow"), Some(5.0)).unwrap();
        assert_eq!(frames.len(), 5);
        // Above the video's 10 fps: refused with the range, nothing written.
        let e = extract_frames(&v, dir.path().join("fast"), Some(1000.0))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("--fps 1000") && e.contains("fps <= 10.000"),
            "{e}"
        );
        assert!(!dir.path().join("fast").exists());
        // A second run into the same folder refuses to overwrite.
        let e = extract_frames(&v, &out, None).unwrap_err().to_string();
        assert!(e.contains("images") && e.contains("not empty"), "{e}");
    }

    /// A 16-bit video gives 8-bit RGB frames (COLMAP reads no others), an
    /// anamorphic one square pixels, and a variable-frame-rate video one
    /// frame per decoded frame.
    #[test]
    fn deep_anamorphic_and_variable_rate_videos_give_one_8_bit_square_frame_per_frame() {
        if !need_ffmpeg() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let v = make_video_as(
            dir.path(),
            "deep.mkv",
            "testsrc=size=64x48:rate=10",
            &["-pix_fmt", "rgb48le"],
        );
        let frames = extract_frames(&v, dir.path().join("deep"), None).unwrap();
        assert_eq!(frames.len(), 10);
        let img = image::open(&frames[3]).unwrap();
        assert_eq!(img.color(), image::ColorType::Rgb8);
        // Anamorphic (4:3 pixels): widened to square pixels, at every rate.
        let v = make_video_as(
            dir.path(),
            "ana.mkv",
            "testsrc=size=60x48:rate=10,setsar=4/3",
            &[],
        );
        for (name, fps) in [("ana", None), ("ana5", Some(5.0))] {
            let frames = extract_frames(&v, dir.path().join(name), fps).unwrap();
            assert_eq!(image::image_dimensions(&frames[0]).unwrap(), (80, 48));
        }
        // Frames 5–9 a second later than their place at 10 fps: 10 frames
        // over 1.9 s, which a constant-rate output pads to 20.
        let v = make_video_as(
            dir.path(),
            "vfr.mkv",
            "testsrc=size=64x48:rate=10:duration=1,setpts='if(lt(N,5),PTS,PTS+1/TB)'",
            &["-t", "3", "-fps_mode", "passthrough"],
        );
        let frames = extract_frames(&v, dir.path().join("vfr"), None).unwrap();
        assert_eq!(frames.len(), 10);
        // An ffmpeg older than 5.1 refuses -fps_mode; -vsync does the same.
        let old = dir.path().join("ffmpeg");
        std::fs::write(
            &old,
            "#!/bin/sh\nfor a in \"$@\"; do [ \"$a\" = -fps_mode ] && { echo \"Unrecognized option 'fps_mode'.\" >&2; exit 1; }; done\nexec ffmpeg \"$@\"\n",
        )
        .unwrap();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&old, std::fs::Permissions::from_mode(0o755)).unwrap();
        }
        let frames =
            extract_frames_with(old.to_str().unwrap(), &v, &dir.path().join("old"), None).unwrap();
        assert_eq!(frames.len(), 10);
    }

    #[test]
    fn failures_are_explained() {
        let dir = tempfile::tempdir().unwrap();
        let v = dir.path().join("v.mp4");
        std::fs::write(&v, b"this is not a video").unwrap();
        let e = extract_frames_with("ffmpeg-definitely-missing", &v, dir.path(), None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("apt-get install -y ffmpeg"), "{e}");
        let e = extract_frames(dir.path().join("none.mp4"), dir.path(), None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("none.mp4") && e.contains("not found"), "{e}");
        assert!(extract_frames(&v, dir.path(), Some(0.0)).is_err());
        if need_ffmpeg() {
            let e = extract_frames(&v, dir.path().join("o"), None)
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("ffmpeg failed") && e.contains("v.mp4") && e.contains("exit status"),
                "{e}"
            );
            assert!(!dir.path().join("o/images").exists());
        }
    }
}
