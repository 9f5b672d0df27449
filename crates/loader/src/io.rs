//! File I/O helpers every crate uses: atomic writes (temp file in the same
//! directory, then rename, so a crash never leaves a half-written output) and
//! image reading/writing with errors that name the file.

use crate::error::{LoaderError, Result};
use image::{GrayImage, ImageBuffer, Rgb32FImage, RgbImage};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

static TMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// A unique temporary path next to `path` (same directory, so `rename` is atomic).
fn temp_path_for(path: &Path) -> PathBuf {
    let n = TMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    let name = path
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    let tmp = format!(".{name}.tmp.{}.{n}", std::process::id());
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.join(tmp),
        _ => PathBuf::from(tmp),
    }
}

/// Write `path` atomically: `f` writes into a buffered temp file in the same
/// directory, which is flushed and renamed over `path`. Parent
/// directories are created. On any error the temp file is removed and `path`
/// is left untouched.
///
/// `f` returns the loader's [`Result`]; plain I/O errors inside it can be
/// mapped with `LoaderError::io(path, e)`, or use `?` on `std::io::Result`
/// through [`io_ctx`].
pub fn write_atomic<F>(path: impl AsRef<Path>, f: F) -> Result<()>
where
    F: FnOnce(&mut dyn Write) -> Result<()>,
{
    let path = path.as_ref();
    if let Some(parent) = path.parent()
        && !parent.as_os_str().is_empty()
    {
        std::fs::create_dir_all(parent).map_err(|e| LoaderError::io(parent, e))?;
    }
    let tmp = temp_path_for(path);
    let result = (|| -> Result<()> {
        let file = std::fs::File::create(&tmp).map_err(|e| LoaderError::io(path, e))?;
        let mut w = BufWriter::with_capacity(1 << 20, file);
        f(&mut w)?;
        // No fsync: the rename already guarantees that readers never see a
        // half-written file if this process dies; fsync would only add
        // durability against power loss, at a large cost per file.
        drop(
            w.into_inner()
                .map_err(|e| LoaderError::io(path, e.into_error()))?,
        );
        std::fs::rename(&tmp, path).map_err(|e| LoaderError::io(path, e))
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// A folder of outputs that appears completely or not at all: a stage
/// writes its files into [`Staging::path`] (a hidden sibling of the
/// destination, on the same file system) and [`Staging::commit`] moves them
/// into place with renames, which need no disk space. Dropping an
/// uncommitted staging folder deletes it, so a failed stage (disk full, bad
/// input, a panic unwinding) leaves the destination as it was.
///
/// When the destination does not exist the whole folder is renamed in one
/// step; otherwise each staged entry is renamed over its counterpart
/// (files replaced, folders merged), leaving other files there untouched.
#[derive(Debug)]
pub struct Staging {
    stage: PathBuf,
    dest: PathBuf,
    committed: bool,
}

impl Staging {
    /// Create the staging folder for `dest` (its parent is created if needed).
    pub fn new(dest: impl AsRef<Path>) -> Result<Staging> {
        let dest = dest.as_ref().to_path_buf();
        let parent = match dest.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let name = dest
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "out".into());
        let n = TMP_COUNTER.fetch_add(1, Ordering::Relaxed);
        let stage = parent.join(format!(".{name}.stage.{}.{n}", std::process::id()));
        std::fs::create_dir_all(&stage).map_err(|e| LoaderError::io(&stage, e))?;
        Ok(Staging {
            stage,
            dest,
            committed: false,
        })
    }

    /// The folder to write into.
    pub fn path(&self) -> &Path {
        &self.stage
    }

    /// The final destination.
    pub fn dest(&self) -> &Path {
        &self.dest
    }

    /// `text` (an error message) with the hidden staging folder named as
    /// the destination it stands for: what a user should read.
    pub fn public(&self, text: &str) -> String {
        text.replace(&*self.stage.to_string_lossy(), &self.dest.to_string_lossy())
    }

    /// Move everything staged into the destination.
    pub fn commit(mut self) -> Result<PathBuf> {
        if !self.dest.exists() {
            std::fs::rename(&self.stage, &self.dest).map_err(|e| LoaderError::io(&self.dest, e))?;
        } else {
            if !self.dest.is_dir() {
                return Err(LoaderError::format(
                    &self.dest,
                    "exists and is not a folder; choose another output path",
                ));
            }
            merge_move(&self.stage, &self.dest)?;
            let _ = std::fs::remove_dir_all(&self.stage);
        }
        self.committed = true;
        Ok(self.dest.clone())
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.stage);
        }
    }
}

/// Rename every entry of `from` into `to`: files replace files, folders are
/// merged (created by renaming when absent).
fn merge_move(from: &Path, to: &Path) -> Result<()> {
    let entries = std::fs::read_dir(from).map_err(|e| LoaderError::io(from, e))?;
    for entry in entries {
        let entry = entry.map_err(|e| LoaderError::io(from, e))?;
        let src = entry.path();
        let dst = to.join(entry.file_name());
        if src.is_dir() && dst.is_dir() {
            merge_move(&src, &dst)?;
        } else {
            if dst.is_dir() {
                return Err(LoaderError::format(
                    &dst,
                    "is a folder where a file was to be written",
                ));
            }
            std::fs::rename(&src, &dst).map_err(|e| LoaderError::io(&dst, e))?;
        }
    }
    Ok(())
}

/// Write `bytes` to `path` atomically.
pub fn write_bytes_atomic(path: impl AsRef<Path>, bytes: &[u8]) -> Result<()> {
    let path = path.as_ref();
    write_atomic(path, |w| {
        w.write_all(bytes).map_err(|e| LoaderError::io(path, e))
    })
}

/// Adapter: turn a `std::io::Result` into the loader's result for `path`.
pub fn io_ctx<T>(path: &Path, r: std::io::Result<T>) -> Result<T> {
    r.map_err(|e| LoaderError::io(path, e))
}

/// Read a whole file, naming it on error.
pub fn read_bytes(path: impl AsRef<Path>) -> Result<Vec<u8>> {
    let path = path.as_ref();
    std::fs::read(path).map_err(|e| open_error(path, e))
}

/// Read a whole text file, naming it on error.
pub fn read_string(path: impl AsRef<Path>) -> Result<String> {
    let path = path.as_ref();
    std::fs::read_to_string(path).map_err(|e| open_error(path, e))
}

fn open_error(path: &Path, e: std::io::Error) -> LoaderError {
    if e.kind() == std::io::ErrorKind::NotFound {
        LoaderError::Missing {
            path: path.to_path_buf(),
            context: String::new(),
        }
    } else {
        LoaderError::io(path, e)
    }
}

/// Read an image in its own pixel format (8- or 16-bit, grey or colour),
/// refusing truncated JPEGs ([`jpeg_truncation`]).
pub fn read_image(path: impl AsRef<Path>) -> Result<image::DynamicImage> {
    open_image(path.as_ref())
}

fn open_image(path: &Path) -> Result<image::DynamicImage> {
    if !path.exists() {
        return Err(LoaderError::Missing {
            path: path.to_path_buf(),
            context: String::new(),
        });
    }
    let bytes = read_bytes(path)?;
    if let Some(problem) = jpeg_truncation(&bytes) {
        return Err(LoaderError::format(path, problem));
    }
    let reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| LoaderError::io(path, e))?;
    reader.decode().map_err(|e| LoaderError::image(path, e))
}

/// Why a JPEG file is cut short, or None when it is complete or not a JPEG.
///
/// The `image` crate's JPEG decoder fills the missing part of a truncated
/// file with grey and reports no error (libjpeg warns "premature end of
/// data"), so a half-copied photo would be used as if whole. The check
/// walks the marker segments up to the first start-of-scan and then looks
/// for the end-of-image marker after it: inside entropy-coded data a 0xFF
/// byte is always followed by 0x00 or a restart marker, so `FF D9` there is
/// the real end (an embedded thumbnail's end marker lies before the scan).
/// Bytes after the end marker (a phone's appended motion-photo video) are
/// allowed. Anything the walk does not understand is left to the decoder.
pub fn jpeg_truncation(bytes: &[u8]) -> Option<&'static str> {
    if bytes.len() < 4 || bytes[0] != 0xFF || bytes[1] != 0xD8 {
        return None;
    }
    let mut i = 2;
    loop {
        // Markers may be preceded by any number of 0xFF fill bytes.
        if i >= bytes.len() {
            return Some("truncated JPEG: the file ends before its image data");
        }
        if bytes[i] != 0xFF {
            return None;
        }
        while i < bytes.len() && bytes[i] == 0xFF {
            i += 1;
        }
        let Some(&marker) = bytes.get(i) else {
            return Some("truncated JPEG: the file ends before its image data");
        };
        i += 1;
        match marker {
            // Standalone markers carry no length.
            0x01 | 0xD0..=0xD7 => continue,
            0xD9 => return None,
            _ => {}
        }
        let Some(len) = bytes
            .get(i..i + 2)
            .map(|b| usize::from(u16::from_be_bytes([b[0], b[1]])))
        else {
            return Some("truncated JPEG: the file ends inside a header segment");
        };
        if marker == 0xDA {
            let scan = i + len;
            let complete = bytes
                .get(scan..)
                .is_some_and(|rest| rest.windows(2).any(|w| w == [0xFF, 0xD9]));
            return (!complete).then_some(
                "truncated JPEG: no end-of-image marker after the image data (the file was cut short; copy it again)",
            );
        }
        i += len;
    }
}

/// Read any supported image (PNG, JPEG) as linear-valued RGB f32 in [0, 1]
/// (values are the stored 8/16-bit code values divided by their maximum; no
/// sRGB decoding is applied).
pub fn read_rgb32f(path: impl AsRef<Path>) -> Result<Rgb32FImage> {
    Ok(open_image(path.as_ref())?.to_rgb32f())
}

/// Read an image as 8-bit RGB.
pub fn read_rgb8(path: impl AsRef<Path>) -> Result<RgbImage> {
    Ok(open_image(path.as_ref())?.to_rgb8())
}

/// Read an image as 8-bit grayscale (colour images are converted with
/// Rec. 709 luma weights by the `image` crate).
pub fn read_gray8(path: impl AsRef<Path>) -> Result<GrayImage> {
    Ok(open_image(path.as_ref())?.to_luma8())
}

fn encode_png<P>(
    path: &Path,
    img: &ImageBuffer<P, Vec<u8>>,
    color: image::ExtendedColorType,
) -> Result<()>
where
    P: image::Pixel<Subpixel = u8>,
{
    use image::ImageEncoder;
    write_atomic(path, |w| {
        image::codecs::png::PngEncoder::new(w)
            .write_image(img.as_raw(), img.width(), img.height(), color)
            .map_err(|e| LoaderError::image(path, e))
    })
}

/// Write an 8-bit grayscale PNG atomically.
pub fn write_png_gray8(path: impl AsRef<Path>, img: &GrayImage) -> Result<()> {
    encode_png(path.as_ref(), img, image::ExtendedColorType::L8)
}

/// Write an 8-bit RGB PNG atomically.
pub fn write_png_rgb8(path: impl AsRef<Path>, img: &RgbImage) -> Result<()> {
    encode_png(path.as_ref(), img, image::ExtendedColorType::Rgb8)
}

/// Convert an f32 RGB image in [0, 1] to 8-bit (clamped, rounded).
pub fn rgb32f_to_rgb8(img: &Rgb32FImage) -> RgbImage {
    let data = img
        .as_raw()
        .iter()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    RgbImage::from_raw(img.width(), img.height(), data)
        .unwrap_or_else(|| RgbImage::new(img.width(), img.height()))
}

/// Write an f32 RGB image in [0, 1] as an 8-bit PNG atomically.
pub fn write_png_rgb32f(path: impl AsRef<Path>, img: &Rgb32FImage) -> Result<()> {
    write_png_rgb8(path, &rgb32f_to_rgb8(img))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_name_the_destination_not_the_staging_folder() {
        let dir = tempfile::tempdir().unwrap();
        let dest = dir.path().join("masks");
        let st = Staging::new(&dest).unwrap();
        let e = LoaderError::io(
            st.path().join("a.png"),
            std::io::Error::other("No space left on device"),
        );
        let text = st.public(&e.to_string());
        assert_eq!(
            text,
            format!("{}: No space left on device", dest.join("a.png").display())
        );
        assert!(!text.contains(".stage."));
    }

    /// A stage that fails leaves nothing behind; one that succeeds appears
    /// whole, merging into an existing folder without touching other files.
    #[test]
    fn staging_is_all_or_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let dest = dir.path().join("out");
        {
            let st = Staging::new(&dest).unwrap();
            write_bytes_atomic(st.path().join("masks/a.png"), b"1").unwrap();
            // An error before commit: the staging folder is dropped.
        }
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert!(left.is_empty() && !dest.exists(), "{left:?}");
        let st = Staging::new(&dest).unwrap();
        write_bytes_atomic(st.path().join("masks/a.png"), b"1").unwrap();
        assert!(!dest.exists());
        st.commit().unwrap();
        assert_eq!(std::fs::read(dest.join("masks/a.png")).unwrap(), b"1");
        std::fs::write(dest.join("keep.txt"), b"k").unwrap();
        let st = Staging::new(&dest).unwrap();
        write_bytes_atomic(st.path().join("masks/a.png"), b"2").unwrap();
        write_bytes_atomic(st.path().join("masks/b.png"), b"3").unwrap();
        st.commit().unwrap();
        assert_eq!(std::fs::read(dest.join("masks/a.png")).unwrap(), b"2");
        assert_eq!(std::fs::read(dest.join("masks/b.png")).unwrap(), b"3");
        assert_eq!(std::fs::read(dest.join("keep.txt")).unwrap(), b"k");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    /// A JPEG cut short is an error naming the file, also when an embedded
    /// thumbnail's end marker comes before the image data; bytes appended
    /// after the end marker are allowed.
    #[test]
    fn truncated_jpeg_is_an_error_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let img = RgbImage::from_fn(64, 48, |x, y| {
            image::Rgb([(x * 4) as u8, (y * 5) as u8, 90])
        });
        let mut jpeg = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 90)
            .encode_image(&img)
            .unwrap();
        // An APP1 segment holding a thumbnail-like FF D8 … FF D9, right after SOI.
        let payload = [b"Exif\0\0".as_slice(), &[0xFF, 0xD8, 1, 2, 0xFF, 0xD9]].concat();
        let len = (payload.len() + 2) as u16;
        let with_thumb = [
            &jpeg[..2],
            &[0xFF, 0xE1],
            &len.to_be_bytes(),
            &payload,
            &jpeg[2..],
        ]
        .concat();
        let appended = [jpeg.as_slice(), b"ftypmp42 motion photo"].concat();
        for (name, bytes) in [
            ("whole.jpg", &jpeg),
            ("thumb.jpg", &with_thumb),
            ("appended.jpg", &appended),
        ] {
            let p = dir.path().join(name);
            std::fs::write(&p, bytes).unwrap();
            assert_eq!(read_rgb8(&p).unwrap().dimensions(), (64, 48), "{name}");
        }
        let cuts = [
            ("half.jpg", jpeg[..jpeg.len() / 2].to_vec()),
            ("last_byte.jpg", jpeg[..jpeg.len() - 1].to_vec()),
            (
                "thumb_half.jpg",
                with_thumb[..with_thumb.len() * 2 / 3].to_vec(),
            ),
            ("header.jpg", jpeg[..5].to_vec()),
        ];
        for (name, bytes) in cuts {
            let p = dir.path().join(name);
            std::fs::write(&p, &bytes).unwrap();
            let e = read_rgb32f(&p).unwrap_err().to_string();
            assert!(
                e.starts_with(&p.display().to_string()) && e.contains("truncated JPEG"),
                "{name}: {e}"
            );
            assert!(!e.contains('\n'), "{e}");
        }
        assert_eq!(jpeg_truncation(b"\x89PNG not a jpeg"), None);
    }

    #[test]
    fn atomic_write_replaces_and_leaves_no_temp() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("sub/a.txt");
        write_bytes_atomic(&p, b"one").unwrap();
        write_bytes_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        let entries: Vec<_> = std::fs::read_dir(dir.path().join("sub")).unwrap().collect();
        assert_eq!(entries.len(), 1);
    }

    #[test]
    fn failed_write_keeps_old_content() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.txt");
        write_bytes_atomic(&p, b"old").unwrap();
        let r = write_atomic(&p, |w| {
            w.write_all(b"partial").unwrap();
            Err(LoaderError::format(&p, "boom"))
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn png_round_trip_gray_and_rgb() {
        let dir = tempfile::tempdir().unwrap();
        let g = GrayImage::from_fn(7, 5, |x, y| image::Luma([(x * 30 + y) as u8]));
        let pg = dir.path().join("g.png");
        write_png_gray8(&pg, &g).unwrap();
        assert_eq!(read_gray8(&pg).unwrap(), g);
        let c = RgbImage::from_fn(4, 3, |x, y| image::Rgb([x as u8 * 60, y as u8 * 80, 255]));
        let pc = dir.path().join("c.png");
        write_png_rgb8(&pc, &c).unwrap();
        assert_eq!(read_rgb8(&pc).unwrap(), c);
        let f = read_rgb32f(&pc).unwrap();
        assert!((f.get_pixel(1, 2).0[0] - 60.0 / 255.0).abs() < 1e-6);
        assert_eq!(rgb32f_to_rgb8(&f), c);
    }

    #[test]
    fn missing_and_corrupt_images_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("nothere.png");
        let e = read_rgb32f(&p).unwrap_err().to_string();
        assert!(e.contains("nothere.png") && e.contains("not found"), "{e}");
        let bad = dir.path().join("bad.png");
        std::fs::write(&bad, b"\x89PNG\r\n\x1a\ngarbage").unwrap();
        let e = read_gray8(&bad).unwrap_err().to_string();
        assert!(e.contains("bad.png"), "{e}");
    }
}
