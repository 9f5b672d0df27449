//! Video → frames through an `ffmpeg` subprocess: the scene's `images/`
//! folder (`%05d.png`, sorted = capture order) from any video ffmpeg can
//! decode, optionally resampled to a frame rate.
//!
//! Frames are 8-bit RGB whatever the video's pixel format: a 10-bit video
//! (a phone's HDR HEVC) would otherwise give 16-bit PNGs, which COLMAP 3.8
//! cannot read (its feature extractor skips them with "Failed to read image
//! file format"). An HDR video (PQ or HLG transfer, as phones record) is
//! tone mapped to SDR BT.709 ([`Hdr`]): read as SDR its frames are washed
//! out and dim (BT.2020 colours taken for BT.709 ones). Without `fps`
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

/// SDR white in an HDR signal, nits (ITU-R BT.2408's HDR reference white):
/// it becomes the frames' white.
pub const HDR_REFERENCE_WHITE_NITS: f64 = 203.0;
/// Peak assumed when an HDR stream carries no light-level metadata, nits
/// (HLG's nominal display peak in ITU-R BT.2100, and HDR10's usual grade).
pub const HDR_DEFAULT_PEAK_NITS: f64 = 1000.0;

/// How an HDR video's frames were brought to 8-bit SDR.
#[derive(Debug, Clone, PartialEq)]
pub struct Hdr {
    /// `"PQ"` (SMPTE ST 2084: HDR10, Dolby Vision) or `"HLG"` (ARIB
    /// STD-B67).
    pub transfer: &'static str,
    /// Brightest level kept, nits: the stream's MaxCLL, else its mastering
    /// display's peak, else [`HDR_DEFAULT_PEAK_NITS`]; at least
    /// [`HDR_REFERENCE_WHITE_NITS`].
    pub peak_nits: f64,
    /// False when this ffmpeg has no `zscale` (libzimg) or `tonemap`
    /// filter: the frames were then converted as if SDR.
    pub tone_mapped: bool,
}

impl Hdr {
    /// One line for the user.
    pub fn describe(&self) -> String {
        if self.tone_mapped {
            format!(
                "HDR video ({}, peak {:.0} nits): tone mapped to SDR BT.709 (reference white {HDR_REFERENCE_WHITE_NITS:.0} nits as white, Möbius roll-off above)",
                self.transfer, self.peak_nits
            )
        } else {
            format!(
                "warning: HDR video ({}) but this ffmpeg has no zscale/tonemap filter (built without libzimg): frames converted without tone mapping, with washed-out colours",
                self.transfer
            )
        }
    }

    /// ffmpeg filters from the decoded HDR frames to SDR BT.709: linear
    /// light with the reference white at 1, BT.2020 → BT.709 primaries,
    /// ffmpeg's Möbius curve (linear below its knee, rolled off up to the
    /// peak; one curve for the whole video, so frames stay photometrically
    /// consistent), BT.709 transfer.
    fn filters(&self) -> String {
        format!(
            "zscale=t=linear:npl={w},format=gbrpf32le,zscale=p=bt709,tonemap=mobius:desat=0:peak={p:.4},zscale=t=bt709:m=bt709:r=tv,format=gbrp",
            w = HDR_REFERENCE_WHITE_NITS,
            p = self.peak_nits / HDR_REFERENCE_WHITE_NITS
        )
    }
}

/// What [`extract_frames`] wrote.
#[derive(Debug, Clone)]
pub struct Extraction {
    /// Frame paths in order.
    pub frames: Vec<PathBuf>,
    /// Set for an HDR video.
    pub hdr: Option<Hdr>,
}

/// Extract every frame (or `fps` frames per second) of `video` into
/// `out_dir/images/`. Frames are decoded into a temp folder next to it and
/// renamed into place when ffmpeg succeeds; an existing non-empty `images/`
/// is an error (never overwritten).
pub fn extract_frames(
    video: impl AsRef<Path>,
    out_dir: impl AsRef<Path>,
    fps: Option<f64>,
) -> Result<Extraction> {
    extract_frames_with("ffmpeg", video.as_ref(), out_dir.as_ref(), fps)
}

/// [`extract_frames`] with an explicit ffmpeg program (name or path).
pub fn extract_frames_with(
    program: &str,
    video: &Path,
    out_dir: &Path,
    fps: Option<f64>,
) -> Result<Extraction> {
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
    let hdr = hdr_of(program, video);
    let tmp = out_dir.join(format!(".images.tmp.{}", std::process::id()));
    std::fs::create_dir_all(&tmp).map_err(|e| LoaderError::io(&tmp, e))?;
    let tone_map = hdr.as_ref().filter(|h| h.tone_mapped).map(Hdr::filters);
    let result = run_ffmpeg(program, video, &tmp, fps, tone_map.as_deref());
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
        Ok(Extraction { frames: v, hdr })
    });
    if result.is_err() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
    result
}

fn run_ffmpeg(
    program: &str,
    video: &Path,
    out: &Path,
    fps: Option<f64>,
    tone_map: Option<&str>,
) -> Result<()> {
    let output = ffmpeg_frames(program, video, out, fps, tone_map, "-fps_mode")?;
    // ffmpeg before 5.1 has no -fps_mode; its -vsync (deprecated since)
    // takes the same value.
    let output = if !output.status.success()
        && String::from_utf8_lossy(&output.stderr).contains("Unrecognized option 'fps_mode'")
    {
        ffmpeg_frames(program, video, out, fps, tone_map, "-vsync")?
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
/// decoded frame once, through `sync_option` (`-fps_mode` or `-vsync`);
/// `tone_map` filters first when given.
fn ffmpeg_frames(
    program: &str,
    video: &Path,
    out: &Path,
    fps: Option<f64>,
    tone_map: Option<&str>,
    sync_option: &str,
) -> Result<std::process::Output> {
    let mut cmd = Command::new(program);
    cmd.args(QUIET).arg("-i").arg(video);
    let mut filters: Vec<String> = Vec::new();
    match fps {
        Some(f) => filters.push(format!("fps={f}")),
        None => {
            cmd.args([sync_option, "passthrough"]);
        }
    }
    filters.push(frame_filters(tone_map));
    cmd.arg("-vf").arg(filters.join(","));
    cmd.args(["-pix_fmt", "rgb24"]).arg(out.join(FRAME_PATTERN));
    cmd.output().map_err(|e| spawn_error(program, e))
}

/// ffmpeg options of every extraction: errors only, no prompt, overwrite.
const QUIET: [&str; 5] = ["-hide_banner", "-loglevel", "error", "-nostdin", "-y"];

/// The filters every extracted frame goes through after frame selection:
/// HDR tone mapping when given, then square pixels.
fn frame_filters(tone_map: Option<&str>) -> String {
    tone_map
        .into_iter()
        .chain([SQUARE_PIXELS])
        .collect::<Vec<_>>()
        .join(",")
}

fn spawn_error(program: &str, e: std::io::Error) -> LoaderError {
    if e.kind() == std::io::ErrorKind::NotFound {
        LoaderError::External(format!(
            "{program} not found on PATH; install it (Debian/Ubuntu: apt-get install -y ffmpeg)"
        ))
    } else {
        LoaderError::External(format!("could not run {program}: {e}"))
    }
}

/// The frames of `video` at `times` (seconds), decoded as
/// [`extract_frames_with`] decodes them (HDR tone-mapped, square pixels,
/// 8-bit RGB), as `out_dir/000.png`, `001.png`, … in the order of `times`.
pub fn extract_frames_at(
    program: &str,
    video: &Path,
    times: &[f64],
    out_dir: &Path,
) -> Result<Vec<PathBuf>> {
    if !video.is_file() {
        return Err(LoaderError::Missing {
            path: video.to_path_buf(),
            context: "video".into(),
        });
    }
    let hdr = hdr_of(program, video);
    let tone_map = hdr.as_ref().filter(|h| h.tone_mapped).map(Hdr::filters);
    let filters = frame_filters(tone_map.as_deref());
    times
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let out = out_dir.join(format!("{i:03}.png"));
            let output = Command::new(program)
                .args(QUIET)
                .args(["-ss", &format!("{t:.3}"), "-i"])
                .arg(video)
                .args(["-frames:v", "1", "-vf", &filters, "-pix_fmt", "rgb24"])
                .arg(&out)
                .output()
                .map_err(|e| spawn_error(program, e))?;
            if !output.status.success() || !out.is_file() {
                let err = String::from_utf8_lossy(&output.stderr);
                return Err(LoaderError::External(format!(
                    "{program} decoded no frame of {} at {t:.2} s: {}",
                    video.display(),
                    err.split_whitespace().collect::<Vec<_>>().join(" ")
                )));
            }
            Ok(out)
        })
        .collect()
}

/// `ffprobe` next to `program` (or on PATH) on the video's first stream
/// with `args`: its standard output, or `None` when it cannot run or fails.
fn ffprobe_text(program: &str, video: &Path, args: &[&str]) -> Option<String> {
    let probe = match program.strip_suffix("ffmpeg") {
        Some(prefix) => format!("{prefix}ffprobe"),
        None => "ffprobe".into(),
    };
    let out = Command::new(probe)
        .args(["-v", "error", "-select_streams", "v:0"])
        .args(args)
        .arg(video)
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The video's HDR transfer and peak from its first frame (`ffprobe`), and
/// whether `program` can tone map it; `None` for SDR, or when ffprobe is
/// missing (the frames are then converted as SDR).
fn hdr_of(program: &str, video: &Path) -> Option<Hdr> {
    let text = ffprobe_text(
        program,
        video,
        &[
            "-read_intervals",
            "%+#1",
            "-show_entries",
            "stream=color_transfer:frame=color_transfer:frame_side_data=max_content,max_luminance",
            "-of",
            "default=noprint_wrappers=1",
        ],
    )?;
    let (transfer, peak_nits) = parse_hdr(&text)?;
    Some(Hdr {
        transfer,
        peak_nits,
        tone_mapped: has_tone_mapping(program),
    })
}

/// HDR transfer and peak (nits) from ffprobe's `key=value` lines
/// (`color_transfer`, `max_content` = MaxCLL, `max_luminance` = the
/// mastering display's peak as a fraction); `None` for an SDR transfer.
fn parse_hdr(text: &str) -> Option<(&'static str, f64)> {
    let value = |key: &str| {
        text.lines()
            .filter_map(|l| l.trim().strip_prefix(key)?.strip_prefix('='))
            .map(str::trim)
            .collect::<Vec<_>>()
    };
    let transfer = value("color_transfer").into_iter().find_map(|t| match t {
        "smpte2084" => Some("PQ"),
        "arib-std-b67" => Some("HLG"),
        _ => None,
    })?;
    let number = |v: &str| ffprobe_ratio(v, '/');
    let peak = value("max_content")
        .into_iter()
        .find_map(number)
        .or_else(|| value("max_luminance").into_iter().find_map(number))
        .unwrap_or(HDR_DEFAULT_PEAK_NITS);
    Some((transfer, peak.max(HDR_REFERENCE_WHITE_NITS)))
}

/// True when `program` lists the `zscale` and `tonemap` filters.
fn has_tone_mapping(program: &str) -> bool {
    Command::new(program)
        .args(["-hide_banner", "-filters"])
        .output()
        .is_ok_and(|o| {
            let text = String::from_utf8_lossy(&o.stdout);
            let has = |name: &str| {
                text.lines()
                    .any(|l| l.split_whitespace().nth(1) == Some(name))
            };
            o.status.success() && has("zscale") && has("tonemap")
        })
}

/// The video's frame rate from `ffprobe` (next to `program`), or `None`
/// when ffprobe is missing or reports none (the check is then skipped and
/// ffmpeg has the last word).
fn video_frame_rate(program: &str, video: &Path) -> Option<f64> {
    let text = ffprobe_text(
        program,
        video,
        &[
            "-show_entries",
            "stream=avg_frame_rate,r_frame_rate",
            "-of",
            "default=noprint_wrappers=1:nokey=1",
        ],
    )?;
    // The larger of the average and the base rate: variable-rate videos
    // may legitimately be sampled up to their base rate.
    text.lines()
        .filter_map(|l| ffprobe_ratio(l, '/'))
        .reduce(f64::max)
}

/// A positive finite number as ffprobe prints one: `n`, or `n<sep>d` (a
/// frame rate `30000/1001`, an aspect ratio `4:3`); `None` otherwise
/// (`0/0`, `N/A`).
pub fn ffprobe_ratio(text: &str, sep: char) -> Option<f64> {
    let text = text.trim();
    let x = match text.split_once(sep) {
        Some((n, d)) => n.trim().parse::<f64>().ok()? / d.trim().parse::<f64>().ok()?,
        None => text.parse::<f64>().ok()?,
    };
    (x.is_finite() && x > 0.0).then_some(x)
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
        let e = extract_frames(&v, &out, None).unwrap();
        assert_eq!(e.hdr, None);
        let frames = e.frames;
        assert_eq!(frames.len(), 10);
        assert_eq!(frames[0], out.join("images/00001.png"));
        assert_eq!(image::image_dimensions(&frames[9]).unwrap(), (64, 48));
        let frames = extract_frames(&v, dir.path().join("slow"), Some(5.0))
            .unwrap()
            .frames;
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
        let frames = extract_frames(&v, dir.path().join("deep"), None)
            .unwrap()
            .frames;
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
            let frames = extract_frames(&v, dir.path().join(name), fps)
                .unwrap()
                .frames;
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
        let frames = extract_frames(&v, dir.path().join("vfr"), None)
            .unwrap()
            .frames;
        assert_eq!(frames.len(), 10);
        // An ffmpeg older than 5.1 refuses -fps_mode; -vsync does the same.
        let old = stand_in(
            dir.path(),
            "for a in \"$@\"; do [ \"$a\" = -fps_mode ] && { echo \"Unrecognized option 'fps_mode'.\" >&2; exit 1; }; done",
        );
        let frames = extract_frames_with(old.to_str().unwrap(), &v, &dir.path().join("old"), None)
            .unwrap()
            .frames;
        assert_eq!(frames.len(), 10);
    }

    /// An executable `dir/ffmpeg` that runs `script` (sh), then the real
    /// ffmpeg with the same arguments; the real ffprobe beside it.
    fn stand_in(dir: &Path, script: &str) -> PathBuf {
        let path = dir.join("ffmpeg");
        let probe = dir.join("ffprobe");
        if !probe.exists() {
            std::fs::write(&probe, "#!/bin/sh\nexec ffprobe \"$@\"\n").unwrap();
            #[cfg(unix)]
            {
                use std::os::unix::fs::PermissionsExt;
                std::fs::set_permissions(&probe, std::fs::Permissions::from_mode(0o755)).unwrap();
            }
        }
        std::fs::write(&path, format!("#!/bin/sh\n{script}\nexec ffmpeg \"$@\"\n")).unwrap();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
        }
        path
    }

    /// Mean absolute difference of two folders' frames, in 8-bit levels.
    fn frame_difference(a: &[PathBuf], b: &[PathBuf]) -> f64 {
        assert_eq!(a.len(), b.len());
        let (mut sum, mut n) = (0f64, 0usize);
        for (x, y) in a.iter().zip(b) {
            let (x, y) = (
                image::open(x).unwrap().to_rgb8(),
                image::open(y).unwrap().to_rgb8(),
            );
            assert_eq!(x.dimensions(), y.dimensions());
            for (p, q) in x.as_raw().iter().zip(y.as_raw()) {
                sum += (f64::from(*p) - f64::from(*q)).abs();
                n += 1;
            }
        }
        sum / n as f64
    }

    /// A real PQ and a real HLG video, made from an SDR source with SDR
    /// white at the reference white (as BT.2408 grades it), come back close
    /// to the source; read as SDR (an ffmpeg without zscale) they do not.
    #[test]
    fn hdr_videos_are_tone_mapped_back_to_their_sdr_source() {
        if !need_ffmpeg() {
            return;
        }
        if !has_tone_mapping("ffmpeg") {
            assert!(
                std::env::var_os("CI").is_none(),
                "CI is set but ffmpeg has no zscale/tonemap filter"
            );
            eprintln!("skipping: ffmpeg without zscale");
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let source =
            "testsrc2=size=64x48:rate=10:duration=1,zscale=tin=bt709:min=bt709:pin=bt709:rin=pc";
        // The SDR reference through the same 10-bit 4:4:4 YUV stage.
        let sdr = make_video_as(
            dir.path(),
            "sdr.mkv",
            &format!("{source}:t=bt709:m=bt709:p=bt709:r=tv,format=yuv444p10le"),
            &[],
        );
        let sdr = extract_frames(&sdr, dir.path().join("sdr"), None)
            .unwrap()
            .frames;
        for (trc, name) in [("smpte2084", "PQ"), ("arib-std-b67", "HLG")] {
            let v = make_video_as(
                dir.path(),
                &format!("{trc}.mkv"),
                &format!(
                    "{source}:t={trc}:m=bt2020nc:p=bt2020:r=tv:npl={HDR_REFERENCE_WHITE_NITS},format=yuv444p10le"
                ),
                &[
                    "-color_trc",
                    trc,
                    "-color_primaries",
                    "bt2020",
                    "-colorspace",
                    "bt2020nc",
                    "-color_range",
                    "tv",
                ],
            );
            let e = extract_frames(&v, dir.path().join(trc), None).unwrap();
            let hdr = e.hdr.clone().unwrap();
            assert_eq!(
                (hdr.transfer, hdr.peak_nits, hdr.tone_mapped),
                (name, HDR_DEFAULT_PEAK_NITS, true)
            );
            let mapped = frame_difference(&sdr, &e.frames);
            // An ffmpeg that lists no zscale: converted as SDR, and said so.
            let plain = stand_in(
                dir.path(),
                "[ \"$2\" = -filters ] && { echo ' ... scale V->V Scale'; exit 0; }",
            );
            let e = extract_frames_with(
                plain.to_str().unwrap(),
                &v,
                &dir.path().join(format!("{trc}-plain")),
                None,
            )
            .unwrap();
            let hdr = e.hdr.unwrap();
            assert!(!hdr.tone_mapped && hdr.describe().contains("without tone mapping"));
            let unmapped = frame_difference(&sdr, &e.frames);
            assert!(
                mapped < 12.0 && unmapped > 2.0 * mapped,
                "{trc}: tone mapped {mapped:.1}, as SDR {unmapped:.1} levels off the source"
            );
        }
    }

    /// Peaks from light-level metadata, as ffprobe prints them.
    #[test]
    fn ffprobe_ratios() {
        assert_eq!(ffprobe_ratio("30000/1001", '/'), Some(30000.0 / 1001.0));
        assert_eq!(ffprobe_ratio(" 4:3 ", ':'), Some(4.0 / 3.0));
        assert_eq!(ffprobe_ratio("1600", '/'), Some(1600.0));
        for bad in ["0/0", "0:1", "N/A", "", "-1/2", "1/0"] {
            assert_eq!(
                ffprobe_ratio(bad, if bad.contains(':') { ':' } else { '/' }),
                None,
                "{bad}"
            );
        }
    }

    #[test]
    fn hdr_peak_is_read_from_the_stream_metadata() {
        let probe = "color_transfer=smpte2084\nmax_luminance=40000000/10000\nmax_content=1600\ncolor_transfer=smpte2084\n";
        assert_eq!(parse_hdr(probe), Some(("PQ", 1600.0)));
        let probe = "color_transfer=smpte2084\nmax_luminance=40000000/10000\nmax_content=0\n";
        assert_eq!(parse_hdr(probe), Some(("PQ", 4000.0)));
        // No metadata: the default; a peak below reference white is raised to it.
        assert_eq!(
            parse_hdr("color_transfer=arib-std-b67\n"),
            Some(("HLG", HDR_DEFAULT_PEAK_NITS))
        );
        assert_eq!(
            parse_hdr("color_transfer=smpte2084\nmax_content=100\n"),
            Some(("PQ", HDR_REFERENCE_WHITE_NITS))
        );
        assert_eq!(
            parse_hdr("color_transfer=bt709\ncolor_transfer=bt709\n"),
            None
        );
        assert_eq!(parse_hdr("color_transfer=unknown\n"), None);
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
