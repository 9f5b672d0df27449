//! COLMAP text model: cameras.txt, images.txt, points3D.txt from one input.
#![no_main]
mod common;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = common::write_parts(data, "txt", &["cameras.txt", "images.txt", "points3D.txt"]);
    if let Ok(m) = loader::colmap::read_model_text(&dir) {
        let out = dir.join("again");
        loader::colmap::write_model_text(&m, &out).expect("a model that reads must write");
        let back = loader::colmap::read_model_text(&out).expect("written model must read");
        assert!(back.cameras == m.cameras && back.images.len() == m.images.len());
    }
});
