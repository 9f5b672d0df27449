//! Float EXR images with 1–3 channels (probability maps, depth, flow), read
//! and written through the `exr` crate (OpenEXR). Channel names: 1 → `Y`,
//! 2 → `R G`, 3 → `R G B`. Values are stored as 32-bit floats, ZIP-compressed
//! (lossless).

use crate::error::{LoaderError, Result};
use crate::io::write_atomic;
use exr::prelude::*;
use std::path::Path;

/// A float image, channels interleaved: `data[(y * width + x) * channels + c]`.
#[derive(Debug, Clone, PartialEq)]
pub struct FloatImage {
    pub width: u32,
    pub height: u32,
    /// 1, 2 or 3.
    pub channels: usize,
    pub data: Vec<f32>,
}

impl FloatImage {
    /// Value of channel `c` at (x, y).
    pub fn get(&self, x: u32, y: u32, c: usize) -> f32 {
        self.data[(y as usize * self.width as usize + x as usize) * self.channels + c]
    }
}

fn names(channels: usize) -> &'static [&'static str] {
    match channels {
        1 => &["Y"],
        2 => &["R", "G"],
        _ => &["R", "G", "B"],
    }
}

/// Write a 1–3 channel float EXR atomically.
pub fn write_exr(path: impl AsRef<Path>, img: &FloatImage) -> Result<()> {
    let path = path.as_ref();
    let n = img.width as usize * img.height as usize;
    if !(1..=3).contains(&img.channels) || img.data.len() != n * img.channels || n == 0 {
        return Err(LoaderError::format(
            path,
            format!(
                "cannot write {}x{}x{} EXR from {} values",
                img.width,
                img.height,
                img.channels,
                img.data.len()
            ),
        ));
    }
    let chans: Vec<AnyChannel<FlatSamples>> = names(img.channels)
        .iter()
        .enumerate()
        .map(|(c, name)| {
            let v: Vec<f32> = (0..n).map(|i| img.data[i * img.channels + c]).collect();
            AnyChannel::new(*name, FlatSamples::F32(v))
        })
        .collect();
    let layer = Layer::new(
        (img.width as usize, img.height as usize),
        LayerAttributes::default(),
        Encoding::FAST_LOSSLESS,
        AnyChannels::sort(chans.into()),
    );
    let mut buf = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .to_buffered(&mut buf)
        .map_err(|e| LoaderError::format(path, format!("EXR encode: {e}")))?;
    let bytes = buf.into_inner();
    write_atomic(path, |w| {
        w.write_all(&bytes).map_err(|e| LoaderError::io(path, e))
    })
}

/// Largest decoded-to-compressed size ratio accepted: zlib (ZIP, ZIPS)
/// cannot exceed about 1032:1, RLE 128:1, the other codecs less.
const MAX_EXPANSION: u64 = 1100;

/// Refuse a header whose layers claim more samples than the file could
/// encode, before the decoder allocates them: allocations stay bounded by
/// the file's size, never by what a header claims.
fn check_claimed_size(path: &Path) -> Result<()> {
    let file_len = std::fs::metadata(path)
        .map_err(|e| LoaderError::io(path, e))?
        .len();
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| LoaderError::format(path, format!("EXR decode: {e}")))?;
    for (i, header) in meta.headers.iter().enumerate() {
        let pixels = header.layer_size.width() as u64 * header.layer_size.height() as u64;
        let bytes_per_pixel: u64 = header
            .channels
            .list
            .iter()
            .map(|c| match c.sample_type {
                exr::meta::attribute::SampleType::F16 => 2,
                _ => 4,
            })
            .sum();
        let claimed = pixels.saturating_mul(bytes_per_pixel);
        if claimed > file_len.saturating_mul(MAX_EXPANSION) {
            return Err(LoaderError::format(
                path,
                format!(
                    "EXR layer {i} claims {}×{} pixels of {bytes_per_pixel} bytes, more than a {file_len}-byte file can hold",
                    header.layer_size.width(),
                    header.layer_size.height()
                ),
            ));
        }
    }
    Ok(())
}

/// Read the first layer of an EXR as a float image. Channels are ordered
/// R, G, B when present (or Y), otherwise alphabetically; at most 3 are kept.
pub fn read_exr(path: impl AsRef<Path>) -> Result<FloatImage> {
    let path = path.as_ref();
    if !path.is_file() {
        return Err(LoaderError::Missing {
            path: path.to_path_buf(),
            context: String::new(),
        });
    }
    check_claimed_size(path)?;
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| LoaderError::format(path, format!("EXR decode: {e}")))?;
    let layer = image.layer_data;
    let (w, h) = (layer.size.width(), layer.size.height());
    let list = &layer.channel_data.list;
    let find = |n: &str| list.iter().position(|c| c.name == *n);
    let mut order: Vec<usize> = ["R", "G", "B"].iter().filter_map(|n| find(n)).collect();
    if order.is_empty() {
        order = find("Y")
            .map(|i| vec![i])
            .unwrap_or_else(|| (0..list.len().min(3)).collect());
    }
    if order.is_empty() {
        return Err(LoaderError::format(path, "EXR has no channels"));
    }
    let cols: Vec<Vec<f32>> = order
        .iter()
        .map(|i| list[*i].sample_data.values_as_f32().collect())
        .collect();
    let n = w * h;
    if cols.iter().any(|c| c.len() != n) {
        return Err(LoaderError::format(
            path,
            "EXR channel has wrong sample count (subsampled channels unsupported)",
        ));
    }
    let channels = cols.len();
    let mut data = vec![0f32; n * channels];
    for (c, col) in cols.iter().enumerate() {
        for (i, v) in col.iter().enumerate() {
            data[i * channels + c] = *v;
        }
    }
    Ok(FloatImage {
        width: w as u32,
        height: h as u32,
        channels,
        data,
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    /// Found by the `exr` fuzz target: a 478-byte file whose data window
    /// claims 136 GB of samples made the decoder abort on allocation.
    #[test]
    fn huge_claimed_size_is_refused_before_allocating() {
        let bytes: &[u8] =
            b"v/1\x01\x02\x02\x00\x00chunkCount\x00in\xff\xff\xff\xff\xff\xff\xff\xff\
              \xff\xfft\x00\x04\x00\x00\x00\x01\x00\x00\x00channels\x00chlist\x00\x13\
              \x00\x00\x00Y\x00\x02\x00\x00\x00\x00\x00\x00\x00\x01\x00\x00\x00\x01\
              \x00\x00\x00\x00compression\x00compression\x00\x01\x00\x00\x00\x01lineOr\
              der\x00lineOrder\x00\x01\x00\x00\x00\x02displayWindow\x00box2i\x00\x10\
              \x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x02\x00\x00\x00\x01\x00\x00\
              \x00pixelAspectRatio\x00float\x00\x04\x00\x00\x00\x00\x00\x80?screenWind\
              owCenter\x00v2f\x00\x08\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00scree\
              nWindowWidth\x00float\x00\x04\x00\x00\x00\x00\x00\x80?dataWindow\x00box2\
              i\x00\x10\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\xf8\xfd\x00\x00\x00\
              \x01\x00\x00\x00type\x00string\x00\x0a\x00\x00\x00tiledimagetiles\x00til\
              edesc\x00\x09\x00\x00\x00@\x00\x00\x00@\x00\x00\x00\x00\x00j\x01\x00\x00\
              \x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\xff\
              \xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\x00\x00\x00\x00\x00\x00\x00\x00\
              \x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\
              \x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\
              \x00\x00\x00\x00\x00\x00\x00\x00\x00@\x18\x00\x00\x00\x00\x00\x80\xbf\
              \x00\x00@\xbf\x00\x00\x00\xbf\x00\x00\x80\xbe\x00\x00\x00\x00\x00\x00\
              \x80>";
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("huge.exr");
        std::fs::write(&p, bytes).unwrap();
        let e = read_exr(&p).unwrap_err().to_string();
        assert!(e.contains("huge.exr") && e.contains("claims"), "{e}");
    }

    #[test]
    fn round_trip_one_two_three_channels() {
        let dir = tempfile::tempdir().unwrap();
        for channels in 1..=3 {
            let (w, h) = (5u32, 3u32);
            let data = (0..(w * h) as usize * channels)
                .map(|i| i as f32 * 0.37 - 2.0)
                .collect();
            let img = FloatImage {
                width: w,
                height: h,
                channels,
                data,
            };
            let p = dir.path().join(format!("c{channels}.exr"));
            write_exr(&p, &img).unwrap();
            let r = read_exr(&p).unwrap();
            assert_eq!(r, img);
            assert_eq!(
                r.get(4, 2, channels - 1),
                img.data[(2 * 5 + 4) * channels + channels - 1]
            );
        }
    }

    #[test]
    fn errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("bad.exr");
        std::fs::write(&p, b"not an exr at all").unwrap();
        let e = read_exr(&p).unwrap_err().to_string();
        assert!(e.contains("bad.exr") && e.contains("EXR decode"), "{e}");
        let e = read_exr(dir.path().join("none.exr"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("none.exr") && e.contains("not found"), "{e}");
        let img = FloatImage {
            width: 2,
            height: 2,
            channels: 4,
            data: vec![0.0; 16],
        };
        let e = write_exr(dir.path().join("o.exr"), &img)
            .unwrap_err()
            .to_string();
        assert!(e.contains("o.exr"), "{e}");
    }
}
