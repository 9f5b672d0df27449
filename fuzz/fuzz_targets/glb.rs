//! glTF binary with KHR_gaussian_splatting.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = splat::export::decode_glb(data, true);
});
