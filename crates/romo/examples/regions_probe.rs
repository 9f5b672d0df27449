//! Measurement aid (not a test): flow segments of one frame pair, as a
//! colour image beside the frame. `regions_probe A.png B.png K OUT.png`.
#![allow(clippy::unwrap_used, clippy::expect_used)]
use romo::flow::FlowEstimator;
use romo::plane::Rgb;
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let o = romo::RomoOptions::default();
    let fa = Rgb::from_image(&loader::io::read_rgb32f(std::path::Path::new(&a[1])).unwrap());
    let fb = Rgb::from_image(&loader::io::read_rgb32f(std::path::Path::new(&a[2])).unwrap());
    let k: f32 = a[3].parse().unwrap();
    let (gw, gh) = o.grid_size(fa.w(), fa.h());
    let dis = romo::flow::dis::Dis::new(o.flow.clone());
    let (ga, gb) = (
        fa.resize(2 * gw, 2 * gh).gray(),
        fb.resize(2 * gw, 2 * gh).gray(),
    );
    let f = dis.flow(&ga, &gb).unwrap().resize(gw, gh);
    let lab = romo::regions::flow_segments(&f, f.mean_magnitude(), k, 20);
    let small = fa.resize(gw, gh);
    let img = image::RgbImage::from_fn(2 * gw as u32, gh as u32, |x, y| {
        let (s, x) = (x as usize / gw, x as usize % gw);
        let i = y as usize * gw + x;
        if s == 0 {
            let b = |v: f32| (v.clamp(0.0, 1.0) * 255.0) as u8;
            image::Rgb([
                b(small.c[0].data[i]),
                b(small.c[1].data[i]),
                b(small.c[2].data[i]),
            ])
        } else {
            let h = (lab[i] as u64).wrapping_mul(0x9E3779B97F4A7C15);
            image::Rgb([(h >> 16) as u8, (h >> 32) as u8, (h >> 48) as u8])
        }
    });
    img.save(&a[4]).unwrap();
}
