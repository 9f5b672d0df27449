//! Splat PLY, every encoding (ASCII, binary little- and big-endian): the one
//! reader; what it accepts must encode and decode to the same splats.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let p = Path::new("fuzz.ply");
    if let Ok(s) = loader::ply::read_ply_bytes(data, p) {
        let bytes = loader::ply::encode_ply(&s, p).expect("read splats must encode");
        let mut back = loader::ply::read_ply_bytes(&bytes, p).expect("encoded splats must read");
        if s.normals.is_none() {
            back.normals = None;
        }
        assert!(back == s, "PLY round trip changed the splats");
    }
});
