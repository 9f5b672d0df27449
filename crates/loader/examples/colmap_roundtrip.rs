//! Check that a COLMAP model (e.g. written by real COLMAP) round-trips:
//! binary read → write is byte-identical, and text write → read gives the
//! same model. `cargo run -p loader --example colmap_roundtrip -- MODEL_DIR`.
//! Prints one JSON line; exit code 1 when anything differs.

use loader::colmap::{read_model_binary, read_model_text, write_model_binary, write_model_text};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::env::args()
        .nth(1)
        .ok_or("usage: colmap_roundtrip MODEL_DIR")?;
    let dir = std::path::Path::new(&dir);
    let model = read_model_binary(dir)?;
    let tmp = tempfile::tempdir()?;
    write_model_binary(&model, tmp.path().join("bin"))?;
    let mut same = true;
    for f in ["cameras.bin", "images.bin", "points3D.bin"] {
        let a = std::fs::read(dir.join(f))?;
        let b = std::fs::read(tmp.path().join("bin").join(f))?;
        same &= a == b;
    }
    write_model_text(&model, tmp.path().join("txt"))?;
    let t = read_model_text(tmp.path().join("txt"))?;
    let text_same =
        t.cameras == model.cameras && t.images == model.images && t.points3d == model.points3d;
    println!(
        "{}",
        serde_json::json!({
            "model": dir, "cameras": model.cameras.len(), "images": model.images.len(),
            "points3d": model.points3d.len(), "binary_byte_exact": same, "text_lossless": text_same
        })
    );
    if same && text_same {
        Ok(())
    } else {
        Err("round trip differs".into())
    }
}
