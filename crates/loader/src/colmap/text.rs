//! COLMAP text model files (`cameras.txt`, `images.txt`, `points3D.txt`),
//! as written by COLMAP's `Reconstruction::Write*Text`. Floats are written in
//! Rust's shortest round-trip form, so text → model → text is lossless.

use super::{ColmapImage, ColmapModel, Point2D, Point3D, Record, Records, read_model_files};
use crate::camera::{Camera, CameraModel, Pose};
use crate::error::{LoaderError, Result};
use crate::io::{read_string, write_atomic};
use std::fmt::Write as _;
use std::io::Write;
use std::path::Path;
use std::str::FromStr;

/// Parse one token, naming file, line and field on failure.
fn parse<T: FromStr>(path: &Path, line: usize, what: &str, tok: Option<&str>) -> Result<T> {
    let tok =
        tok.ok_or_else(|| LoaderError::format(path, format!("line {line}: missing {what}")))?;
    tok.parse::<T>()
        .map_err(|_| LoaderError::format(path, format!("line {line}: bad {what} {tok:?}")))
}

fn is_data(line: &str) -> bool {
    let t = line.trim();
    !t.is_empty() && !t.starts_with('#')
}

/// Read a text record file with one record per data line (comments and
/// blank lines skipped): `record` parses a line's tokens, given its
/// 1-based number; records keep file order.
fn read_line_records<K: Ord + Copy + std::fmt::Display, V: Record<Id = K>>(
    path: &Path,
    mut record: impl FnMut(usize, std::str::SplitWhitespace) -> Result<V>,
) -> Result<Records<K, V>> {
    let text = read_string(path)?;
    let mut records = Records::with_capacity(0);
    for (i, line) in text.lines().enumerate().filter(|(_, l)| is_data(l)) {
        records.insert(path, Some(i + 1), record(i + 1, line.split_whitespace())?)?;
    }
    Ok(records)
}

fn read_cameras(path: &Path) -> Result<Records<u32, Camera>> {
    read_line_records(path, |ln, mut it| {
        let id: u32 = parse(path, ln, "camera id", it.next())?;
        let name = it.next().unwrap_or("");
        let model = CameraModel::from_name(name)
            .or_else(|| name.parse::<i32>().ok().and_then(CameraModel::from_id))
            .ok_or_else(|| {
                LoaderError::format(path, format!("line {ln}: unknown camera model {name:?}"))
            })?;
        let width: u64 = parse(path, ln, "width", it.next())?;
        let height: u64 = parse(path, ln, "height", it.next())?;
        let params = it
            .map(|t| parse::<f64>(path, ln, "camera param", Some(t)))
            .collect::<Result<Vec<f64>>>()?;
        Camera::new(id, model, width, height, params)
            .map_err(|e| LoaderError::format(path, format!("line {ln}: {e}")))
    })
}

fn read_images(path: &Path) -> Result<Records<u32, ColmapImage>> {
    let text = read_string(path)?;
    let mut records = Records::with_capacity(0);
    let mut lines = text.lines().enumerate();
    while let Some((i, line)) = lines.next() {
        if !is_data(line) {
            continue;
        }
        let ln = i + 1;
        let mut it = line.split_whitespace();
        let id: u32 = parse(path, ln, "image id", it.next())?;
        let mut v = [0.0f64; 7];
        for (k, x) in v.iter_mut().enumerate() {
            *x = parse(path, ln, if k < 4 { "qvec" } else { "tvec" }, it.next())?;
        }
        let camera_id: u32 = parse(path, ln, "camera id", it.next())?;
        let name = it.collect::<Vec<_>>().join(" ");
        if name.is_empty() {
            return Err(LoaderError::format(
                path,
                format!("line {ln}: missing image name"),
            ));
        }
        // The POINTS2D line follows directly (it may be empty).
        let (j, pts) = lines.next().unwrap_or((i + 1, ""));
        let toks: Vec<&str> = pts.split_whitespace().collect();
        if !toks.len().is_multiple_of(3) {
            return Err(LoaderError::format(
                path,
                format!(
                    "line {}: POINTS2D needs triples (X Y POINT3D_ID), found {} values",
                    j + 1,
                    toks.len()
                ),
            ));
        }
        let mut points2d = Vec::with_capacity(toks.len() / 3);
        for c in toks.chunks_exact(3) {
            let x: f64 = parse(path, j + 1, "point2D x", Some(c[0]))?;
            let y: f64 = parse(path, j + 1, "point2D y", Some(c[1]))?;
            let pid: i64 = parse(path, j + 1, "point3D id", Some(c[2]))?;
            points2d.push(Point2D {
                xy: [x, y],
                point3d_id: u64::try_from(pid).ok(),
            });
        }
        let pose = Pose {
            qvec: [v[0], v[1], v[2], v[3]],
            tvec: [v[4], v[5], v[6]],
        };
        let image = ColmapImage {
            id,
            pose,
            camera_id,
            name,
            points2d,
        };
        records.insert(path, Some(ln), image)?;
    }
    Ok(records)
}

fn read_points(path: &Path) -> Result<Records<u64, Point3D>> {
    read_line_records(path, |ln, mut it| {
        let id: u64 = parse(path, ln, "point3D id", it.next())?;
        let mut xyz = [0.0; 3];
        for x in &mut xyz {
            *x = parse(path, ln, "xyz", it.next())?;
        }
        let mut rgb = [0u8; 3];
        for c in &mut rgb {
            *c = parse(path, ln, "rgb", it.next())?;
        }
        let error: f64 = parse(path, ln, "error", it.next())?;
        let rest: Vec<&str> = it.collect();
        if !rest.len().is_multiple_of(2) {
            return Err(LoaderError::format(
                path,
                format!("line {ln}: track needs (IMAGE_ID, POINT2D_IDX) pairs"),
            ));
        }
        let track = rest
            .chunks_exact(2)
            .map(|c| {
                Ok((
                    parse(path, ln, "track image id", Some(c[0]))?,
                    parse(path, ln, "track idx", Some(c[1]))?,
                ))
            })
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

/// Read `cameras.txt`, `images.txt` and `points3D.txt` from `dir`.
pub fn read_model_text(dir: impl AsRef<Path>) -> Result<ColmapModel> {
    read_model_files(dir.as_ref(), "txt", read_cameras, read_images, read_points)
}

fn cameras_text(m: &ColmapModel) -> String {
    let mut s = String::new();
    s.push_str("# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n");
    let _ = writeln!(s, "# Number of cameras: {}", m.cameras.len());
    for c in m.camera_order().iter().filter_map(|id| m.cameras.get(id)) {
        let _ = write!(s, "{} {} {} {}", c.id, c.model.name(), c.width, c.height);
        for p in &c.params {
            let _ = write!(s, " {p}");
        }
        s.push('\n');
    }
    s
}

fn images_text(m: &ColmapModel) -> String {
    let mut s = String::new();
    s.push_str("# Image list with two lines of data per image:\n");
    s.push_str("#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n#   POINTS2D[] as (X, Y, POINT3D_ID)\n");
    let nobs: usize = m
        .images
        .values()
        .map(|i| i.points2d.iter().filter(|p| p.point3d_id.is_some()).count())
        .sum();
    let mean = mean_per(nobs, m.images.len());
    let _ = writeln!(
        s,
        "# Number of images: {}, mean observations per image: {mean}",
        m.images.len()
    );
    for im in m.image_order().iter().filter_map(|id| m.images.get(id)) {
        let [qw, qx, qy, qz] = im.pose.qvec;
        let [tx, ty, tz] = im.pose.tvec;
        let _ = writeln!(
            s,
            "{} {qw} {qx} {qy} {qz} {tx} {ty} {tz} {} {}",
            im.id, im.camera_id, im.name
        );
        let pts: Vec<String> = im
            .points2d
            .iter()
            .map(|p| match p.point3d_id {
                Some(id) => format!("{} {} {id}", p.xy[0], p.xy[1]),
                None => format!("{} {} -1", p.xy[0], p.xy[1]),
            })
            .collect();
        s.push_str(&pts.join(" "));
        s.push('\n');
    }
    s
}

/// `total / n` for the header comments, 0 when there is nothing (as COLMAP).
fn mean_per(total: usize, n: usize) -> f64 {
    if n == 0 { 0.0 } else { total as f64 / n as f64 }
}

fn points_text(m: &ColmapModel) -> String {
    let mut s = String::new();
    s.push_str("# 3D point list with one line of data per point:\n");
    s.push_str("#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n");
    let tl: usize = m.points3d.values().map(|p| p.track.len()).sum();
    let mean = mean_per(tl, m.points3d.len());
    let _ = writeln!(
        s,
        "# Number of points: {}, mean track length: {mean}",
        m.points3d.len()
    );
    for p in m.point_order().iter().filter_map(|id| m.points3d.get(id)) {
        let [x, y, z] = p.xyz;
        let [r, g, b] = p.rgb;
        let _ = write!(s, "{} {x} {y} {z} {r} {g} {b} {}", p.id, p.error);
        for (im, idx) in &p.track {
            let _ = write!(s, " {im} {idx}");
        }
        s.push('\n');
    }
    s
}

/// Write the model as `cameras.txt`, `images.txt`, `points3D.txt` in `dir`
/// (created if needed; each file written atomically).
pub fn write_model_text(model: &ColmapModel, dir: impl AsRef<Path>) -> Result<()> {
    let dir = dir.as_ref();
    model.validate_files(dir, Some("txt"))?;
    for (name, text) in [
        ("cameras.txt", cameras_text(model)),
        ("images.txt", images_text(model)),
        ("points3D.txt", points_text(model)),
    ] {
        if let Some(im) = model
            .images
            .values()
            .find(|i| i.name.contains('\n') || i.name.trim() != i.name)
        {
            return Err(LoaderError::format(
                dir,
                format!("image name {:?} cannot be written to text", im.name),
            ));
        }
        let path = dir.join(name);
        write_atomic(&path, |w: &mut dyn Write| {
            w.write_all(text.as_bytes())
                .map_err(|e| LoaderError::io(&path, e))
        })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::testutil::sample_model;
    use super::*;

    #[test]
    fn text_round_trip_is_lossless() {
        let dir = tempfile::tempdir().unwrap();
        let m = sample_model();
        write_model_text(&m, dir.path()).unwrap();
        let r = read_model_text(dir.path()).unwrap();
        assert_eq!(r, m);
        let a = std::fs::read_to_string(dir.path().join("images.txt")).unwrap();
        write_model_text(&r, dir.path()).unwrap();
        assert_eq!(
            std::fs::read_to_string(dir.path().join("images.txt")).unwrap(),
            a
        );
    }

    #[test]
    fn parses_colmap_written_text() {
        // Verbatim shape of COLMAP 3.8 output, including an empty POINTS2D line.
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(
            dir.path().join("cameras.txt"),
            "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n# Number of cameras: 1\n1 SIMPLE_RADIAL 320 240 288.5 160 120 0.01\n",
        )
        .unwrap();
        std::fs::write(
            dir.path().join("images.txt"),
            "# Image list\n# Number of images: 2\n1 1 0 0 0 0 0 0 1 a.png\n12.5 3.25 5 1 1 -1\n2 0.7071 0 0.7071 0 1 2 3 1 b.png\n\n",
        )
        .unwrap();
        std::fs::write(
            dir.path().join("points3D.txt"),
            "# pts\n5 1.5 2 3 10 20 30 0.5 1 0 2 7\n",
        )
        .unwrap();
        let m = read_model_text(dir.path()).unwrap();
        assert_eq!(m.cameras[&1].model, CameraModel::SIMPLE_RADIAL);
        assert_eq!(m.cameras[&1].params, vec![288.5, 160.0, 120.0, 0.01]);
        assert_eq!(
            m.images[&1].points2d[0],
            Point2D {
                xy: [12.5, 3.25],
                point3d_id: Some(5)
            }
        );
        assert_eq!(m.images[&1].points2d[1].point3d_id, None);
        assert!(m.images[&2].points2d.is_empty());
        assert_eq!(m.images[&2].name, "b.png");
        assert_eq!(m.points3d[&5].track, vec![(1, 0), (2, 7)]);
        assert_eq!(m.points3d[&5].rgb, [10, 20, 30]);
    }

    #[test]
    fn bad_text_names_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        write_model_text(&sample_model(), dir.path()).unwrap();
        let p = dir.path().join("cameras.txt");
        std::fs::write(&p, "1 FANCY_MODEL 10 10 1 2 3\n").unwrap();
        let e = read_model_text(dir.path()).unwrap_err().to_string();
        assert!(
            e.contains("cameras.txt") && e.contains("line 1") && e.contains("unknown camera model"),
            "{e}"
        );
        std::fs::write(&p, "1 PINHOLE 10 10 1 2 3\n").unwrap();
        let e = read_model_text(dir.path()).unwrap_err().to_string();
        assert!(
            e.contains("cameras.txt") && e.contains("needs 4 params"),
            "{e}"
        );
        std::fs::write(&p, "1 PINHOLE 10 ten 1 2 3 4\n").unwrap();
        let e = read_model_text(dir.path()).unwrap_err().to_string();
        assert!(e.contains("bad height"), "{e}");
    }
}
