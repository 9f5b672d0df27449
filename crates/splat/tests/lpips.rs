//! LPIPS path (feature `onnx`): models with the LPIPS signature are written
//! here as ONNX protobuf by hand (no network, no pretrained weights) — the
//! "distance" is the mean squared difference of the two [−1, 1] inputs, so
//! the value `Lpips::distance` returns can be checked against a hand
//! computation: 4 · mean((a − b)²) for images a, b in [0, 1]. Covers the
//! output layouts [1,1,1,1], scalar and spatial [1,1,H,W], a fixed-size
//! model, and models with the wrong signature (error naming the file).
//! Needs `ORT_DYLIB_PATH`; skips when it is unset and `CI` is unset.
#![cfg(feature = "onnx")]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use splat::lpips::Lpips;
use std::path::Path;

/// Minimal protobuf writer for the ONNX messages used here.
#[derive(Default)]
struct Pb(Vec<u8>);

impl Pb {
    fn varint(&mut self, mut v: u64) {
        loop {
            let b = (v & 0x7f) as u8;
            v >>= 7;
            if v == 0 {
                self.0.push(b);
                break;
            }
            self.0.push(b | 0x80);
        }
    }
    fn int(mut self, field: u64, v: i64) -> Self {
        self.varint(field << 3);
        self.varint(v as u64);
        self
    }
    fn bytes(mut self, field: u64, b: &[u8]) -> Self {
        self.varint((field << 3) | 2);
        self.varint(b.len() as u64);
        self.0.extend_from_slice(b);
        self
    }
    fn str(self, field: u64, s: &str) -> Self {
        self.bytes(field, s.as_bytes())
    }
    fn msg(self, field: u64, m: Pb) -> Self {
        self.bytes(field, &m.0)
    }
}

/// ValueInfoProto of an f32 tensor; a dim is a value (> 0) or a name.
fn value_info(name: &str, dims: &[Result<i64, &str>]) -> Pb {
    let mut shape = Pb::default();
    for d in dims {
        let dim = match d {
            Ok(v) => Pb::default().int(1, *v),
            Err(p) => Pb::default().str(2, p),
        };
        shape = shape.msg(1, dim);
    }
    let tensor = Pb::default().int(1, 1).msg(2, shape); // elem_type FLOAT
    Pb::default()
        .str(1, name)
        .msg(2, Pb::default().msg(1, tensor))
}

fn node(op: &str, inputs: &[&str], output: &str, attrs: Vec<Pb>) -> Pb {
    let mut n = Pb::default();
    for i in inputs {
        n = n.str(1, i);
    }
    n = n.str(2, output).str(3, output).str(4, op);
    for a in attrs {
        n = n.msg(5, a);
    }
    n
}

fn int_attr(name: &str, v: i64) -> Pb {
    Pb::default().str(1, name).int(3, v).int(20, 2) // type INT
}

fn ints_attr(name: &str, v: &[i64]) -> Pb {
    let mut a = Pb::default().str(1, name);
    for x in v {
        a = a.int(8, *x);
    }
    a.int(20, 7) // type INTS
}

/// A model `out = ReduceMean((in0 − in1)², axes, keepdims)` (opset 13).
fn write_model(
    path: &Path,
    n_inputs: usize,
    in_dims: &[Result<i64, &str>],
    reduce: Option<(Option<&[i64]>, i64)>,
    out_dims: &[Result<i64, &str>],
) {
    let mut g = Pb::default();
    let diff_in: Vec<&str> = if n_inputs == 2 {
        vec!["in0", "in1"]
    } else {
        vec!["in0", "in0"]
    };
    g = g.msg(1, node("Sub", &diff_in, "d", vec![]));
    g = g.msg(1, node("Mul", &["d", "d"], "sq", vec![]));
    let out = match reduce {
        Some((axes, keep)) => {
            let mut attrs = vec![int_attr("keepdims", keep)];
            if let Some(a) = axes {
                attrs.push(ints_attr("axes", a));
            }
            g = g.msg(1, node("ReduceMean", &["sq"], "out", attrs));
            "out"
        }
        None => "sq",
    };
    g = g.str(2, "lpips_test");
    for i in 0..n_inputs {
        g = g.msg(11, value_info(&format!("in{i}"), in_dims));
    }
    g = g.msg(12, value_info(out, out_dims));
    let model = Pb::default()
        .int(1, 8) // ir_version
        .str(2, "romosplat-test")
        .msg(7, g)
        .msg(8, Pb::default().str(1, "").int(2, 13));
    std::fs::write(path, model.0).unwrap();
}

fn runtime() -> bool {
    if std::env::var_os("ORT_DYLIB_PATH").is_some() {
        return true;
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "CI set but ORT_DYLIB_PATH missing"
    );
    eprintln!("skipped: ORT_DYLIB_PATH not set");
    false
}

fn images(w: u32, h: u32) -> (Vec<f32>, Vec<f32>) {
    let n = (w * h * 3) as usize;
    let a = (0..n).map(|i| ((i * 37) % 101) as f32 / 100.0).collect();
    let b = (0..n).map(|i| ((i * 53 + 7) % 97) as f32 / 96.0).collect();
    (a, b)
}

fn hand(a: &[f32], b: &[f32]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| {
            let d = (2.0 * *x as f64 - 1.0) - (2.0 * *y as f64 - 1.0);
            d * d
        })
        .sum::<f64>()
        / a.len() as f64
}

/// (file name, ReduceMean axes, keepdims, declared output dims).
type Case<'a> = (&'a str, Option<&'a [i64]>, i64, Vec<Result<i64, &'a str>>);

const DYN: [Result<i64, &str>; 4] = [Ok(1), Ok(3), Err("H"), Err("W")];

#[test]
fn lpips_layouts_match_hand_computation() {
    if !runtime() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (13, 9);
    let (a, b) = images(w, h);
    let want = hand(&a, &b);
    assert!(want > 0.1);
    let cases: [Case; 3] = [
        ("lpips.onnx", None, 1, vec![Ok(1), Ok(1), Ok(1), Ok(1)]),
        ("scalar.onnx", None, 0, vec![]),
        (
            "spatial.onnx",
            Some(&[1]),
            1,
            vec![Ok(1), Ok(1), Err("H"), Err("W")],
        ),
    ];
    for (name, axes, keep, out) in cases {
        let p = dir.path().join(name);
        write_model(&p, 2, &DYN, Some((axes, keep)), &out);
        let mut m = Lpips::load(&p).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(m.fixed_size(), None);
        let got = m.distance(&a, &b, w, h).unwrap();
        assert!(
            (got - want).abs() < 1e-5 * want,
            "{name}: {got} vs hand-computed {want}"
        );
        assert!(m.distance(&a, &a, w, h).unwrap().abs() < 1e-12);
        // Swapping the images gives the same (symmetric) distance.
        assert!((m.distance(&b, &a, w, h).unwrap() - got).abs() < 1e-6);
    }
}

#[test]
fn fixed_size_model_resizes() {
    if !runtime() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("fixed.onnx");
    let fixed = [Ok(1), Ok(3), Ok(8), Ok(6)];
    write_model(
        &p,
        2,
        &fixed,
        Some((None, 1)),
        &[Ok(1), Ok(1), Ok(1), Ok(1)],
    );
    let mut m = Lpips::load(&p).unwrap();
    assert_eq!(m.fixed_size(), Some((6, 8)));
    // Constant images survive any resize: per channel a = 0.2, 0.5, 0.9 and b = 0.6.
    let (w, h) = (20, 11);
    let a: Vec<f32> = (0..w * h).flat_map(|_| [0.2, 0.5, 0.9]).collect();
    let b = vec![0.6f32; (w * h * 3) as usize];
    let want: f64 = 4.0 * (0.16 + 0.01 + 0.09) / 3.0;
    let got = m.distance(&a, &b, w, h).unwrap();
    assert!((got - want).abs() < 1e-5, "{got} vs {want}");
}

#[test]
fn wrong_signatures_are_errors_naming_the_file() {
    if !runtime() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // One input.
    let p = dir.path().join("one_input.onnx");
    write_model(&p, 1, &DYN, Some((None, 1)), &[Ok(1), Ok(1), Ok(1), Ok(1)]);
    let e = Lpips::load(&p).unwrap_err().to_string();
    assert!(
        e.contains("one_input.onnx") && e.contains("1 inputs"),
        "{e}"
    );
    // Inputs of rank 3.
    let p = dir.path().join("rank3.onnx");
    write_model(&p, 2, &DYN[1..], Some((None, 1)), &[Ok(1), Ok(1), Ok(1)]);
    let e = Lpips::load(&p).unwrap_err().to_string();
    assert!(
        e.contains("rank3.onnx") && e.contains("[1, 3, H, W]"),
        "{e}"
    );
    // A [1, 3, H, W] output is not a distance: loads, fails on run.
    let p = dir.path().join("map3.onnx");
    write_model(&p, 2, &DYN, None, &DYN);
    let mut m = Lpips::load(&p).unwrap();
    let (a, b) = images(5, 4);
    let e = m.distance(&a, &b, 5, 4).unwrap_err().to_string();
    assert!(e.contains("map3.onnx") && e.contains("output shape"), "{e}");
    assert!(!e.contains('\n'));
    // Wrong buffer size.
    assert!(m.distance(&a[1..], &b, 5, 4).is_err());
    // Missing file, garbage file.
    let e = Lpips::load(&dir.path().join("nope.onnx"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("nope.onnx"), "{e}");
    let p = dir.path().join("garbage.onnx");
    std::fs::write(&p, b"not a model").unwrap();
    let e = Lpips::load(&p).unwrap_err().to_string();
    assert!(e.contains("garbage.onnx"), "{e}");
}
