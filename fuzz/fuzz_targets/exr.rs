//! Float EXR (1–3 channels).
#![no_main]
mod common;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let p = common::scratch().join("f.exr");
    std::fs::write(&p, data).expect("scratch write");
    let _ = loader::exr::read_exr(&p);
});
