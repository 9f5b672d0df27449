//! COLMAP binary model: cameras.bin, images.bin, points3D.bin from one input.
#![no_main]
mod common;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = common::write_parts(data, "bin", &["cameras.bin", "images.bin", "points3D.bin"]);
    if let Ok(m) = loader::colmap::read_model_binary(&dir) {
        // What reads must write back and read again identically.
        let out = dir.join("again");
        loader::colmap::write_model_binary(&m, &out).expect("a model that reads must write");
        let back = loader::colmap::read_model_binary(&out).expect("written model must read");
        // Compared as bytes: the format can carry NaN (the scene loader is
        // what rejects it), and NaN != NaN.
        let again = dir.join("again2");
        loader::colmap::write_model_binary(&back, &again).expect("re-read model must write");
        for name in ["cameras.bin", "images.bin", "points3D.bin"] {
            let a = std::fs::read(out.join(name)).expect("scratch read");
            let b = std::fs::read(again.join(name)).expect("scratch read");
            assert!(a == b, "binary round trip changed {name}");
        }
    }
});
