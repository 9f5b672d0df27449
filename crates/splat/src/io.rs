//! Splat files: the INRIA 3DGS PLY layout (`gaussian_model.py`
//! `save_ply`/`load_ply`: x y z, nx ny nz, f_dc_0..2, f_rest_* channel-major,
//! opacity as logit, scale_0..2 as log, rot_0..3 as w x y z; binary little
//! endian float32), which SuperSplat, Brush and the gsplat viewers open, and
//! the training checkpoint (parameters + Adam state + step). Writes are
//! atomic (temp file + rename).

use crate::error::{Result, SplatError};
use crate::types::{AdamState, Splats, sh_coeffs};
use serde::{Deserialize, Serialize};
use std::path::Path;

fn ferr(path: &Path, msg: impl Into<String>) -> SplatError {
    SplatError::File {
        path: path.to_path_buf(),
        msg: msg.into(),
    }
}

/// Encode splats as an INRIA PLY.
pub fn encode_ply(s: &Splats) -> Result<Vec<u8>> {
    crate::error::check_splats(s)?;
    let k = s.coeffs_per_channel();
    let n_rest = 3 * (k - 1);
    let mut h = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\n",
        s.len()
    );
    for p in [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ] {
        h += &format!("property float {p}\n");
    }
    for i in 0..n_rest {
        h += &format!("property float f_rest_{i}\n");
    }
    h += "property float opacity\n";
    for p in [
        "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
    ] {
        h += &format!("property float {p}\n");
    }
    h += "end_header\n";
    let mut out = h.into_bytes();
    let stride = 9 + n_rest + 1 + 7;
    out.reserve(s.len() * stride * 4);
    let mut row = Vec::with_capacity(stride);
    for i in 0..s.len() {
        row.clear();
        row.extend_from_slice(&s.means[i]);
        row.extend_from_slice(&[0.0; 3]);
        let sh = &s.sh[i * k * 3..(i + 1) * k * 3];
        row.extend_from_slice(&sh[..3]);
        for ch in 0..3 {
            for c in 1..k {
                row.push(sh[c * 3 + ch]);
            }
        }
        row.push(s.opacity_logits[i]);
        row.extend_from_slice(&s.log_scales[i]);
        row.extend_from_slice(&s.rotations[i]);
        for v in &row {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    Ok(out)
}

/// Write splats as an INRIA PLY (atomically).
pub fn write_ply(path: impl AsRef<Path>, s: &Splats) -> Result<()> {
    let bytes = encode_ply(s)?;
    loader::io::write_bytes_atomic(path.as_ref(), &bytes)?;
    Ok(())
}

/// Read an INRIA-layout PLY (binary little endian; float or double properties).
pub fn read_ply(path: impl AsRef<Path>) -> Result<Splats> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| ferr(path, e.to_string()))?;
    decode_ply(&bytes).map_err(|m| ferr(path, m))
}

/// Decode an INRIA-layout PLY.
pub fn decode_ply(bytes: &[u8]) -> std::result::Result<Splats, String> {
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .ok_or("no end_header")?
        + 11;
    let header = std::str::from_utf8(&bytes[..end]).map_err(|_| "header is not UTF-8")?;
    let mut lines = header.lines();
    if lines.next() != Some("ply") {
        return Err("not a PLY file".into());
    }
    let mut n = None;
    let mut props: Vec<(String, usize)> = Vec::new(); // (name, byte size)
    let mut in_vertex = false;
    for l in lines {
        let t: Vec<&str> = l.split_whitespace().collect();
        match t.as_slice() {
            ["format", f, _] if *f != "binary_little_endian" => {
                return Err(format!("unsupported PLY format {f}"));
            }
            ["element", "vertex", c] => {
                n = Some(
                    c.parse::<usize>()
                        .map_err(|_| format!("bad vertex count {c}"))?,
                );
                in_vertex = true;
            }
            ["element", ..] => in_vertex = false,
            ["property", ty, name] if in_vertex => {
                let sz = match *ty {
                    "float" | "float32" => 4,
                    "double" | "float64" => 8,
                    _ => return Err(format!("unsupported property type {ty} for {name}")),
                };
                props.push((name.to_string(), sz));
            }
            _ => {}
        }
    }
    let n = n.ok_or("no vertex element")?;
    let stride: usize = props.iter().map(|p| p.1).sum();
    let body = &bytes[end..];
    if body.len() < n * stride {
        return Err(format!(
            "truncated: {} bytes for {n} vertices of {stride} bytes",
            body.len()
        ));
    }
    let mut offs = std::collections::HashMap::new();
    let mut o = 0;
    for (name, sz) in &props {
        offs.insert(name.as_str(), (o, *sz));
        o += sz;
    }
    let get = |i: usize, name: &str| -> std::result::Result<f32, String> {
        let (off, sz) = *offs
            .get(name)
            .ok_or_else(|| format!("missing property {name}"))?;
        let b = &body[i * stride + off..i * stride + off + sz];
        Ok(if sz == 4 {
            f32::from_le_bytes([b[0], b[1], b[2], b[3]])
        } else {
            f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]) as f32
        })
    };
    let n_rest = props.iter().filter(|p| p.0.starts_with("f_rest_")).count();
    let k = n_rest / 3 + 1;
    let degree = (0..=3u32)
        .find(|&d| sh_coeffs(d) == k && n_rest % 3 == 0)
        .ok_or_else(|| format!("{n_rest} f_rest properties is not an SH degree ≤ 3"))?;
    let mut s = Splats {
        sh_degree: degree,
        ..Default::default()
    };
    s.sh.reserve(n * k * 3);
    for i in 0..n {
        s.means.push([get(i, "x")?, get(i, "y")?, get(i, "z")?]);
        s.log_scales
            .push([get(i, "scale_0")?, get(i, "scale_1")?, get(i, "scale_2")?]);
        s.rotations.push([
            get(i, "rot_0")?,
            get(i, "rot_1")?,
            get(i, "rot_2")?,
            get(i, "rot_3")?,
        ]);
        s.opacity_logits.push(get(i, "opacity")?);
        let mut block = vec![0.0f32; k * 3];
        for ch in 0..3 {
            block[ch] = get(i, &format!("f_dc_{ch}"))?;
            for c in 1..k {
                block[c * 3 + ch] = get(i, &format!("f_rest_{}", ch * (k - 1) + c - 1))?;
            }
        }
        s.sh.extend_from_slice(&block);
    }
    Ok(s)
}

/// A training checkpoint.
#[derive(Debug, Clone, PartialEq)]
pub struct Checkpoint {
    /// Steps completed.
    pub step: u32,
    pub splats: Splats,
    pub adam: AdamState,
}

#[derive(Serialize, Deserialize)]
struct CkptMeta {
    format: String,
    step: u32,
    splats: usize,
    sh_degree: u32,
    adam_step: u64,
}

const CKPT_MAGIC: &[u8; 8] = b"RSCKPT1\n";

fn push_splats(out: &mut Vec<u8>, s: &Splats) {
    let mut f = |v: &[f32]| {
        v.iter()
            .for_each(|x| out.extend_from_slice(&x.to_le_bytes()))
    };
    f(s.means.as_flattened());
    f(s.log_scales.as_flattened());
    f(s.rotations.as_flattened());
    f(&s.opacity_logits);
    f(&s.sh);
}

/// Write a checkpoint (atomically).
pub fn write_checkpoint(path: impl AsRef<Path>, c: &Checkpoint) -> Result<()> {
    crate::error::check_splats(&c.splats)?;
    let meta = CkptMeta {
        format: "romosplat-checkpoint-1".into(),
        step: c.step,
        splats: c.splats.len(),
        sh_degree: c.splats.sh_degree,
        adam_step: c.adam.step,
    };
    let js = serde_json::to_vec(&meta).map_err(|e| SplatError::Invalid(e.to_string()))?;
    let mut out = CKPT_MAGIC.to_vec();
    out.extend_from_slice(&(js.len() as u64).to_le_bytes());
    out.extend_from_slice(&js);
    push_splats(&mut out, &c.splats);
    push_splats(&mut out, &c.adam.m);
    push_splats(&mut out, &c.adam.v);
    loader::io::write_bytes_atomic(path.as_ref(), &out)?;
    Ok(())
}

/// Read a checkpoint written by [`write_checkpoint`].
pub fn read_checkpoint(path: impl AsRef<Path>) -> Result<Checkpoint> {
    let path = path.as_ref();
    let b = std::fs::read(path).map_err(|e| ferr(path, e.to_string()))?;
    if b.len() < 16 || &b[..8] != CKPT_MAGIC {
        return Err(ferr(path, "not a romosplat checkpoint"));
    }
    let jl =
        u64::from_le_bytes(b[8..16].try_into().map_err(|_| ferr(path, "bad header"))?) as usize;
    let js = b
        .get(16..16 + jl)
        .ok_or_else(|| ferr(path, "truncated header"))?;
    let meta: CkptMeta =
        serde_json::from_slice(js).map_err(|e| ferr(path, format!("bad header: {e}")))?;
    if meta.sh_degree > 3 {
        return Err(ferr(path, "bad SH degree"));
    }
    let n = meta.splats;
    let k3 = sh_coeffs(meta.sh_degree) * 3;
    let per = n * (3 + 3 + 4 + 1 + k3);
    let body = &b[16 + jl..];
    if body.len() != per * 3 * 4 {
        return Err(ferr(
            path,
            format!("size {} does not match {n} splats", body.len()),
        ));
    }
    let floats: Vec<f32> = body
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    let take = |f: &[f32]| -> Splats {
        let (m, r) = f.split_at(n * 3);
        let (l, r) = r.split_at(n * 3);
        let (q, r) = r.split_at(n * 4);
        let (o, sh) = r.split_at(n);
        Splats {
            means: m.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
            log_scales: l.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
            rotations: q
                .chunks_exact(4)
                .map(|c| [c[0], c[1], c[2], c[3]])
                .collect(),
            opacity_logits: o.to_vec(),
            sh: sh.to_vec(),
            sh_degree: meta.sh_degree,
        }
    };
    Ok(Checkpoint {
        step: meta.step,
        splats: take(&floats[..per]),
        adam: AdamState {
            step: meta.adam_step,
            m: take(&floats[per..2 * per]),
            v: take(&floats[2 * per..]),
        },
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    fn sample(deg: u32) -> Splats {
        let k3 = sh_coeffs(deg) * 3;
        let n = 5;
        Splats {
            means: (0..n).map(|i| [i as f32, 1.5, -2.0]).collect(),
            log_scales: (0..n).map(|i| [-(i as f32), 0.1, 0.2]).collect(),
            rotations: (0..n).map(|i| [1.0, 0.0, i as f32 * 0.1, 0.3]).collect(),
            opacity_logits: (0..n).map(|i| i as f32 - 2.0).collect(),
            sh: (0..n * k3).map(|i| i as f32 * 0.01).collect(),
            sh_degree: deg,
        }
    }

    #[test]
    fn ply_round_trip_and_layout() {
        for deg in 0..=3 {
            let s = sample(deg);
            let b = encode_ply(&s).unwrap();
            assert_eq!(decode_ply(&b).unwrap(), s);
        }
        // Channel-major f_rest: f_rest_0 is red coefficient 1, f_rest_15 is green coefficient 1.
        let s = sample(3);
        let b = encode_ply(&s).unwrap();
        let end = b.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        let f = |j: usize| f32::from_le_bytes(b[end + j * 4..end + j * 4 + 4].try_into().unwrap());
        assert_eq!(f(9), s.sh[3]); // f_rest_0 = coeff 1 red
        assert_eq!(f(9 + 15), s.sh[4]); // f_rest_15 = coeff 1 green
        assert_eq!(f(9 + 45), s.opacity_logits[0]);
        assert!(decode_ply(b"ply\nformat ascii 1.0\nend_header\n").is_err());
        assert!(decode_ply(&b[..b.len() - 4]).is_err());
    }

    #[test]
    fn checkpoint_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let s = sample(2);
        let mut adam = AdamState::zeros_like(&s);
        adam.step = 77;
        adam.m.sh[3] = 0.5;
        let c = Checkpoint {
            step: 1234,
            splats: s,
            adam,
        };
        let p = dir.path().join("ck.bin");
        write_checkpoint(&p, &c).unwrap();
        assert_eq!(read_checkpoint(&p).unwrap(), c);
        std::fs::write(&p, b"garbage").unwrap();
        let e = read_checkpoint(&p).unwrap_err().to_string();
        assert!(e.contains("ck.bin"), "{e}");
    }
}
