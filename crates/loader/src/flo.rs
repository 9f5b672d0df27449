//! Middlebury `.flo` optical-flow files (Baker et al., "A Database and
//! Evaluation Methodology for Optical Flow", IJCV 2011; the format also used
//! by MPI Sintel): little-endian float32 magic 202021.25, int32 width,
//! int32 height, then width·height (u, v) float32 pairs, row-major.

use crate::error::{LoaderError, Result};
use crate::io::{read_bytes, write_atomic};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;

/// The `.flo` magic number ("PIEH" as bytes).
pub const FLO_MAGIC: f32 = 202021.25;
/// Middlebury's marker: components above this are "unknown flow".
pub const UNKNOWN_FLOW_THRESH: f32 = 1e9;
/// Largest width or height accepted on read (sanity limit against corrupt headers).
pub const MAX_DIM: i32 = 1 << 16;

/// A dense flow field: `data[y * width + x] = (u, v)` in pixels, where
/// pixel (x, y) moves to (x + u, y + v).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FlowField {
    pub width: u32,
    pub height: u32,
    pub data: Vec<[f32; 2]>,
}

impl FlowField {
    /// A zero flow field.
    pub fn zeros(width: u32, height: u32) -> Self {
        FlowField {
            width,
            height,
            data: vec![[0.0; 2]; width as usize * height as usize],
        }
    }

    /// Flow at (x, y).
    pub fn get(&self, x: u32, y: u32) -> [f32; 2] {
        self.data[y as usize * self.width as usize + x as usize]
    }

    /// True when the flow at index `i` is known (finite, below Middlebury's threshold).
    pub fn is_known(&self, i: usize) -> bool {
        let [u, v] = self.data[i];
        u.is_finite()
            && v.is_finite()
            && u.abs() < UNKNOWN_FLOW_THRESH
            && v.abs() < UNKNOWN_FLOW_THRESH
    }
}

/// Read a `.flo` file, validating magic, sizes and length.
pub fn read_flo(path: impl AsRef<Path>) -> Result<FlowField> {
    let path = path.as_ref();
    let b = read_bytes(path)?;
    if b.len() < 12 {
        return Err(LoaderError::format(
            path,
            format!("truncated .flo: {} bytes, header needs 12", b.len()),
        ));
    }
    let word = |o: usize| [b[o], b[o + 1], b[o + 2], b[o + 3]];
    let magic = f32::from_le_bytes(word(0));
    if magic != FLO_MAGIC {
        return Err(LoaderError::format(
            path,
            format!("bad .flo magic {magic} (expected {FLO_MAGIC})"),
        ));
    }
    let (w, h) = (i32::from_le_bytes(word(4)), i32::from_le_bytes(word(8)));
    if !(1..=MAX_DIM).contains(&w) || !(1..=MAX_DIM).contains(&h) {
        return Err(LoaderError::format(path, format!("bad .flo size {w}x{h}")));
    }
    let n = w as usize * h as usize;
    let need = 12 + n * 8;
    if b.len() != need {
        let what = if b.len() < need {
            "truncated"
        } else {
            "too long"
        };
        return Err(LoaderError::format(
            path,
            format!(
                "{what} .flo: {w}x{h} needs {need} bytes, file has {}",
                b.len()
            ),
        ));
    }
    let data = b[12..]
        .chunks_exact(8)
        .map(|c| {
            [
                f32::from_le_bytes([c[0], c[1], c[2], c[3]]),
                f32::from_le_bytes([c[4], c[5], c[6], c[7]]),
            ]
        })
        .collect();
    Ok(FlowField {
        width: w as u32,
        height: h as u32,
        data,
    })
}

/// Write a `.flo` file atomically.
pub fn write_flo(path: impl AsRef<Path>, flow: &FlowField) -> Result<()> {
    let path = path.as_ref();
    if flow.data.len() != flow.width as usize * flow.height as usize
        || flow.width == 0
        || flow.height == 0
    {
        return Err(LoaderError::format(
            path,
            format!(
                "flow is {}x{} but has {} vectors",
                flow.width,
                flow.height,
                flow.data.len()
            ),
        ));
    }
    let mut out = Vec::with_capacity(12 + flow.data.len() * 8);
    out.extend_from_slice(&FLO_MAGIC.to_le_bytes());
    out.extend_from_slice(&(flow.width as i32).to_le_bytes());
    out.extend_from_slice(&(flow.height as i32).to_le_bytes());
    for [u, v] in &flow.data {
        out.extend_from_slice(&u.to_le_bytes());
        out.extend_from_slice(&v.to_le_bytes());
    }
    write_atomic(path, |w: &mut dyn Write| {
        w.write_all(&out).map_err(|e| LoaderError::io(path, e))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_known_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("f.flo");
        let mut f = FlowField::zeros(3, 2);
        f.data[4] = [1.5, -2.25];
        f.data[5] = [1e10, 0.0];
        write_flo(&p, &f).unwrap();
        let b = std::fs::read(&p).unwrap();
        assert_eq!(&b[..4], b"PIEH");
        assert_eq!(b.len(), 12 + 6 * 8);
        let r = read_flo(&p).unwrap();
        assert_eq!(r, f);
        assert_eq!(r.get(1, 1), [1.5, -2.25]);
        assert!(r.is_known(4) && !r.is_known(5));
    }

    #[test]
    fn errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("bad.flo");
        let check = |bytes: &[u8], want: &str| {
            std::fs::write(&p, bytes).unwrap();
            let e = read_flo(&p).unwrap_err().to_string();
            assert!(e.contains("bad.flo") && e.contains(want), "{e}");
        };
        check(b"PIE", "truncated");
        check(
            b"XXXX\x01\0\0\0\x01\0\0\0\0\0\0\0\0\0\0\0",
            "bad .flo magic",
        );
        check(b"PIEH\0\0\0\0\x01\0\0\0", "bad .flo size 0x1");
        check(
            b"PIEH\x02\0\0\0\x01\0\0\0\0\0\0\0\0\0\0\0",
            "truncated .flo: 2x1 needs 28",
        );
        check(b"PIEH\x01\0\0\0\x01\0\0\0\0\0\0\0\0\0\0\0\0", "too long");
        let bad = FlowField {
            width: 2,
            height: 2,
            data: vec![[0.0; 2]],
        };
        let e = write_flo(dir.path().join("o.flo"), &bad)
            .unwrap_err()
            .to_string();
        assert!(e.contains("o.flo") && e.contains("has 1 vectors"), "{e}");
    }
}
