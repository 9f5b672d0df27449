//! Measurement (not a test): per-stage diagnosis of RoMo on DAVIS-2016.
//! For each sequence: how much of U lies inside the ground-truth object
//! (U precision) and how much of the object it covers (U recall), how much
//! of L lies inside the object (L error), the MLP output on the grid
//! (J / precision / recall at the threshold) and after refinement to full
//! resolution. Env as in the `davis` example (`DAVIS_DIR`, default
//! `../shared/data/davis2016` beside the repository; `ROMO_OPTS`; `SEQS`),
//! plus `MAXF` (first N frames only), `FRAME_STEP` (every N-th frame) and
//! `DUMP` (a folder for frame | U/L | probability | truth images) and `RAW`
//! (a folder for every frame's grid channels as raw f32, see [`raw`]). Any
//! folder with `JPEGImages/480p/<seq>/` and `Annotations/480p/<seq>/` (255 =
//! moving) works, e.g. a generated scene's `images/` and `gt_motion/`
//! linked in.
mod common;
use common::Res;
use romo::plane::{Plane, Rgb};
use std::path::PathBuf;

#[derive(Default, Clone, Copy)]
struct Counts {
    tp: f64,
    fp: f64,
    fn_: f64,
    j: f64,
    n: f64,
}
impl Counts {
    fn add(&mut self, pred: &[bool], gt: &[bool]) {
        let (mut tp, mut fp, mut fn_) = (0.0, 0.0, 0.0);
        for (p, g) in pred.iter().zip(gt) {
            match (*p, *g) {
                (true, true) => tp += 1.0,
                (true, false) => fp += 1.0,
                (false, true) => fn_ += 1.0,
                _ => {}
            }
        }
        self.tp += tp;
        self.fp += fp;
        self.fn_ += fn_;
        let u = tp + fp + fn_;
        self.j += if u == 0.0 { 1.0 } else { tp / u };
        self.n += 1.0;
    }
    fn p(&self) -> f64 {
        self.tp / (self.tp + self.fp).max(1.0)
    }
    fn r(&self) -> f64 {
        self.tp / (self.tp + self.fn_).max(1.0)
    }
    fn jm(&self) -> f64 {
        self.j / self.n.max(1.0)
    }
}

fn main() -> std::process::ExitCode {
    common::main("davis_diag", run)
}

fn run() -> Res<()> {
    let davis = common::davis_dir();
    let mut opts = common::romo_options()?;
    opts.record_stages = true;
    let only = common::sequences();
    let maxf: usize = common::max_frames()?;
    let step = common::frame_step()?;
    let data = loader::davis::Davis::open(&davis, "480p")
        .map_err(|e| format!("{}: {e}", davis.display()))?;
    let mut sums = [0.0f64; 4];
    let mut k = 0.0;
    for s in data.sequences()? {
        if only.as_ref().is_some_and(|o| !o.contains(&s)) {
            continue;
        }
        let mut frames: Vec<_> = data
            .sequence(&s)?
            .frames
            .into_iter()
            .step_by(step)
            .collect();
        frames.truncate(maxf);
        let paths: Vec<PathBuf> = frames.iter().map(|f| f.image.clone()).collect();
        let src = romo::scene::PathSource {
            paths: paths.clone(),
        };
        let fx = romo::scene::make_extractor(&opts)?;
        let flow = romo::flow::dis::Dis::new(opts.flow.clone());
        let t = std::time::Instant::now();
        let gts = ground_truth(&s, &frames)?;
        let seg = romo::segment_frames(&src, &opts, &flow, fx.as_ref(), &|_, _, _| {})?;
        let secs = t.elapsed().as_secs_f64();
        let (gw, gh) = seg.report.grid;
        let (mut uc, mut lc, mut gc, mut fc) = (
            Counts::default(),
            Counts::default(),
            Counts::default(),
            Counts::default(),
        );
        let mut gt_frac = 0.0;
        let thrs = [0.3f32, 0.7, 0.9];
        let mut tc = [Counts::default(); 3];
        let mut vc = Counts::default();
        let mut sc = vec![Counts::default(); seg.stages.len()];
        for (i, p) in paths.iter().enumerate() {
            let gtp = &gts[i];
            let gt_full: Vec<bool> = gtp.data.iter().map(|v| *v > 0.5).collect();
            let gt_grid: Vec<bool> = gtp.resize(gw, gh).data.iter().map(|v| *v > 0.5).collect();
            gt_frac += gt_grid.iter().filter(|b| **b).count() as f64 / gt_grid.len() as f64;
            uc.add(&seg.u[i], &gt_grid);
            lc.add(&seg.l[i], &gt_grid.iter().map(|b| !b).collect::<Vec<_>>());
            let thr = opts.refine.threshold;
            gc.add(
                &seg.probs[i]
                    .data
                    .iter()
                    .map(|v| *v > thr)
                    .collect::<Vec<_>>(),
                &gt_grid,
            );
            vc.add(
                &seg.probs[i]
                    .data
                    .iter()
                    .zip(&seg.l[i])
                    .map(|(v, l)| *v > thr && !l)
                    .collect::<Vec<_>>(),
                &gt_grid,
            );
            if std::env::var_os("PERFRAME").is_some() {
                eprintln!("{s} {i:3} P/R {}", frame_line(&seg, i, &gt_grid, thr));
            }
            for (c, (_, st)) in sc.iter_mut().zip(&seg.stages) {
                c.add(
                    &st[i].data.iter().map(|v| *v > thr).collect::<Vec<_>>(),
                    &gt_grid,
                );
            }
            for (c, t) in tc.iter_mut().zip(thrs) {
                c.add(
                    &seg.probs[i].data.iter().map(|v| *v > t).collect::<Vec<_>>(),
                    &gt_grid,
                );
            }
            let frame = seg
                .exposure
                .applied(Rgb::from_image(&loader::io::read_rgb32f(p)?));
            if let Ok(d) = std::env::var("RAW") {
                raw(&d, &s, i, &seg, &gt_grid, &frame.resize(gw, gh))?;
            }
            if let Ok(d) = std::env::var("DUMP")
                && i % 10 == 0
            {
                dump(&d, &s, i, &frame, &seg, &gt_grid)?;
            }
            let full = romo::refine::upsample_probability(&seg.probs[i], &frame, &opts.refine);
            fc.add(
                &full.data.iter().map(|v| *v > thr).collect::<Vec<_>>(),
                &gt_full,
            );
        }
        let n = paths.len() as f64;
        let nh = seg.report.pairs.iter().filter(|p| p.model == "H").count();
        eprintln!(
            "{s:15} gt {:.3} | U prec {:.2} rec {:.2} cov {:.3} | L prec(static) {:.3} rec {:.2} | grid J {:.3} P {:.2} R {:.2} | full J {:.3} P {:.2} R {:.2} | H {nh}/{} | {:.1} fps | J@.3/.7/.9 {:.3} {:.3} {:.3} | train rec mov/stat {:.2}/{:.2} | veto J {:.3} P {:.2} R {:.2}",
            gt_frac / n,
            uc.p(),
            uc.r(),
            (uc.tp + uc.fp) / (n * (gw * gh) as f64),
            lc.p(),
            lc.r(),
            gc.jm(),
            gc.p(),
            gc.r(),
            fc.jm(),
            fc.p(),
            fc.r(),
            seg.report.pairs.len(),
            n / secs,
            tc[0].jm(),
            tc[1].jm(),
            tc[2].jm(),
            seg.report.rounds.last().map_or(0.0, |r| r.recall_moving),
            seg.report.rounds.last().map_or(0.0, |r| r.recall_static),
            vc.jm(),
            vc.p(),
            vc.r(),
        );
        let stages: Vec<String> = seg
            .stages
            .iter()
            .zip(&sc)
            .map(|((name, _), c)| format!("{name} J {:.3} P {:.2} R {:.2}", c.jm(), c.p(), c.r()))
            .collect();
        eprintln!("{s:15} stages | {}", stages.join(" | "));
        sums[0] += gc.jm();
        sums[1] += fc.jm();
        sums[2] += fc.p();
        sums[3] += fc.r();
        k += 1.0;
    }
    eprintln!(
        "MEAN grid J {:.3} | full J {:.3} P {:.3} R {:.3}",
        sums[0] / k,
        sums[1] / k,
        sums[2] / k,
        sums[3] / k
    );
    Ok(())
}

/// `DIR/<seq>_<i>.f32`: the grid's channels as little-endian f32, each
/// `w × h`: residual ÷ v (NaN: none), U, L, every recorded stage, truth,
/// R, G, B. `DIR/<seq>.json` names them.
fn raw(d: &str, s: &str, i: usize, seg: &romo::Segmentation, gt: &[bool], rgb: &Rgb) -> Res<()> {
    std::fs::create_dir_all(d)?;
    let v = seg.mean_flow[i].max(1e-6);
    let mut names = vec!["s_over_v".to_string(), "u".into(), "l".into()];
    let mut out: Vec<f32> = seg.residual[i].iter().map(|x| x / v).collect();
    out.extend(seg.u[i].iter().map(|b| *b as u8 as f32));
    out.extend(seg.l[i].iter().map(|b| *b as u8 as f32));
    for (name, st) in &seg.stages {
        names.push(name.clone());
        out.extend(&st[i].data);
    }
    names.push("gt".into());
    out.extend(gt.iter().map(|b| *b as u8 as f32));
    for (k, c) in ["r", "g", "b"].iter().enumerate() {
        names.push(c.to_string());
        out.extend(&rgb.c[k].data);
    }
    let bytes: Vec<u8> = out.iter().flat_map(|x| x.to_le_bytes()).collect();
    std::fs::write(format!("{d}/{s}_{i:03}.f32"), bytes)?;
    // The channels are the same in every frame: name them once.
    if i == 0 {
        let (w, h) = seg.report.grid;
        std::fs::write(
            format!("{d}/{s}.json"),
            format!("{{\"w\":{w},\"h\":{h},\"channels\":{names:?}}}"),
        )?;
    }
    Ok(())
}

/// The ground truth (0 / 1) of every frame of sequence `s`, at full
/// resolution.
fn ground_truth(s: &str, frames: &[loader::davis::DavisFrame]) -> Res<Vec<Plane>> {
    frames
        .iter()
        .map(|f| -> Res<Plane> {
            let a = f
                .annotation
                .as_ref()
                .ok_or_else(|| format!("{s}/{}: no annotation", f.name))?;
            let g = loader::io::read_gray8(a)?;
            Ok(Plane {
                w: g.width() as usize,
                h: g.height() as usize,
                data: g.as_raw().iter().map(|v| (*v > 127) as u8 as f32).collect(),
            })
        })
        .collect()
}

/// Precision / recall of frame `i`'s U, not-L and every recorded stage.
fn frame_line(seg: &romo::Segmentation, i: usize, gt_grid: &[bool], thr: f32) -> String {
    let mut row = Vec::new();
    let mut one = |name: &str, pred: &[bool]| {
        let mut c = Counts::default();
        c.add(pred, gt_grid);
        row.push(format!("{name} {:.2}/{:.2}", c.p(), c.r()));
    };
    one("U", &seg.u[i]);
    one("notL", &seg.l[i].iter().map(|b| !b).collect::<Vec<_>>());
    for (name, st) in &seg.stages {
        one(
            name,
            &st[i].data.iter().map(|v| *v > thr).collect::<Vec<_>>(),
        );
    }
    row.join(" ")
}

/// `DIR/<seq>_<i>.png`: frame | U (red) / L (green) | probability | ground
/// truth, on the grid.
fn dump(
    d: &str,
    s: &str,
    i: usize,
    frame: &Rgb,
    seg: &romo::Segmentation,
    gt_grid: &[bool],
) -> Res<()> {
    let (gw, gh) = seg.report.grid;
    let small = frame.resize(gw, gh);
    let ns = seg.stages.len();
    let img = image::RgbImage::from_fn((4 + ns) as u32 * gw as u32, gh as u32, |x, y| {
        let (k, x) = (x as usize / gw, x as usize % gw);
        let j = y as usize * gw + x;
        let b = |v: f32| (v.clamp(0.0, 1.0) * 255.0) as u8;
        if k >= 4 {
            return image::Rgb([b(seg.stages[k - 4].1[i].data[j]); 3]);
        }
        match k {
            0 => image::Rgb([
                b(small.c[0].data[j]),
                b(small.c[1].data[j]),
                b(small.c[2].data[j]),
            ]),
            1 => image::Rgb([255 * seg.u[i][j] as u8, 255 * seg.l[i][j] as u8, 0]),
            2 => image::Rgb([b(seg.probs[i].data[j]); 3]),
            _ => image::Rgb([255 * gt_grid[j] as u8; 3]),
        }
    });
    std::fs::create_dir_all(d)?;
    img.save(format!("{d}/{s}_{i:03}.png"))?;
    Ok(())
}
