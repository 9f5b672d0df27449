//! Float EXR images with 1–3 channels (probability maps, depth, flow), read
//! and written through the `exr` crate (OpenEXR). Channel names: 1 → `Y`,
//! 2 → `R G`, 3 → `R G B`. Values are stored as 32-bit floats, ZIP-compressed
//! (lossless).

use crate::error::{LoaderError, Result};
use crate::io::write_atomic;
use exr::block::UncompressedBlock;
use exr::meta::attribute::SampleType;
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

/// Refuse a header that claims more than the file could encode, before the
/// decoder allocates it: allocations stay bounded by the file's size, never
/// by what a header claims. Checked per layer: the pixel data, the largest
/// block (a tile or a group of scan lines, which the decoder allocates whole
/// for every chunk it reads) and the chunk count (8 bytes of offset each).
fn check_claimed_size(path: &Path, meta: &exr::meta::MetaData, file_len: u64) -> Result<()> {
    let budget = file_len.saturating_mul(MAX_EXPANSION);
    for (i, header) in meta.headers.iter().enumerate() {
        let bytes_per_pixel: u64 = header
            .channels
            .list
            .iter()
            .map(|c| match c.sample_type {
                exr::meta::attribute::SampleType::F16 => 2,
                _ => 4,
            })
            .sum();
        let (w, h) = (
            header.layer_size.width() as u64,
            header.layer_size.height() as u64,
        );
        let (block_w, block_h) = match header.blocks {
            exr::meta::BlockDescription::Tiles(t) => {
                (t.tile_size.width() as u64, t.tile_size.height() as u64)
            }
            exr::meta::BlockDescription::ScanLines => {
                (w, header.compression.scan_lines_per_block() as u64)
            }
        };
        let claims = [("pixels", w, h), ("block", block_w, block_h)];
        for (what, cw, ch) in claims {
            if cw.saturating_mul(ch).saturating_mul(bytes_per_pixel) > budget {
                return Err(LoaderError::format(
                    path,
                    format!(
                        "EXR layer {i} claims {what} of {cw}×{ch} samples of {bytes_per_pixel} bytes, more than a {file_len}-byte file can hold"
                    ),
                ));
            }
        }
        if (header.chunk_count as u64).saturating_mul(8) > file_len {
            return Err(LoaderError::format(
                path,
                format!(
                    "EXR layer {i} claims {} chunks, more than a {file_len}-byte file can hold",
                    header.chunk_count
                ),
            ));
        }
    }
    Ok(())
}

/// Read the first layer of an EXR as a float image. Channels are ordered
/// R, G, B when present (or Y), otherwise alphabetically; at most 3 are kept.
/// Only the full-resolution level is read; subsampled channels and deep data
/// are refused.
///
/// Decoding goes block by block through the `exr` crate's block API, on the
/// calling thread, and every decoded line is checked against the layer
/// before it is stored: a chunk whose own coordinates disagree with the
/// offset table (another layer or level, or outside the data window) is an
/// error, never a write out of place.
pub fn read_exr(path: impl AsRef<Path>) -> Result<FloatImage> {
    let path = path.as_ref();
    if !path.is_file() {
        return Err(LoaderError::Missing {
            path: path.to_path_buf(),
            context: String::new(),
        });
    }
    let bad = |what: String| LoaderError::format(path, what);
    let decode = |e: exr::error::Error| bad(format!("EXR decode: {e}"));
    let file = std::fs::File::open(path).map_err(|e| LoaderError::io(path, e))?;
    let file_len = file.metadata().map_err(|e| LoaderError::io(path, e))?.len();
    // Reads the headers only; the offset tables and chunks come after the check.
    let reader = exr::block::read(std::io::BufReader::new(file), false).map_err(decode)?;
    let meta = reader.meta_data().clone();
    check_claimed_size(path, &meta, file_len)?;
    let header = meta
        .headers
        .first()
        .ok_or_else(|| bad("EXR has no layers".into()))?;
    if header.deep {
        return Err(bad("EXR deep data is not supported".into()));
    }
    let list = &header.channels.list;
    if list.iter().any(|c| c.sampling != Vec2(1, 1)) {
        return Err(bad(
            "EXR channel is subsampled (subsampled channels are not supported)".into(),
        ));
    }
    let find = |n: &str| list.iter().position(|c| c.name == *n);
    let mut order: Vec<usize> = ["R", "G", "B"].iter().filter_map(|n| find(n)).collect();
    if order.is_empty() {
        order = find("Y")
            .map(|i| vec![i])
            .unwrap_or_else(|| (0..list.len().min(3)).collect());
    }
    if order.is_empty() {
        return Err(bad("EXR has no channels".into()));
    }
    let channels = order.len();
    let (w, h) = (header.layer_size.width(), header.layer_size.height());
    let full_res = Vec2(0, 0);
    let chunks = reader
        .filter_chunks(false, |_, tile, block| {
            block.layer == 0 && tile.level_index == full_res
        })
        .map_err(decode)?;
    let mut data = vec![0f32; w * h * channels];
    for chunk in chunks {
        let block = UncompressedBlock::decompress_chunk(chunk.map_err(decode)?, &meta, false)
            .map_err(decode)?;
        if block.index.layer != 0 || block.index.level != full_res {
            return Err(bad(format!(
                "EXR chunk of layer {} level {:?} stands where the offset table puts the first layer's full resolution",
                block.index.layer, block.index.level
            )));
        }
        for line in block.lines(&header.channels) {
            let at = line.location;
            let Some(c) = order.iter().position(|&o| o == at.channel) else {
                continue;
            };
            let (x, y, n) = (at.position.x(), at.position.y(), at.sample_count);
            if y >= h
                || x + n > w
                || line.value.len() < n * list[at.channel].sample_type.bytes_per_sample()
            {
                return Err(bad(format!(
                    "EXR line at ({x}, {y}) of {n} samples lies outside the {w}×{h} layer"
                )));
            }
            let row = &mut data[(y * w + x) * channels..(y * w + x + n) * channels];
            let dst = row.iter_mut().skip(c).step_by(channels);
            match list[at.channel].sample_type {
                SampleType::F16 => store(dst, line.read_samples::<f16>(), f16::to_f32),
                SampleType::F32 => store(dst, line.read_samples::<f32>(), |v| v),
                SampleType::U32 => store(dst, line.read_samples::<u32>(), |v| v as f32),
            }
            .map_err(decode)?;
        }
    }
    Ok(FloatImage {
        width: w as u32,
        height: h as u32,
        channels,
        data,
    })
}

/// Store decoded samples, converted to f32, into the destination slots.
fn store<'a, T>(
    dst: impl Iterator<Item = &'a mut f32>,
    samples: impl Iterator<Item = exr::error::Result<T>>,
    to_f32: impl Fn(T) -> f32,
) -> exr::error::Result<()> {
    for (d, v) in dst.zip(samples) {
        *d = to_f32(v?);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `read_exr`'s error for `bytes` written as `name`; it names the file.
    fn refusal(name: &str, bytes: &[u8]) -> String {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        let e = read_exr(&p).unwrap_err().to_string();
        assert!(e.contains(name), "{e}");
        e
    }

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
        let e = refusal("huge.exr", bytes);
        assert!(e.contains("claims"), "{e}");
    }

    /// Found by the `exr` fuzz target: a 488-byte tiled file with a 2×1
    /// layer but tiles that claim 2^30 samples each made the decoder zero a
    /// 1.6 GB block buffer per chunk (1.7 GB of memory, 40 s).
    #[test]
    fn huge_claimed_tile_is_refused_before_allocating() {
        let bytes: &[u8] = b"v/1\x01\x02\x02\x00\x00chunkCount\x00int\x00\x04\x00\x00\x00\x01\x00\
              \x00\x00channels\x00chlist\x00\x13\x00\x00\x00Y\x00\x02\x00\x00\x00\
              \x00\x00\x00\x00\x01\x00\x00\x00\x01\x00\x00\x00\x00compression\x00c\
              ompression\x00\x01\x00\x00\x00\x01li\x92\x90Order\x00lineOrder\x00\
              \x01\x00\x00\x00\x02displayWindow\x00box2i\x00\x10\x00\x00\x00\x00\
              \x00\x00\x00\x00\x00\x00\x00\x02\x00\x00\x00\x01\x00\x00\x00pixelAsp\
              ectRatio\x00floaplt\x00\x04\x00\x00\x00\x00\x00\x80?screenWinduwCent\
              er\x00v2f\x00\x08\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00scrloat\
              \x00\x04\x00\x00\x00\x00\x00\x80?dataWindow\x00box2i\x00\x10\x00\x00\
              \x00\x00\x00\x00\x00\x00\x00\x00\x00\x02\x00\x00\x00\x01\x00\x00\x00\
              type\x00rtring\x00\x0a\x00\x00\x00tiledimageteenWindowWidth\x00float\
              \x00\x04\x00\x00\x00\x00\x00\x80?dataWindow\x00box2i\x00\x10\x00\x00\
              \x00\x00\x00\x00\x00\x00\x00\x00\x00\x02\x00\x00\x00\x01\x00\x00\x00\
              type\x00string\x00\x0a\x00\x00\x00tiledimagetiles\x00tiledesc\x00\
              \x09\x00\x00\x00@\x00\x00*@\x00\x00\x00\x00\x00j\x01\x00\x00\x00\x00\
              \x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x06\x00\x00\
              \x00\x18\x00\x00\x00\x00\x00\x80\xbf\x00\x00@\xbf\x00\x00\x00\xbf\
              \x00\x00\xff\xff\xff\xff\xff\xff\xff\xff\xff\x00\x00\x80>";
        let e = refusal("tile.exr", bytes);
        assert!(e.contains("claims block"), "{e}");
    }

    /// Found by the `exr` fuzz target: a 559-byte file whose chunk header
    /// names a lower mip level than its offset-table slot, so the decoded
    /// lines belong elsewhere (the `exr` crate's own reader asserts on it).
    #[test]
    fn chunk_disagreeing_with_its_offset_table_is_refused() {
        let bytes: &[u8] = b"v/1\x01\x02\x02\x00\x00chunkCo\x8ant\x00int\x00\x04\x00\x00\x00\x01\
              \x00\x00\x00channels\x00chlist\x00\x13\x00\x00\x00Y\x00\x02\x00\x00\
              \x00\x00\x00\x00\x00\x01\x00\x00\x00\x01\x00\x00\x00\x00compression\
              \x00compression\x00\x01\x00\x00\x00\x01lineOrder\x00lineOrder\x00\
              \x01\x00\x00\x00\x02displayWindow\x00box2i\x00\x10\x00\x00\x00\x00\
              \x00\x00\x00\x00\x00\x00\x00\x02\x00\x00\x00\x01\x00\x00\x00pixelAsp\
              ectRatio\x00float\x00\x04\x00\x00\x00\x00\x00\x80\xad?screenWindowCe\
              nter\x00v1f\x00\x08\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00scree\
              nWindowW/dth\x00float\x00\x04\x00\x00\x00\x00\x00\x80?dataWindow\x00\
              box2i\x00\x10\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x02\x00\
              \x00\x00\x01\x00\x00\x00type\x00string\x00\x0a\x00\x00\x00tiledimage\
              tiles\x00tiledesc\x00\x09\x00\x00\x00@\x00\x00\x00@\x00\x00\x00\x00\
              \x00j\x01\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x04\
              \x00\x00\x00\x00\x00\x00\x00H\x00\x00\x00\x00\x00\x00\x00\x00\x05\
              \x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\
              \x00A\x00\x00\x00\x00\x00ssion\x00\x01\x00\x00\x00\x01lineOrder\x00l\
              ineOrder\x00\x01\x00\x00\x00\x02displayWindow\x00b\xff\xff\xff\xff\
              \xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\
              \xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\
              \xff\xff\xff\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\
              \x00\x00\x00\x00\x00\x01\x00\x00\x00\x00\x00\x00\x08\x18\x00\x00\x00\
              \x00\x00\x80\xbf\x00\x00@\xbf\x00\x00\x00\xbf\x00\x00\x80\xbe\x00\
              \x00\x00\x00\x00\x00\x80>";
        let e = refusal("level.exr", bytes);
        assert!(e.contains("EXR"), "{e}");
        assert_eq!(e.lines().count(), 1, "{e}");
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
        let e = refusal("bad.exr", b"not an exr at all");
        assert!(e.contains("EXR decode"), "{e}");
        let dir = tempfile::tempdir().unwrap();
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
