//! The hostile-input table of the reliability issue, through the binary:
//! every bad input gives exit code 1 and one line naming the file and the
//! problem, never a panic, an abort, a silently accepted scene or a partly
//! written output.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use loader::camera::{Camera, CameraModel, Pose};
use loader::colmap::{ColmapImage, ColmapModel, Point3D, write_model_binary};
use std::path::{Path, PathBuf};
use std::process::Command;

/// Run the binary; returns (exit code, stderr).
fn romosplat(args: &[&str]) -> (i32, String) {
    exit_and_stderr(Command::new(env!("CARGO_BIN_EXE_romosplat")).args(args))
}

/// Run `cmd` with `--quiet`; returns (exit code, stderr).
fn exit_and_stderr(cmd: &mut Command) -> (i32, String) {
    let out = cmd
        .arg("--quiet")
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Expect failure with one line holding every `want`.
fn fails(args: &[&str], want: &[&str]) -> String {
    let (code, err) = romosplat(args);
    assert_eq!(code, 1, "romosplat {args:?}: exit {code}: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "not one line: {err}");
    for w in want {
        assert!(err.contains(w), "romosplat {args:?}: {err:?} lacks {w:?}");
    }
    err
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A 3-image scene (48×32 PNGs) with a valid binary COLMAP model.
fn scene(root: &Path) -> PathBuf {
    for k in 0..3u8 {
        let img = image::RgbImage::from_fn(48, 32, |x, y| {
            image::Rgb([x as u8 * 5, y as u8 * 7, k * 80])
        });
        loader::io::write_png_rgb8(root.join(format!("images/{k:03}.png")), &img).unwrap();
    }
    let mut m = ColmapModel::default();
    m.cameras.insert(
        1,
        Camera {
            id: 1,
            model: CameraModel::PINHOLE,
            width: 48,
            height: 32,
            params: vec![40.0, 40.0, 24.0, 16.0],
        },
    );
    for k in 0..3u32 {
        let pose = Pose {
            qvec: [1.0, 0.0, 0.0, 0.0],
            tvec: [k as f64 * 0.1, 0.0, 0.0],
        };
        m.images.insert(
            k + 1,
            ColmapImage::new(k + 1, pose, 1, format!("{k:03}.png")),
        );
    }
    for id in 1..=8u64 {
        m.points3d.insert(
            id,
            Point3D {
                id,
                xyz: [id as f64 * 0.1, 0.2, 3.0],
                rgb: [200, 100, 50],
                error: 0.5,
                track: vec![],
            },
        );
    }
    let sparse = root.join("sparse/0");
    write_model_binary(&m, &sparse).unwrap();
    sparse
}

fn patch(path: &Path, offset: usize, bytes: &[u8]) {
    let mut b = std::fs::read(path).unwrap();
    b[offset..offset + bytes.len()].copy_from_slice(bytes);
    std::fs::write(path, b).unwrap();
}

#[test]
fn bad_scenes_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let train = |scene: &Path, out: &Path, want: &[&str]| {
        fails(
            &[
                "train",
                "--scene",
                s(scene),
                "--steps",
                "2",
                "--backend",
                "cpu",
                "--out",
                s(out),
            ],
            want,
        );
        assert!(!out.exists(), "{} was created", out.display());
    };
    // (binary file, byte offset, new bytes, expected words)
    let cases: [(&str, usize, Vec<u8>, &[&str]); 5] = [
        (
            "points3D.bin",
            16,
            f64::INFINITY.to_le_bytes().to_vec(),
            &["points3D.bin", "point 1", "not finite"],
        ),
        (
            "images.bin",
            12,
            [0u8; 32].to_vec(),
            &["images.bin", "image 1 (000.png)", "quaternion"],
        ),
        (
            "images.bin",
            12,
            f64::NAN.to_le_bytes().to_vec(),
            &["images.bin", "cannot be normalised"],
        ),
        (
            "images.bin",
            68,
            99u32.to_le_bytes().to_vec(),
            &["images.bin", "missing camera 99"],
        ),
        (
            "cameras.bin",
            16,
            0u64.to_le_bytes().to_vec(),
            &["cameras.bin", "camera 1", "image size 0x32"],
        ),
    ];
    for (k, (file, offset, bytes, want)) in cases.iter().enumerate() {
        let root = dir.path().join(format!("s{k}"));
        let sparse = scene(&root);
        patch(&sparse.join(file), *offset, bytes);
        train(&root, &dir.path().join(format!("o{k}")), want);
    }
    // An absurd downscale is refused with its range.
    let root = dir.path().join("ok");
    scene(&root);
    fails(
        &[
            "train",
            "--scene",
            s(&root),
            "--downscale",
            "1000",
            "--steps",
            "2",
            "--backend",
            "cpu",
            "--out",
            s(&dir.path().join("od")),
        ],
        &["downscale 1000", "from 1 to 2"],
    );
    // A split that trains on a held-out view, and one in serde's words.
    std::fs::write(
        root.join("split.json"),
        r#"{"clutter": [0, 1], "extra": [1]}"#,
    )
    .unwrap();
    train(
        &root,
        &dir.path().join("os"),
        &["split.json", "in both clutter"],
    );
    std::fs::write(
        root.join("split.json"),
        r#"{"clutter": [-1], "extra": [2]}"#,
    )
    .unwrap();
    let e = fails(
        &["inspect", s(&root)],
        &["split.json", "index -1 is negative"],
    );
    assert!(!e.contains("untagged"), "{e}");
}

/// A photo cut short in copying (the `image` crate's JPEG decoder fills the
/// rest with grey and reports nothing) stops every stage that reads photos
/// with one line naming it, and nothing is written.
#[test]
fn truncated_jpeg_is_refused_by_every_reader() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("photos");
    std::fs::create_dir_all(root.join("images")).unwrap();
    for k in 0..4u32 {
        let img = image::RgbImage::from_fn(96, 64, |x, y| {
            let v = ((x * 7 + y * 13 + k * 5) % 97) as u8;
            image::Rgb([v * 2, 255 - v, (x * 2) as u8])
        });
        let mut bytes = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 90)
            .encode_image(&img)
            .unwrap();
        if k == 2 {
            bytes.truncate(bytes.len() * 2 / 3);
        }
        std::fs::write(root.join(format!("images/{k:03}.jpg")), bytes).unwrap();
    }
    let bad = root.join("images/002.jpg");
    for cmd in ["mask", "keyframes"] {
        let out = dir.path().join(cmd);
        fails(
            &[cmd, "--scene", s(&root), "--out", s(&out)],
            &[s(&bad), "truncated JPEG"],
        );
        assert!(!out.exists(), "{cmd} wrote {}", out.display());
    }
}

/// Without `XDG_RUNTIME_DIR` (a root shell, a container) wgpu's Vulkan
/// loader printed two "error: XDG_RUNTIME_DIR is invalid" lines that read
/// as romosplat's own; the binary now gives itself a private one.
#[test]
fn no_runtime_dir_prints_no_loader_noise() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let out = Command::new(env!("CARGO_BIN_EXE_romosplat"))
        .args([
            "--quiet",
            "bench",
            "train",
            "--backend",
            "wgpu",
            "--steps",
            "1",
        ])
        .current_dir(&root)
        .env_remove("XDG_RUNTIME_DIR")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("XDG_RUNTIME_DIR"), "{err}");
    // Without a Vulkan driver the wgpu bench fails by its own error.
    assert!(out.status.success() || err.contains("wgpu"), "{err}");
}

/// A splat PLY (INRIA layout, SH 0) as text, with `n` in the header.
fn ascii_ply(count: &str, rows: &[&str]) -> String {
    let mut t = format!("ply\nformat ascii 1.0\nelement vertex {count}\n");
    for p in [
        "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
        "rot_0", "rot_1", "rot_2", "rot_3",
    ] {
        t += &format!("property float {p}\n");
    }
    t += "end_header\n";
    for r in rows {
        t += r;
        t += "\n";
    }
    t
}

#[test]
fn splat_files_read_everywhere_and_exports_read_back() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let rows = [
        "0 0 3 0.1 0.2 0.3 1 -2 -2 -2 1 0 0 0",
        "0.5 0 3 0.3 0.2 0.1 0 -2 -2 -3 1 0 0 0",
    ];
    // A header claiming 10^12 vertices: an error, not SIGABRT.
    let huge = d.join("huge.ply");
    std::fs::write(&huge, ascii_ply("1000000000000", &rows)).unwrap();
    fails(&["inspect", s(&huge)], &["huge.ply", "truncated"]);
    // NaN splats are refused by every reader, naming splat and property.
    let nan = d.join("nan.ply");
    std::fs::write(
        &nan,
        ascii_ply("2", &[rows[0], "0 nan 3 0 0 0 0 -2 -2 -2 1 0 0 0"]),
    )
    .unwrap();
    let want = ["nan.ply", "splat 1", "property y"];
    fails(&["inspect", s(&nan)], &want);
    fails(
        &["export", "--splats", s(&nan), "--out", s(&d.join("n.spz"))],
        &want,
    );
    fails(
        &[
            "render",
            "--splats",
            s(&nan),
            "--scene",
            s(d),
            "--out",
            s(&d.join("r")),
        ],
        &want,
    );
    // ASCII PLY is read by export; every exported format reads back.
    let ascii = d.join("a.ply");
    std::fs::write(&ascii, ascii_ply("2", &rows)).unwrap();
    for ext in ["ply", "spz", "splat", "glb"] {
        let out = d.join(format!("e.{ext}"));
        let (code, err) = romosplat(&["export", "--splats", s(&ascii), "--out", s(&out)]);
        assert_eq!(code, 0, "{err}");
        let (code, err) = romosplat(&["inspect", s(&out)]);
        assert_eq!(code, 0, "inspect {ext}: {err}");
        let (code, err) = romosplat(&[
            "export",
            "--splats",
            s(&out),
            "--out",
            s(&d.join(format!("again_{ext}.ply"))),
        ]);
        assert_eq!(code, 0, "re-export {ext}: {err}");
    }
    // A format that contradicts the extension, or a folder as --out.
    let glb = d.join("x.glb");
    fails(
        &[
            "export",
            "--splats",
            s(&ascii),
            "--format",
            "ply",
            "--out",
            s(&glb),
        ],
        &["x.glb", "--format is ply"],
    );
    assert!(!glb.exists());
    std::fs::create_dir(d.join("folder")).unwrap();
    fails(
        &[
            "export",
            "--splats",
            s(&ascii),
            "--out",
            &format!("{}/", s(&d.join("folder"))),
        ],
        &["is a folder"],
    );
    // An OS error is printed once.
    let e = fails(
        &[
            "export",
            "--splats",
            s(&ascii),
            "--out",
            s(&ascii.join("x.spz")),
        ],
        &["a.ply"],
    );
    assert_eq!(e.matches("os error").count(), 1, "{e}");
}

#[test]
fn toml_errors_are_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "name = \"x\"\nwidth = [\n").unwrap();
    fails(
        &[
            "scene",
            "generate",
            s(&bad),
            "--out",
            s(&dir.path().join("o")),
        ],
        &["bad.toml", "line "],
    );
}

/// `scenes/rotation.toml` (a camera that only turns) cut to 4 frames of
/// `w`×`h` without held-out views, generated into `dir/rot`.
fn short_pan(dir: &Path, w: u32, h: u32) -> PathBuf {
    let spec = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/rotation.toml"),
    )
    .unwrap();
    let spec = spec
        .replace("frames = 16", "frames = 4")
        .replace("width = 320", &format!("width = {w}"))
        .replace("height = 240", &format!("height = {h}"))
        .replace("supersample = 3", "supersample = 1")
        .replace("test_views = 2", "test_views = 0");
    assert!(spec.contains("frames = 4") && spec.contains("test_views = 0"));
    std::fs::create_dir_all(dir).unwrap();
    let toml = dir.join("rotation.toml");
    std::fs::write(&toml, spec).unwrap();
    let scene = dir.join("rot");
    let (code, err) = romosplat(&["scene", "generate", s(&toml), "--out", s(&scene)]);
    assert_eq!(code, 0, "{err}");
    std::fs::remove_file(&toml).unwrap();
    scene
}

/// A camera that only turns gives COLMAP nothing to triangulate. COLMAP
/// still builds a model from a few noisy points on this short pan; `pose`
/// reads the matcher's verdicts from its database and warns that there is
/// little or no parallax, and its report counts the pairs. When the mapper
/// fails, the error names "no parallax" as the cause.
#[test]
fn pure_rotation_pose_names_no_parallax() {
    let dir = tempfile::tempdir().unwrap();
    let scene = short_pan(dir.path(), 240, 180);
    let out = Command::new(env!("CARGO_BIN_EXE_romosplat"))
        .args(["--json", "pose", "--scene", s(&scene), "--no-masks"])
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    if out.status.success() {
        assert!(err.contains("little or no parallax"), "{err}");
        let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let pairs = &report["pairs"];
        assert!(pairs["verified"].as_u64().unwrap() > 0, "{report}");
        assert_eq!(pairs["general"].as_u64(), Some(0), "{report}");
    } else {
        let line = err.trim_end().lines().last().unwrap_or_default();
        assert!(line.contains("no parallax"), "{err}");
    }
}

/// Run the binary with writes failing beyond `blocks` 512-byte blocks per
/// file (RLIMIT_FSIZE, SIGXFSZ ignored, so a write returns EFBIG as a full
/// disk returns ENOSPC); returns (exit code, stderr).
fn romosplat_file_limit(blocks: u32, args: &[&str]) -> (i32, String) {
    exit_and_stderr(
        Command::new("sh")
            .arg("-c")
            .arg(format!(
                "trap '' XFSZ; ulimit -f {blocks}; exec \"$0\" \"$@\""
            ))
            .arg(env!("CARGO_BIN_EXE_romosplat"))
            .args(args),
    )
}

/// Entries of `dir`, sorted.
fn entries(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// A write that fails part way (a full disk) leaves neither the output
/// folder nor a staging folder behind, and says which file in one line.
#[test]
fn failed_writes_leave_no_partial_output() {
    let dir = tempfile::tempdir().unwrap();
    // `train` on the 3-image scene: every file it writes fails.
    let root = dir.path().join("train");
    scene(&root);
    let before = entries(&root);
    let out = root.join("tr");
    let (code, err) = romosplat_file_limit(
        0,
        &[
            "train",
            "--scene",
            s(&root),
            "--steps",
            "2",
            "--out",
            s(&out),
        ],
    );
    assert_eq!(code, 1, "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("File too large"), "{err}");
    // The file is named where the user asked for it, not in the hidden
    // staging folder.
    assert!(err.contains(s(&out)) && !err.contains(".stage."), "{err}");
    assert_eq!(entries(&root), before, "{err}");

    // `mask --out` on a small generated scene with a transforms.json: the
    // masks are written, then the nerfstudio copy of transforms.json fails.
    let parent = dir.path().join("gen");
    let sc = short_pan(&parent, 320, 240);
    // Masks of 320×240 are about 1 KB, transforms.json about 3 KB.
    let (code, err) = romosplat_file_limit(
        4,
        &["mask", "--scene", s(&sc), "--out", s(&parent.join("m"))],
    );
    assert_eq!(code, 1, "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("transforms.json"), "{err}");
    assert!(
        err.contains(&format!("{}/transforms.json", s(&parent.join("m")))),
        "{err}"
    );
    assert!(!err.contains(".stage."), "{err}");
    assert_eq!(entries(&parent), vec!["rot".to_string()], "{err}");
    // With room, the same command writes masks and the copy.
    let (code, err) = romosplat(&["mask", "--scene", s(&sc), "--out", s(&parent.join("m"))]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        entries(&parent.join("m")),
        vec!["images", "masks", "transforms.json"]
    );
}
