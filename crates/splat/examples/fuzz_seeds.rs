//! Seed corpora for the cargo-fuzz targets in `fuzz/`, generated from the
//! built-in small scene and our own writers and exporters (small on purpose:
//! libFuzzer mutates short inputs fastest).
//!
//! `cargo run --release -p splat --example fuzz_seeds -- fuzz/corpus`
//! writes `fuzz/corpus/<target>/<seed>` for every target.

use loader::colmap::{ColmapModel, read_model, write_model_binary, write_model_text};
use loader::ply::PlySplats;
use splat::export::{ExportFormat, ExportOptions, encode_checked};
use std::path::{Path, PathBuf};

type Res<T> = Result<T, Box<dyn std::error::Error>>;

/// The separator the multi-file targets split their input at.
const SEP: &[u8] = b"\n--8<--\n";

fn main() -> Res<()> {
    let out = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "fuzz/corpus".into()),
    );
    let tmp = std::env::temp_dir().join(format!("romosplat-seeds-{}", std::process::id()));
    let scene = tmp.join("scene");
    let spec_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/small.toml");
    let mut spec = loader::synth::load_spec(&spec_path)?;
    spec.frames = 4;
    spec.test_views = 1;
    spec.points3d = 40;
    loader::synth::generate(&spec, &scene)?;
    let full = read_model(scene.join("sparse/0"))?;
    let model = small_model(&full);
    let put = |target: &str, name: &str, bytes: &[u8]| -> Res<()> {
        let d = out.join(target);
        std::fs::create_dir_all(&d)?;
        std::fs::write(d.join(name), bytes)?;
        Ok(())
    };

    // COLMAP binary and text: the three files joined by SEP.
    for (target, ext) in [("colmap_bin", "bin"), ("colmap_txt", "txt")] {
        let d = tmp.join(target);
        if ext == "bin" {
            write_model_binary(&model, &d)?;
        } else {
            write_model_text(&model, &d)?;
        }
        let mut joined = Vec::new();
        for (k, f) in ["cameras", "images", "points3D"].iter().enumerate() {
            if k > 0 {
                joined.extend_from_slice(SEP);
            }
            joined.extend_from_slice(&std::fs::read(d.join(format!("{f}.{ext}")))?);
        }
        put(target, "small_scene", &joined)?;
    }

    // transforms.json naming the scratch image the target provides, and
    // split.json in index and name form.
    let mut t = loader::transforms::Transforms::from_model(&model, "images/")?;
    for f in &mut t.frames {
        f.file_path = "images/a.png".into();
    }
    put(
        "transforms",
        "from_model.json",
        serde_json::to_string_pretty(&t)?.as_bytes(),
    )?;
    put(
        "split",
        "indices.json",
        br#"{"clutter": [0, 1, 2], "extra": [3]}"#,
    )?;
    put(
        "split",
        "names.json",
        br#"{"clutter": ["000.png", "001"], "extra": ["003.jpg"], "clean": [2]}"#,
    )?;

    // Splats from the scene's points, every SH degree, every format.
    let pts: Vec<[f32; 3]> = full
        .points3d
        .values()
        .take(6)
        .map(|p| p.xyz.map(|v| v as f32))
        .collect();
    let cols: Vec<[f32; 3]> = full
        .points3d
        .values()
        .take(6)
        .map(|p| p.rgb.map(|c| f32::from(c) / 255.0))
        .collect();
    for degree in 0..=3u32 {
        let s = splat::init::splats_from_points(&pts[..3], &cols[..3], degree);
        let ply = splat::io::to_ply_splats(&s)?;
        put(
            "ply",
            &format!("le_sh{degree}.ply"),
            &loader::ply::encode_ply(&ply, Path::new("x.ply"))?,
        )?;
        put(
            "ply",
            &format!("ascii_sh{degree}.ply"),
            &encode_other(&ply, false),
        )?;
        put(
            "ply",
            &format!("be_sh{degree}.ply"),
            &encode_other(&ply, true),
        )?;
        let s6 = splat::init::splats_from_points(&pts, &cols, degree);
        for (f, target) in [
            (ExportFormat::Spz, "spz"),
            (ExportFormat::Glb, "glb"),
            (ExportFormat::Splat, "web_splat"),
        ] {
            let mut opts = ExportOptions::default();
            for version in [2, 3] {
                opts.spz.version = version;
                let (bytes, _) = encode_checked(&s6, f, Path::new("x"), &opts)?;
                put(
                    target,
                    &format!("sh{degree}_v{version}.{}", f.name()),
                    &bytes,
                )?;
            }
        }
    }

    // .flo and EXR through our writers.
    let mut flow = loader::flo::FlowField::zeros(3, 2);
    flow.data[1] = [1.5, -0.25];
    flow.data[4] = [1e10, 0.0];
    let p = tmp.join("f.flo");
    loader::flo::write_flo(&p, &flow)?;
    put("flo", "3x2.flo", &std::fs::read(&p)?)?;
    for channels in 1..=3usize {
        let img = loader::exr::FloatImage {
            width: 3,
            height: 2,
            channels,
            data: (0..6 * channels).map(|i| i as f32 * 0.25 - 1.0).collect(),
        };
        let p = tmp.join(format!("c{channels}.exr"));
        loader::exr::write_exr(&p, &img)?;
        put("exr", &format!("c{channels}.exr"), &std::fs::read(&p)?)?;
    }
    std::fs::remove_dir_all(&tmp)?;
    println!("seeds written to {}", out.display());
    Ok(())
}

/// The first two images (10 keypoints each), their camera(s) and the points
/// they observe, with tracks cut to those keypoints.
fn small_model(m: &ColmapModel) -> ColmapModel {
    let mut s = ColmapModel::default();
    for im in m.images.values().take(2) {
        let mut im = im.clone();
        im.points2d.truncate(10);
        s.cameras
            .insert(im.camera_id, m.cameras[&im.camera_id].clone());
        s.images.insert(im.id, im);
    }
    for p in m.points3d.values() {
        let track: Vec<(u32, u32)> = p
            .track
            .iter()
            .copied()
            .filter(|(i, k)| {
                s.images
                    .get(i)
                    .is_some_and(|im| (*k as usize) < im.points2d.len())
            })
            .collect();
        if !track.is_empty() && s.points3d.len() < 8 {
            let mut p = p.clone();
            p.track = track;
            s.points3d.insert(p.id, p);
        }
    }
    for im in s.images.values_mut() {
        for p2 in &mut im.points2d {
            if p2
                .point3d_id
                .is_some_and(|id| !s.points3d.contains_key(&id))
            {
                p2.point3d_id = None;
            }
        }
    }
    s
}

/// ASCII or big-endian PLY (float properties) for the reader's other encodings.
fn encode_other(s: &PlySplats, big_endian: bool) -> Vec<u8> {
    let names = s.property_names();
    let format = if big_endian {
        "binary_big_endian"
    } else {
        "ascii"
    };
    let mut out = format!("ply\nformat {format} 1.0\nelement vertex {}\n", s.len());
    for n in &names {
        out.push_str(&format!("property float {n}\n"));
    }
    out.push_str("end_header\n");
    let mut bytes = out.into_bytes();
    let r = loader::ply::rest_len(s.sh_degree);
    for i in 0..s.len() {
        let mut row: Vec<f32> = Vec::new();
        row.extend(s.means[i]);
        row.extend([0.0; 3]);
        row.extend(s.f_dc[i]);
        row.extend(&s.f_rest[i * r..(i + 1) * r]);
        row.push(s.opacities[i]);
        row.extend(s.scales[i]);
        row.extend(s.rotations[i]);
        if big_endian {
            row.iter()
                .for_each(|v| bytes.extend_from_slice(&v.to_be_bytes()));
        } else {
            let line: Vec<String> = row.iter().map(|v| v.to_string()).collect();
            bytes.extend_from_slice((line.join(" ") + "\n").as_bytes());
        }
    }
    bytes
}
