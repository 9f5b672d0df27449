//! NeRF On-the-go split.json: parse and resolve against four image names.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let p = Path::new("split.json");
    if let Ok(s) = loader::split::parse_split(text, p) {
        let names: Vec<String> = ["000.png", "001.png", "002.jpg", "003.jpg"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        if let Ok(r) = s.resolve(p, &names) {
            assert!(r.clutter.iter().chain(&r.extra).all(|i| *i < names.len()));
        }
    }
});
