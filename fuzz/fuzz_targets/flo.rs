//! Middlebury `.flo`.
#![no_main]
mod common;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let p = common::scratch().join("f.flo");
    std::fs::write(&p, data).expect("scratch write");
    if let Ok(f) = loader::flo::read_flo(&p) {
        assert_eq!(f.data.len(), f.width as usize * f.height as usize);
    }
});
