//! COLMAP text model: cameras.txt, images.txt, points3D.txt from one input.
#![no_main]
mod common;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = common::scratch().join("txt");
    let _ = std::fs::create_dir_all(&dir);
    let parts = common::split_parts(data, 3);
    for (name, bytes) in ["cameras.txt", "images.txt", "points3D.txt"].iter().zip(&parts) {
        std::fs::write(dir.join(name), bytes).expect("scratch write");
    }
    if let Ok(m) = loader::colmap::read_model_text(&dir) {
        let out = dir.join("again");
        loader::colmap::write_model_text(&m, &out).expect("a model that reads must write");
        let back = loader::colmap::read_model_text(&out).expect("written model must read");
        assert!(back.cameras == m.cameras && back.images.len() == m.images.len());
    }
});
