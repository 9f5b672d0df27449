//! Fuzz: NaN / Inf / huge inputs are culled (or rejected with a clear error),
//! never hang and never produce a NaN pixel; culling agrees with the reference.

use super::ctx;
use super::forward::max_abs_diff;
use super::scenes::{camera, random_splats};
use crate::gpu::GpuError;
use crate::gpu::forward::{ForwardKernels, forward, upload_splats};
use crate::reference;
use crate::types::RenderOptions;
use rand::{Rng, SeedableRng};

#[test]
fn non_finite_and_huge_inputs_are_culled() {
    let Some(c) = ctx() else { return };
    let k = ForwardKernels::new(c);
    let bad = [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        1e30,
        -1e30,
        1e19,
        3e38,
        -0.0,
        1e-30,
    ];
    let mut r = rand_pcg::Pcg64::seed_from_u64(77);
    for round in 0..4u64 {
        let mut s = random_splats(240, 2, 900 + round, true);
        let k3 = s.coeffs_per_channel() * 3;
        for i in 0..s.len() {
            if r.random_range(0..3) != 0 {
                continue;
            }
            let v = bad[r.random_range(0..bad.len())];
            match r.random_range(0..6) {
                0 => s.means[i][r.random_range(0..3)] = v,
                1 => {
                    s.log_scales[i][r.random_range(0..3)] = if v.abs() > 1e3 {
                        v.abs().min(88.0) + 1.0
                    } else {
                        v
                    }
                }
                2 => s.rotations[i][r.random_range(0..4)] = v,
                3 => s.opacity_logits[i] = v,
                4 => s.sh[i * k3 + r.random_range(0..k3)] = v,
                _ => s.log_scales[i] = [v, v, v],
            }
        }
        let cam = camera(80, 60);
        let opts = RenderOptions {
            background: [0.5, 0.5, 0.5],
            sh_degree: 2,
            low_pass: 0.3,
            antialiased: round % 2 == 1,
        };
        let p = upload_splats(c, &s).unwrap();
        let (st, _) = forward(c, &k, &p, &cam, &opts, false).unwrap();
        let img: Vec<f32> = c.read(&st.image, 80 * 60 * 3).unwrap();
        assert!(
            img.iter().all(|v| v.is_finite()),
            "round {round}: non-finite pixel"
        );
        let gp = st.read_projected(c).unwrap();
        let rp = reference::project(&s, &cam, &opts);
        for (i, (g, rr)) in gp.iter().zip(&rp).enumerate() {
            assert_eq!(
                g.radius > 0.0,
                rr.radius > 0.0,
                "round {round} splat {i}: culling differs {g:?} vs {rr:?}"
            );
        }
        let reference = reference::render(&s, &cam, &opts).unwrap();
        // Huge-but-finite SH values give huge colours in both; compare relative to
        // max(1, |reference|).
        let _ = max_abs_diff("fuzz image", &img, &reference.image); // NaN check
        for (i, (a, b)) in img.iter().zip(&reference.image).enumerate() {
            assert!(
                (a - b).abs() <= 1e-4 * b.abs().max(1.0),
                "round {round} value {i}: {a} vs {b}"
            );
        }
    }
}

#[test]
fn bad_camera_or_options_give_a_clear_error() {
    let Some(c) = ctx() else { return };
    let k = ForwardKernels::new(c);
    let s = random_splats(10, 0, 1, false);
    let p = upload_splats(c, &s).unwrap();
    let mut cam = camera(32, 32);
    cam.fx = f32::NAN;
    let e = forward(c, &k, &p, &cam, &RenderOptions::default(), false).err();
    assert!(matches!(e, Some(GpuError::InvalidInput(_))), "{e:?}");
    let cam = camera(32, 32);
    let opts = RenderOptions {
        low_pass: f32::INFINITY,
        ..Default::default()
    };
    let e = forward(c, &k, &p, &cam, &opts, false).err();
    assert!(matches!(e, Some(GpuError::InvalidInput(_))), "{e:?}");
    let mut s2 = s.clone();
    s2.sh.pop();
    assert!(matches!(
        upload_splats(c, &s2).err(),
        Some(GpuError::InvalidInput(_))
    ));
}
