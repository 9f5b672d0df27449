//! antimatter15 `.splat` (32-byte records).
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    if let Ok(s) = splat::export::decode_splat(data) {
        let _ = splat::export::encode_checked(
            &s,
            splat::export::ExportFormat::Splat,
            Path::new("fuzz.splat"),
            &Default::default(),
        );
    }
});
