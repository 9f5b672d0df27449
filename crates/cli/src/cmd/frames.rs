//! `romosplat frames --video FILE --out DIR [--fps N]`: extract a video's
//! frames into `DIR/images/%05d.png` with ffmpeg (see `loader::video`).

use crate::Ctx;
use std::path::PathBuf;

/// `romosplat frames --video FILE --out DIR [--fps N]`
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Input video (anything ffmpeg decodes).
    #[arg(long)]
    pub video: PathBuf,
    /// Scene folder to create; frames go to OUT/images/.
    #[arg(long)]
    pub out: PathBuf,
    /// Resample to this many frames per second (default: every frame).
    #[arg(long)]
    pub fps: Option<f64>,
}

/// Run `romosplat frames`.
pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    ctx.info(format!("extracting frames of {} ...", args.video.display()));
    let extraction = loader::video::extract_frames(&args.video, &args.out, args.fps)?;
    if let Some(hdr) = &extraction.hdr {
        ctx.info(hdr.describe());
    }
    let frames = extraction.frames;
    let images = args.out.join("images");
    ctx.info(format!(
        "{} frames written to {}",
        frames.len(),
        images.display()
    ));
    Ok(serde_json::json!({
        "video": args.video,
        "images_dir": images,
        "frames": frames.len(),
        "fps": args.fps,
        "hdr": extraction.hdr.as_ref().map(|h| serde_json::json!({
            "transfer": h.transfer,
            "peak_nits": h.peak_nits,
            "tone_mapped": h.tone_mapped,
        })),
        "first": frames.first(),
        "last": frames.last(),
    }))
}
