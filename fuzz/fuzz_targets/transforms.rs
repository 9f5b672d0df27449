//! nerfstudio / instant-ngp transforms.json: parse and resolve against a
//! scratch scene holding one 2×2 image (`images/a.png`).
#![no_main]
mod common;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = common::scratch().join("tf");
    let img = dir.join("images/a.png");
    if !img.is_file() {
        let _ = std::fs::create_dir_all(dir.join("images"));
        loader::io::write_png_gray8(&img, &image_gray()).expect("scratch image");
    }
    let p = dir.join("transforms.json");
    std::fs::write(&p, data).expect("scratch write");
    if let Ok(t) = loader::transforms::read_transforms(&p) {
        let _ = t.resolve(&p, &dir);
    }
});

fn image_gray() -> image::GrayImage {
    image::GrayImage::new(2, 2)
}
