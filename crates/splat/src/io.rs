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

/// Convert to the loader's PLY arrays (f_rest channel-major, see `loader::ply`).
pub fn to_ply_splats(s: &Splats) -> Result<loader::ply::PlySplats> {
    crate::error::check_splats(s)?;
    let k = s.coeffs_per_channel();
    let mut f_dc = Vec::with_capacity(s.len());
    let mut f_rest = Vec::with_capacity(s.len() * 3 * (k - 1));
    for sh in s.sh.chunks_exact(k * 3) {
        f_dc.push([sh[0], sh[1], sh[2]]);
        for ch in 0..3 {
            f_rest.extend((1..k).map(|c| sh[c * 3 + ch]));
        }
    }
    Ok(loader::ply::PlySplats {
        means: s.means.clone(),
        normals: None,
        f_dc,
        f_rest,
        opacities: s.opacity_logits.clone(),
        scales: s.log_scales.clone(),
        rotations: s.rotations.clone(),
        sh_degree: s.sh_degree,
    })
}

/// Convert the loader's PLY arrays to [`Splats`] (normals are dropped).
pub fn from_ply_splats(p: loader::ply::PlySplats) -> Splats {
    let k = sh_coeffs(p.sh_degree);
    let r = k - 1;
    let mut sh = vec![0.0f32; p.len() * k * 3];
    for (i, block) in sh.chunks_exact_mut(k * 3).enumerate() {
        block[..3].copy_from_slice(&p.f_dc[i]);
        let rest = &p.f_rest[i * 3 * r..(i + 1) * 3 * r];
        for ch in 0..3 {
            for c in 1..k {
                block[c * 3 + ch] = rest[ch * r + c - 1];
            }
        }
    }
    Splats {
        means: p.means,
        log_scales: p.scales,
        rotations: p.rotations,
        opacity_logits: p.opacities,
        sh,
        sh_degree: p.sh_degree,
    }
}

/// Encode splats as an INRIA PLY (binary little endian). Fails on NaN/Inf,
/// naming the splat and the property.
pub fn encode_ply(s: &Splats) -> Result<Vec<u8>> {
    encode_ply_named(s, Path::new("<splats>"))
}

/// [`encode_ply`] with `path` named in errors.
pub fn encode_ply_named(s: &Splats, path: &Path) -> Result<Vec<u8>> {
    Ok(loader::ply::encode_ply(&to_ply_splats(s)?, path)?)
}

/// Write splats as an INRIA PLY (atomically). Refuses NaN/Inf, so what is
/// written can always be read back.
pub fn write_ply(path: impl AsRef<Path>, s: &Splats) -> Result<()> {
    let path = path.as_ref();
    let bytes = encode_ply_named(s, path)?;
    loader::io::write_bytes_atomic(path, &bytes)?;
    Ok(())
}

/// Read a splat PLY through the one PLY reader (`loader::ply`): binary
/// little- or big-endian or ASCII, SH degree 0–3, any scalar property type;
/// NaN/Inf rejected with the splat index and property.
pub fn read_ply(path: impl AsRef<Path>) -> Result<Splats> {
    Ok(from_ply_splats(loader::ply::read_ply(path)?))
}

/// Decode PLY bytes (see [`read_ply`]); `path` names them in errors.
pub fn decode_ply(bytes: &[u8], path: &Path) -> Result<Splats> {
    Ok(from_ply_splats(loader::ply::read_ply_bytes(bytes, path)?))
}

/// Read splats from any format we write, chosen by extension: `.ply`,
/// `.spz`, `.splat` or `.glb` (the last two in the axes our exporter writes
/// by default, converted back to COLMAP's). Non-finite values are rejected.
pub fn read_splats(path: impl AsRef<Path>) -> Result<Splats> {
    use crate::export::{ExportFormat, read_glb, read_splat, read_spz};
    let path = path.as_ref();
    let s = match ExportFormat::from_path(path) {
        Some(ExportFormat::Ply) => return read_ply(path),
        Some(ExportFormat::Spz) => read_spz(path, true)?.1,
        Some(ExportFormat::Splat) => read_splat(path)?,
        Some(ExportFormat::Glb) => read_glb(path)?,
        None => {
            return Err(ferr(
                path,
                "unknown splat file extension (expected .ply, .spz, .splat or .glb)",
            ));
        }
    };
    to_ply_splats(&s)?.validate(path)?;
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
    let b = loader::io::read_bytes(path)?;
    if b.len() < 16 || &b[..8] != CKPT_MAGIC {
        return Err(ferr(path, "not a romosplat checkpoint"));
    }
    let jl =
        u64::from_le_bytes(b[8..16].try_into().map_err(|_| ferr(path, "bad header"))?) as usize;
    let js = jl
        .checked_add(16)
        .and_then(|end| b.get(16..end))
        .ok_or_else(|| ferr(path, "truncated header"))?;
    let meta: CkptMeta =
        serde_json::from_slice(js).map_err(|e| ferr(path, format!("bad header: {e}")))?;
    if meta.sh_degree > 3 {
        return Err(ferr(path, "bad SH degree"));
    }
    let n = meta.splats;
    let k3 = sh_coeffs(meta.sh_degree) * 3;
    let per = n
        .checked_mul(3 + 3 + 4 + 1 + k3)
        .ok_or_else(|| ferr(path, format!("{n} splats is too many")))?;
    let body = &b[16 + jl..];
    if Some(body.len()) != per.checked_mul(3 * 4) {
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
            assert_eq!(decode_ply(&b, Path::new("x.ply")).unwrap(), s);
        }
        // Channel-major f_rest: f_rest_0 is red coefficient 1, f_rest_15 is green coefficient 1.
        let s = sample(3);
        let b = encode_ply(&s).unwrap();
        let end = b.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        let f = |j: usize| f32::from_le_bytes(b[end + j * 4..end + j * 4 + 4].try_into().unwrap());
        assert_eq!(f(9), s.sh[3]); // f_rest_0 = coeff 1 red
        assert_eq!(f(9 + 15), s.sh[4]); // f_rest_15 = coeff 1 green
        assert_eq!(f(9 + 45), s.opacity_logits[0]);
        let p = Path::new("x.ply");
        assert!(decode_ply(b"ply\nformat ascii 1.0\nend_header\n", p).is_err());
        assert!(decode_ply(&b[..b.len() - 4], p).is_err());
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
