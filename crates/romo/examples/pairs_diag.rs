//! Measurement (not a test): per-pair F-vs-H diagnosis on DAVIS-2016. For
//! every `STEP`-th adjacent pair of the first `MAXF` frames: mean flow v,
//! the U fraction under F and under H (`S > u·v`) and how much of each lies
//! inside the ground-truth object (precision), the "parallax set"
//! (`S_H > u·v`, `S_F < l·v`: explained by F, not by H) with its object
//! fraction and spatial spread, and GRIC of both models. Env: `DAVIS_DIR`,
//! `SEQS`, `MAXF`, `STEP`, `ROMO_OPTS`.
#![allow(clippy::unwrap_used, clippy::expect_used)]
use romo::flow::FlowEstimator;
use romo::geometry::robust::ModelSelection;
use romo::pipeline::FrameSource;
use romo::plane::Plane;
use std::path::PathBuf;

fn main() {
    let davis =
        PathBuf::from(std::env::var("DAVIS_DIR").unwrap_or("/work/shared/data/davis2016".into()));
    let opts: romo::RomoOptions =
        serde_json::from_str(&std::env::var("ROMO_OPTS").unwrap_or("{}".into())).unwrap();
    let only: Option<Vec<String>> = std::env::var("SEQS")
        .ok()
        .map(|s| s.split(',').map(String::from).collect());
    let env = |k: &str, d: usize| {
        std::env::var(k)
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(d)
    };
    let (maxf, step) = (env("MAXF", usize::MAX), env("STEP", 5));
    let data = loader::davis::Davis::open(&davis, "480p").unwrap();
    let flow = romo::flow::dis::Dis::new(opts.flow.clone());
    for s in data.sequences().unwrap() {
        if only.as_ref().is_some_and(|o| !o.contains(&s)) {
            continue;
        }
        let mut frames = data.sequence(&s).unwrap().frames;
        frames.truncate(maxf);
        let paths: Vec<PathBuf> = frames.iter().map(|f| f.image.clone()).collect();
        let src = romo::scene::PathSource {
            paths: paths.clone(),
        };
        let f0 = src.frame(0).unwrap();
        let (gw, gh) = opts.grid_size(f0.w(), f0.h());
        let (fw, fh) = (gw * opts.flow_scale, gh * opts.flow_scale);
        for p in (0..paths.len() - 1).step_by(step) {
            let a = src.frame(p).unwrap().resize(fw, fh).gray();
            let b = src.frame(p + 1).unwrap().resize(fw, fh).gray();
            let fwd = flow.flow(&a, &b).unwrap().resize(gw, gh);
            let bwd = flow.flow(&b, &a).unwrap().resize(gw, gh);
            let valid = romo::labels::cycle_valid(&fwd, &bwd, &opts.labels);
            let g = loader::io::read_gray8(frames[p].annotation.as_ref().unwrap()).unwrap();
            let gtp = Plane {
                w: g.width() as usize,
                h: g.height() as usize,
                data: g.as_raw().iter().map(|v| (*v > 127) as u8 as f32).collect(),
            };
            let gt: Vec<bool> = gtp.resize(gw, gh).data.iter().map(|v| *v > 0.5).collect();
            let fit = |sel| {
                let mut lo = opts.labels.clone();
                lo.robust.selection = sel;
                let r = romo::labels::fit_pair(&fwd, &valid, &lo, 7, None).unwrap();
                (r.model, r.report)
            };
            let (mf, _) = fit(ModelSelection::Fundamental);
            let (mh, _) = fit(ModelSelection::Homography);
            let (_, rg) = fit(ModelSelection::Gric);
            let v = fwd.mean_magnitude();
            let (u, l) = (opts.labels.u_factor * v, opts.labels.l_factor * v);
            let (mut n, mut uf, mut uf_in, mut uh, mut uh_in, mut par, mut par_in) =
                (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
            let (mut sx, mut sy, mut sxx, mut syy) = (0.0, 0.0, 0.0, 0.0);
            for i in 0..gw * gh {
                if !valid[i] {
                    continue;
                }
                let (x, y) = ((i % gw) as f64, (i / gw) as f64);
                let q = [x + fwd.u.data[i] as f64, y + fwd.v.data[i] as f64];
                let sf = mf.residual_px([x, y], q) as f32;
                let sh = mh.residual_px([x, y], q) as f32;
                n += 1.0;
                let inside = gt[i] as u8 as f64;
                if sf > u {
                    uf += 1.0;
                    uf_in += inside;
                }
                if sh > u {
                    uh += 1.0;
                    uh_in += inside;
                    if sf < l {
                        par += 1.0;
                        par_in += inside;
                        let (xn, yn) = (x / gw as f64, y / gh as f64);
                        sx += xn;
                        sy += yn;
                        sxx += xn * xn;
                        syy += yn * yn;
                    }
                }
            }
            let spread = if par > 0.0 {
                ((sxx / par - (sx / par).powi(2)) + (syy / par - (sy / par).powi(2))).sqrt()
            } else {
                0.0
            };
            println!(
                "{s:14} {p:3} v {v:5.2} | UF {:.3} prec {:.2} | UH {:.3} prec {:.2} | par {:.3} prec {:.2} spread {spread:.2} | gric {} F-H {:8.0}",
                uf / n,
                uf_in / uf.max(1.0),
                uh / n,
                uh_in / uh.max(1.0),
                par / n,
                par_in / par.max(1.0),
                rg.model,
                rg.gric_f - rg.gric_h,
            );
        }
    }
}
