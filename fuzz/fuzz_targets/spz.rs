//! Niantic SPZ (gzip): decode, and what decodes must export and read back.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    for axes in [false, true] {
        if let Ok((_, s)) = splat::export::decode_spz(data, axes) {
            let _ = splat::export::encode_checked(
                &s,
                splat::export::ExportFormat::Spz,
                Path::new("fuzz.spz"),
                &Default::default(),
            );
        }
    }
});
