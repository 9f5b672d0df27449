//! COLMAP binary model: cameras.bin, images.bin, points3D.bin from one input.
#![no_main]
mod common;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = common::scratch().join("bin");
    let _ = std::fs::create_dir_all(&dir);
    let parts = common::split_parts(data, 3);
    for (name, bytes) in ["cameras.bin", "images.bin", "points3D.bin"].iter().zip(&parts) {
        std::fs::write(dir.join(name), bytes).expect("scratch write");
    }
    if let Ok(m) = loader::colmap::read_model_binary(&dir) {
        // What reads must write back and read again identically.
        let out = dir.join("again");
        loader::colmap::write_model_binary(&m, &out).expect("a model that reads must write");
        let back = loader::colmap::read_model_binary(&out).expect("written model must read");
        assert!(back == m, "binary round trip changed the model");
    }
});
