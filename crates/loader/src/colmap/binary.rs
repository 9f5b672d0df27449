//! COLMAP binary model files (`cameras.bin`, `images.bin`, `points3D.bin`),
//! little-endian, as written by COLMAP's `Reconstruction::Write*Binary`.
//! Counts are checked against the bytes left before allocating, so a corrupt
//! count fails cleanly instead of exhausting memory.

use super::{ColmapImage, ColmapModel, Point2D, Point3D, Record, Records, read_model_files};
use crate::camera::{Camera, CameraModel, Pose};
use crate::error::{LoaderError, Result};
use crate::io::{read_bytes, write_atomic};
use std::io::Write;
use std::path::Path;

const INVALID_POINT3D: u64 = u64::MAX;

/// A bounds-checked little-endian cursor naming its file in errors.
struct Cursor<'a> {
    buf: &'a [u8],
    pos: usize,
    path: &'a Path,
}

impl<'a> Cursor<'a> {
    fn new(buf: &'a [u8], path: &'a Path) -> Self {
        Cursor { buf, pos: 0, path }
    }
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        if self.buf.len() - self.pos < n {
            return Err(LoaderError::format(
                self.path,
                format!(
                    "truncated: need {n} bytes for {what} at offset {}, file has {}",
                    self.pos,
                    self.buf.len()
                ),
            ));
        }
        let s = &self.buf[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn arr<const N: usize>(&mut self, what: &str) -> Result<[u8; N]> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N, what)?);
        Ok(a)
    }
    fn u8(&mut self, what: &str) -> Result<u8> {
        Ok(self.arr::<1>(what)?[0])
    }
    fn u32(&mut self, what: &str) -> Result<u32> {
        Ok(u32::from_le_bytes(self.arr(what)?))
    }
    fn i32(&mut self, what: &str) -> Result<i32> {
        Ok(i32::from_le_bytes(self.arr(what)?))
    }
    fn u64(&mut self, what: &str) -> Result<u64> {
        Ok(u64::from_le_bytes(self.arr(what)?))
    }
    fn f64(&mut self, what: &str) -> Result<f64> {
        Ok(f64::from_le_bytes(self.arr(what)?))
    }
    fn f64s<const N: usize>(&mut self, what: &str) -> Result<[f64; N]> {
        let mut a = [0.0; N];
        for v in &mut a {
            *v = self.f64(what)?;
        }
        Ok(a)
    }
    fn remaining(&self) -> usize {
        self.buf.len() - self.pos
    }
    /// Read a count and check that `count * min_record` bytes can follow.
    fn count(&mut self, what: &str, min_record: usize) -> Result<usize> {
        let n = self.u64(what)?;
        let max = (self.remaining() / min_record.max(1)) as u64;
        if n > max {
            return Err(LoaderError::format(
                self.path,
                format!(
                    "bad count (file truncated or corrupt): {what} = {n} at offset {}, but only {} bytes follow (at most {max} records)",
                    self.pos - 8,
                    self.remaining()
                ),
            ));
        }
        Ok(n as usize)
    }
    fn cstring(&mut self, what: &str) -> Result<String> {
        let rest = &self.buf[self.pos..];
        let Some(end) = rest.iter().position(|b| *b == 0) else {
            return Err(LoaderError::format(
                self.path,
                format!("truncated: unterminated {what} at offset {}", self.pos),
            ));
        };
        let s = std::str::from_utf8(&rest[..end])
            .map_err(|_| {
                LoaderError::format(
                    self.path,
                    format!("{what} at offset {} is not UTF-8", self.pos),
                )
            })?
            .to_string();
        self.pos += end + 1;
        Ok(s)
    }
    fn finish(&self) -> Result<()> {
        if self.pos != self.buf.len() {
            return Err(LoaderError::format(
                self.path,
                format!(
                    "{} unexpected trailing bytes after offset {}",
                    self.buf.len() - self.pos,
                    self.pos
                ),
            ));
        }
        Ok(())
    }
}

/// Read a binary record file: a u64 count (`count`, checked against the
/// bytes left at `min_record` bytes a record), then that many records, each
/// read by `record` and kept in file order; nothing may follow.
fn read_records<K: Ord + Copy + std::fmt::Display, V: Record<Id = K>>(
    path: &Path,
    count: &str,
    min_record: usize,
    mut record: impl FnMut(&mut Cursor) -> Result<V>,
) -> Result<Records<K, V>> {
    let buf = read_bytes(path)?;
    let mut c = Cursor::new(&buf, path);
    let n = c.count(count, min_record)?;
    let mut records = Records::with_capacity(n);
    for _ in 0..n {
        records.insert(path, None, record(&mut c)?)?;
    }
    c.finish()?;
    Ok(records)
}

fn read_cameras(path: &Path) -> Result<Records<u32, Camera>> {
    read_records(path, "number of cameras", 24, |c| {
        let id = c.u32("camera id")?;
        let model_id = c.i32("camera model id")?;
        let model = CameraModel::from_id(model_id).ok_or_else(|| {
            LoaderError::format(
                path,
                format!("camera {id}: unknown camera model id {model_id}"),
            )
        })?;
        let width = c.u64("camera width")?;
        let height = c.u64("camera height")?;
        let params = (0..model.num_params())
            .map(|_| c.f64("camera params"))
            .collect::<Result<Vec<f64>>>()?;
        Camera::new(id, model, width, height, params)
            .map_err(|e| LoaderError::format(path, format!("camera {id}: {e}")))
    })
}

fn read_images(path: &Path) -> Result<Records<u32, ColmapImage>> {
    read_records(path, "number of images", 4 + 56 + 4 + 1 + 8, |c| {
        let id = c.u32("image id")?;
        let qvec = c.f64s::<4>("image qvec")?;
        let tvec = c.f64s::<3>("image tvec")?;
        let camera_id = c.u32("image camera id")?;
        let name = c.cstring("image name")?;
        let np = c.count("number of points2D", 24)?;
        let mut points2d = Vec::with_capacity(np);
        for _ in 0..np {
            let xy = c.f64s::<2>("point2D xy")?;
            let pid = c.u64("point2D point3D id")?;
            points2d.push(Point2D {
                xy,
                point3d_id: (pid != INVALID_POINT3D).then_some(pid),
            });
        }
        let pose = Pose { qvec, tvec };
        Ok(ColmapImage {
            id,
            pose,
            camera_id,
            name,
            points2d,
        })
    })
}

fn read_points(path: &Path) -> Result<Records<u64, Point3D>> {
    read_records(path, "number of points3D", 8 + 24 + 3 + 8 + 8, |c| {
        let id = c.u64("point3D id")?;
        let xyz = c.f64s::<3>("point3D xyz")?;
        let rgb = [
            c.u8("point3D rgb")?,
            c.u8("point3D rgb")?,
            c.u8("point3D rgb")?,
        ];
        let error = c.f64("point3D error")?;
        let nt = c.count("track length", 8)?;
        let track = (0..nt)
            .map(|_| Ok((c.u32("track image id")?, c.u32("track point2D idx")?)))
            .collect::<Result<Vec<(u32, u32)>>>()?;
        Ok(Point3D {
            id,
            xyz,
            rgb,
            error,
            track,
        })
    })
}

/// Read `cameras.bin`, `images.bin` and `points3D.bin` from `dir`.
pub fn read_model_binary(dir: impl AsRef<Path>) -> Result<ColmapModel> {
    read_model_files(dir.as_ref(), "bin", read_cameras, read_images, read_points)
}

/// Encode `cameras.bin`.
pub(crate) fn encode_cameras(m: &ColmapModel, out: &mut Vec<u8>) {
    out.extend_from_slice(&(m.cameras.len() as u64).to_le_bytes());
    for id in m.camera_order() {
        let Some(cam) = m.cameras.get(&id) else {
            continue;
        };
        out.extend_from_slice(&cam.id.to_le_bytes());
        out.extend_from_slice(&cam.model.id().to_le_bytes());
        out.extend_from_slice(&cam.width.to_le_bytes());
        out.extend_from_slice(&cam.height.to_le_bytes());
        for p in &cam.params {
            out.extend_from_slice(&p.to_le_bytes());
        }
    }
}

/// Encode `images.bin`.
pub(crate) fn encode_images(m: &ColmapModel, out: &mut Vec<u8>) {
    out.extend_from_slice(&(m.images.len() as u64).to_le_bytes());
    for id in m.image_order() {
        let Some(im) = m.images.get(&id) else {
            continue;
        };
        out.extend_from_slice(&im.id.to_le_bytes());
        for v in im.pose.qvec.iter().chain(im.pose.tvec.iter()) {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&im.camera_id.to_le_bytes());
        out.extend_from_slice(im.name.as_bytes());
        out.push(0);
        out.extend_from_slice(&(im.points2d.len() as u64).to_le_bytes());
        for p in &im.points2d {
            out.extend_from_slice(&p.xy[0].to_le_bytes());
            out.extend_from_slice(&p.xy[1].to_le_bytes());
            out.extend_from_slice(&p.point3d_id.unwrap_or(INVALID_POINT3D).to_le_bytes());
        }
    }
}

/// Encode `points3D.bin`.
pub(crate) fn encode_points(m: &ColmapModel, out: &mut Vec<u8>) {
    out.extend_from_slice(&(m.points3d.len() as u64).to_le_bytes());
    for id in m.point_order() {
        let Some(p) = m.points3d.get(&id) else {
            continue;
        };
        out.extend_from_slice(&p.id.to_le_bytes());
        for v in p.xyz {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&p.rgb);
        out.extend_from_slice(&p.error.to_le_bytes());
        out.extend_from_slice(&(p.track.len() as u64).to_le_bytes());
        for (im, idx) in &p.track {
            out.extend_from_slice(&im.to_le_bytes());
            out.extend_from_slice(&idx.to_le_bytes());
        }
    }
}

/// Write the model as `cameras.bin`, `images.bin`, `points3D.bin` in `dir`
/// (created if needed; each file written atomically). The model is validated
/// first (camera parameter counts, image cameras exist).
pub fn write_model_binary(model: &ColmapModel, dir: impl AsRef<Path>) -> Result<()> {
    let dir = dir.as_ref();
    model.validate_files(dir, Some("bin"))?;
    type Enc = fn(&ColmapModel, &mut Vec<u8>);
    let files: [(&str, Enc); 3] = [
        ("cameras.bin", encode_cameras),
        ("images.bin", encode_images),
        ("points3D.bin", encode_points),
    ];
    for (name, enc) in files {
        let path = dir.join(name);
        let mut buf = Vec::new();
        enc(model, &mut buf);
        write_atomic(&path, |w: &mut dyn Write| {
            w.write_all(&buf).map_err(|e| LoaderError::io(&path, e))
        })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::testutil::sample_model;
    use super::*;

    fn files(dir: &Path) -> Vec<Vec<u8>> {
        ["cameras.bin", "images.bin", "points3D.bin"]
            .iter()
            .map(|f| std::fs::read(dir.join(f)).unwrap())
            .collect()
    }

    #[test]
    fn binary_round_trip_is_byte_exact_and_keeps_order() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a"), dir.path().join("b"));
        let m = sample_model();
        write_model_binary(&m, &a).unwrap();
        let r = read_model_binary(&a).unwrap();
        assert_eq!(r.cameras, m.cameras);
        assert_eq!(r.images, m.images);
        assert_eq!(r.points3d, m.points3d);
        assert_eq!(r.file_order.images, vec![3, 1, 2]);
        assert_eq!(r.file_order.points3d, vec![9, 7]);
        write_model_binary(&r, &b).unwrap();
        assert_eq!(files(&a), files(&b));
        // Known layout: cameras.bin = 8 + sum(24 + 8 * num_params).
        let expect: usize = 8 + CameraModel::ALL
            .iter()
            .map(|m| 24 + 8 * m.num_params())
            .sum::<usize>();
        assert_eq!(files(&a)[0].len(), expect);
        // Invalid point3D id is stored as u64::MAX (COLMAP's -1).
        let img = &files(&a)[1];
        assert!(img.windows(8).any(|w| w == u64::MAX.to_le_bytes()));
    }

    /// Found by the `colmap_bin` fuzz target: keypoint coordinates may be
    /// NaN (nothing downstream uses a keypoint without a 3D point; poses,
    /// intrinsics and points are checked), and they must survive a write and
    /// a read bit for bit, though NaN != NaN.
    #[test]
    fn nan_values_round_trip_bit_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a"), dir.path().join("b"));
        let mut m = sample_model();
        let id = *m.images.keys().next().unwrap();
        m.images.get_mut(&id).unwrap().points2d[0].xy[1] = f64::NAN;
        write_model_binary(&m, &a).unwrap();
        let r = read_model_binary(&a).unwrap();
        assert!(r.images[&id].points2d[0].xy[1].is_nan());
        assert!(r != m, "NaN != NaN: why the fuzz target compares bytes");
        write_model_binary(&r, &b).unwrap();
        assert_eq!(files(&a), files(&b));
    }

    #[test]
    fn truncated_files_fail_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        write_model_binary(&sample_model(), dir.path()).unwrap();
        for name in ["cameras.bin", "images.bin", "points3D.bin"] {
            let p = dir.path().join(name);
            let orig = std::fs::read(&p).unwrap();
            std::fs::write(&p, &orig[..orig.len() - 5]).unwrap();
            let e = read_model_binary(dir.path()).unwrap_err().to_string();
            assert!(e.contains(name) && e.contains("truncated"), "{e}");
            assert!(e.starts_with(p.to_str().unwrap()), "{e}");
            std::fs::write(&p, &orig).unwrap();
        }
    }

    #[test]
    fn bad_count_and_unknown_model_fail_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        write_model_binary(&sample_model(), dir.path()).unwrap();
        let p = dir.path().join("points3D.bin");
        let mut b = std::fs::read(&p).unwrap();
        b[..8].copy_from_slice(&(1u64 << 60).to_le_bytes());
        std::fs::write(&p, &b).unwrap();
        let e = read_model_binary(dir.path()).unwrap_err().to_string();
        assert!(e.contains("points3D.bin") && e.contains("bad count"), "{e}");

        let p = dir.path().join("cameras.bin");
        let mut b = std::fs::read(&p).unwrap();
        b[12..16].copy_from_slice(&42i32.to_le_bytes()); // first camera's model id
        std::fs::write(&p, &b).unwrap();
        let e = read_model_binary(dir.path()).unwrap_err().to_string();
        assert!(
            e.contains("cameras.bin") && e.contains("unknown camera model id 42"),
            "{e}"
        );
    }

    #[test]
    fn trailing_bytes_are_reported() {
        let dir = tempfile::tempdir().unwrap();
        write_model_binary(&sample_model(), dir.path()).unwrap();
        let p = dir.path().join("images.bin");
        let mut b = std::fs::read(&p).unwrap();
        b.extend_from_slice(&[0, 1, 2]);
        std::fs::write(&p, &b).unwrap();
        let e = read_model_binary(dir.path()).unwrap_err().to_string();
        assert!(e.contains("images.bin") && e.contains("trailing"), "{e}");
    }
}
