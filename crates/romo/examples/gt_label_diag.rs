//! Diagnosis (not a test): per frame of a generated scene (`SCENE`), v,
//! and over the ground-truth moving pixels the median S, own flow and the
//! fractions in U / L / with no residual. `ROMO_OPTS` as in `scene_eval`.
#![allow(clippy::unwrap_used, clippy::expect_used)]
use std::path::PathBuf;
fn main() {
    let dir = PathBuf::from(std::env::var("SCENE").unwrap());
    let opts: romo::RomoOptions =
        serde_json::from_str(&std::env::var("ROMO_OPTS").unwrap_or("{}".into())).unwrap();
    let scene = loader::scene::Scene::load(&dir, &Default::default()).unwrap();
    let extra = scene.split_indices("extra");
    let video: Vec<usize> = (0..scene.len()).filter(|i| !extra.contains(i)).collect();
    let frames: Vec<romo::plane::Rgb> = video
        .iter()
        .map(|&i| romo::plane::Rgb::from_image(&scene.load_image(i).unwrap()))
        .collect();
    let gts: Vec<image::GrayImage> = video
        .iter()
        .map(|&i| scene.load_gt_motion(i).unwrap().unwrap())
        .collect();
    let fx = romo::scene::make_extractor(&opts).unwrap();
    let flow = romo::scene::make_flow(&opts).unwrap();
    let hook = |t: usize, (gw, gh): (usize, usize), fl: &mut romo::labels::FrameLabels| {
        let g = image::imageops::resize(
            &gts[t],
            gw as u32,
            gh as u32,
            image::imageops::FilterType::Nearest,
        );
        let mut ss = vec![];
        let (mut nu, mut nl, mut nn, mut n) = (0, 0, 0, 0);
        for i in 0..gw * gh {
            if g.as_raw()[i] >= 128 {
                n += 1;
                if fl.s[i].is_nan() {
                    nn += 1
                } else {
                    ss.push(fl.s[i])
                }
                nu += fl.u[i] as usize;
                nl += fl.l[i] as usize;
            }
        }
        ss.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let med = ss.get(ss.len() / 2).copied().unwrap_or(f32::NAN);
        eprintln!(
            "t {t}: v {:.2} gt px {n} S med {med:.2} U {:.2} L {:.2} nan {:.2} Ucov {:.3}",
            fl.v,
            nu as f32 / n.max(1) as f32,
            nl as f32 / n.max(1) as f32,
            nn as f32 / n.max(1) as f32,
            fl.u_coverage
        );
    };
    let _ = romo::pipeline::segment_frames_with_labels(
        &frames,
        &opts,
        flow.as_ref(),
        fx.as_ref(),
        &|_, _, _| {},
        Some(&hook),
    )
    .unwrap();
}
