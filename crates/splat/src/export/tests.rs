#![allow(clippy::needless_range_loop)]
//! Writes one sample of every format through [`export`] and reads each back.
//! With `ROMOSPLAT_EXPORT_SAMPLES=DIR` the samples go to DIR (for
//! `scripts/check_exports.sh`, which feeds them to external tools);
//! otherwise to a temporary directory.

use super::*;
use crate::export::test_data::random_splats;

/// Number of splats in the samples.
const SAMPLE_SPLATS: usize = 1000;

#[test]
fn format_names_parse() {
    for f in ExportFormat::ALL {
        assert_eq!(f.name().parse::<ExportFormat>().unwrap(), f);
        assert_eq!(
            ExportFormat::from_path(Path::new(&format!("a/b.{}", f.name().to_uppercase()))),
            Some(f)
        );
    }
    assert!("obj".parse::<ExportFormat>().is_err());
}

/// Rotation matrix of a unit (w, x, y, z) quaternion.
fn rot(q: [f32; 4]) -> [[f32; 3]; 3] {
    let [w, x, y, z] = normalized_wxyz(q);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// Σ = R S² Rᵀ.
fn covariance(q: [f32; 4], ls: [f32; 3]) -> [[f32; 3]; 3] {
    let r = rot(q);
    let mut c = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = (0..3)
                .map(|k| r[i][k] * r[j][k] * (2.0 * ls[k]).exp())
                .sum();
        }
    }
    c
}

#[test]
fn rdf_to_rub_is_a_rotation_of_every_attribute() {
    use crate::reference::sh::{basis, eval};
    let s = random_splats(50, 3, 9);
    let r = rdf_to_rub(&s);
    // Involution.
    assert_eq!(rdf_to_rub(&r), s);
    let flip = [1.0f32, -1.0, -1.0];
    let dirs = [[0.3f32, -0.5, 0.81], [-0.9, 0.1, 0.42], [0.0, 0.0, 1.0]];
    for i in 0..s.len() {
        for a in 0..3 {
            assert_eq!(r.means[i][a], flip[a] * s.means[i][a]);
        }
        // Σ' = F Σ F with F = diag(1, −1, −1).
        let c = covariance(s.rotations[i], s.log_scales[i]);
        let c2 = covariance(r.rotations[i], r.log_scales[i]);
        for a in 0..3 {
            for b in 0..3 {
                let want = flip[a] * flip[b] * c[a][b];
                assert!(
                    (c2[a][b] - want).abs() <= 1e-5 * (1.0 + want.abs()),
                    "{i} {a}{b}"
                );
            }
        }
        // Colour seen along d before equals colour along F d after.
        let block = |x: &Splats| x.sh[i * 48..(i + 1) * 48].to_vec();
        for d in dirs {
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let d = d.map(|v| v / n);
            let fd = [d[0], -d[1], -d[2]];
            let before = eval::<f64>(3, &basis(3, d.map(f64::from)), &block(&s));
            let after = eval::<f64>(3, &basis(3, fd.map(f64::from)), &block(&r));
            for c in 0..3 {
                assert!(
                    (before[c] - after[c]).abs() < 1e-9,
                    "{i} {c}: {before:?} {after:?}"
                );
            }
        }
    }
}

/// The exact parameters as CSV in the INRIA PLY column layout (what
/// splat-transform prints for a .ply), for `scripts/compare_exports.py`.
fn write_truth_csv(path: &Path, s: &Splats) {
    let k = s.coeffs_per_channel();
    let mut cols: Vec<String> = ["x", "y", "z", "scale_0", "scale_1", "scale_2"]
        .iter()
        .chain(&[
            "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "rot_0", "rot_1", "rot_2", "rot_3",
        ])
        .map(|c| c.to_string())
        .collect();
    cols.extend((0..3 * (k - 1)).map(|i| format!("f_rest_{i}")));
    let mut out = cols.join(",") + "\n";
    for i in 0..s.len() {
        let mut row: Vec<f32> = Vec::new();
        row.extend(s.means[i]);
        row.extend(s.log_scales[i]);
        row.extend(&s.sh[i * k * 3..i * k * 3 + 3]);
        row.push(s.opacity_logits[i]);
        row.extend(s.rotations[i]);
        for c in 0..3 {
            for j in 1..k {
                row.push(s.sh[i * k * 3 + j * 3 + c]);
            }
        }
        let row: Vec<String> = row.iter().map(|v| format!("{}", f64::from(*v))).collect();
        out += &(row.join(",") + "\n");
    }
    loader::io::write_bytes_atomic(path, out.as_bytes()).unwrap();
}

#[test]
fn write_samples_of_every_format_and_read_them_back() {
    let tmp;
    let dir = match std::env::var_os("ROMOSPLAT_EXPORT_SAMPLES") {
        Some(d) => PathBuf::from(d),
        None => {
            tmp = tempfile::tempdir().unwrap();
            tmp.path().to_path_buf()
        }
    };
    let s = random_splats(SAMPLE_SPLATS, 3, 2024);
    write_truth_csv(&dir.join("sample_truth.csv"), &s);
    let opts = ExportOptions::default();
    let mut sizes = Vec::new();
    for f in ExportFormat::ALL {
        let path = dir.join(format!("sample.{}", f.name()));
        let sum = export(&s, f, &path, &opts).unwrap();
        assert_eq!(sum.splats, SAMPLE_SPLATS);
        assert_eq!(std::fs::metadata(&path).unwrap().len(), sum.bytes);
        sizes.push((f.name(), sum.bytes));
    }
    // Read each back.
    let splat = read_splat(&dir.join("sample.splat")).unwrap();
    assert_eq!(splat.len(), SAMPLE_SPLATS);
    assert_eq!(
        std::fs::metadata(dir.join("sample.splat")).unwrap().len(),
        32 * SAMPLE_SPLATS as u64
    );
    let (h, spz) = read_spz(&dir.join("sample.spz"), true).unwrap();
    assert_eq!((h.num_points as usize, spz.sh_degree), (SAMPLE_SPLATS, 3));
    let glb = parse_glb(&std::fs::read(dir.join("sample.glb")).unwrap()).unwrap();
    assert_eq!(glb.json["accessors"][0]["count"], SAMPLE_SPLATS as u64);
    let ply = crate::io::read_ply(dir.join("sample.ply")).unwrap();
    assert_eq!(ply, s);
    // No temp files left behind by the atomic writes.
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains(".tmp."))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    eprintln!("export samples ({SAMPLE_SPLATS} splats, SH degree 3): {sizes:?}");
}

/// Every exported format reads back through `read_splats` (the reader
/// `inspect` and `export --splats` use), .glb close to the original.
#[test]
fn read_splats_reads_every_format() {
    let dir = tempfile::tempdir().unwrap();
    let s = random_splats(64, 2, 7);
    for f in ExportFormat::ALL {
        let p = dir.path().join(format!("s.{}", f.name()));
        export(&s, f, &p, &ExportOptions::default()).unwrap();
        let back = crate::io::read_splats(&p).unwrap();
        assert_eq!(back.len(), s.len(), "{f}");
        assert_eq!(back.sh_degree, if f == ExportFormat::Splat { 0 } else { 2 });
    }
    let glb = crate::io::read_splats(dir.path().join("s.glb")).unwrap();
    for i in 0..s.len() {
        for a in 0..3 {
            assert!((glb.means[i][a] - s.means[i][a]).abs() < 1e-6);
            assert!((glb.log_scales[i][a] - s.log_scales[i][a]).abs() < 1e-4);
        }
        assert!((glb.opacity_logits[i] - s.opacity_logits[i]).abs() < 1e-2);
    }
    assert_eq!(&glb.sh[..27], &s.sh[..27]);
    let e = crate::io::read_splats(dir.path().join("s.obj"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("s.obj") && e.contains("extension"), "{e}");
}

/// A splat whose linear scale overflows f32 would be written as `inf` by
/// the .splat and .glb encoders; the export refuses before writing.
#[test]
fn export_refuses_what_would_not_read_back() {
    let dir = tempfile::tempdir().unwrap();
    let mut s = random_splats(5, 0, 3);
    s.log_scales[3][1] = 120.0;
    for f in [ExportFormat::Splat, ExportFormat::Glb] {
        let p = dir.path().join(format!("big.{}", f.name()));
        let e = export(&s, f, &p, &ExportOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("big.") && e.contains("scale_1") && e.contains("would not read back"),
            "{e}"
        );
        assert!(!p.exists(), "{f} written");
    }
    // NaN is refused by every format, naming the splat and property for PLY.
    s.log_scales[3][1] = 0.0;
    s.means[1][2] = f32::NAN;
    let p = dir.path().join("nan.ply");
    let e = export(&s, ExportFormat::Ply, &p, &ExportOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("nan.ply") && e.contains("splat 1") && e.contains("property z"),
        "{e}"
    );
    assert!(!p.exists());
}
