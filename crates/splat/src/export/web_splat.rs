//! The `.splat` web format of antimatter15/splat (`convert.py`), read by most
//! web viewers and by PlayCanvas splat-transform: no header, 32 bytes per
//! splat, little-endian:
//!
//! ```text
//! 0..12   f32 × 3   position
//! 12..24  f32 × 3   scale, linear (exp of the log scale)
//! 24..28  u8 × 4    r g b a: colour = (0.5 + SH_C0·dc)·255, alpha = sigmoid(opacity)·255,
//!                   clipped to [0, 255] then truncated (numpy `astype(uint8)`)
//! 28..32  u8 × 4    rotation w x y z of the normalised quaternion, q·128 + 128,
//!                   clipped and truncated the same way
//! ```
//!
//! Splats are ordered as the reference converter orders them: by
//! exp(Σ log scale) · sigmoid(opacity) descending (volume × opacity), ties
//! by input index. Higher SH degrees are dropped (the format has none).

use super::{SH_C0, normalized_wxyz, sigmoid};
use crate::error::{Result, SplatError};
use crate::types::Splats;
use std::path::Path;

/// Bytes per splat.
pub const SPLAT_RECORD_BYTES: usize = 32;

/// numpy's `(x).clip(0, 255).astype(np.uint8)`: clip, then truncate.
fn clip_trunc(x: f32) -> u8 {
    if x.is_nan() {
        0
    } else {
        x.clamp(0.0, 255.0) as u8
    }
}

/// The order the reference viewer's converter writes splats in.
pub fn importance_order(s: &Splats) -> Vec<usize> {
    let key: Vec<f32> = (0..s.len())
        .map(|i| {
            let ls = s.log_scales[i];
            (ls[0] + ls[1] + ls[2]).exp() * sigmoid(s.opacity_logits[i])
        })
        .collect();
    let mut order: Vec<usize> = (0..s.len()).collect();
    order.sort_by(|&a, &b| key[b].total_cmp(&key[a]).then(a.cmp(&b)));
    order
}

/// Encode one splat's 32-byte record.
pub fn encode_record(s: &Splats, i: usize) -> [u8; SPLAT_RECORD_BYTES] {
    let mut rec = [0u8; SPLAT_RECORD_BYTES];
    let k3 = s.coeffs_per_channel() * 3;
    for a in 0..3 {
        rec[4 * a..4 * a + 4].copy_from_slice(&s.means[i][a].to_le_bytes());
        let sc = s.log_scales[i][a].exp();
        rec[12 + 4 * a..16 + 4 * a].copy_from_slice(&sc.to_le_bytes());
        rec[24 + a] = clip_trunc((0.5 + SH_C0 * s.sh[i * k3 + a]) * 255.0);
    }
    rec[27] = clip_trunc(sigmoid(s.opacity_logits[i]) * 255.0);
    let q = normalized_wxyz(s.rotations[i]);
    for (a, v) in q.iter().enumerate() {
        rec[28 + a] = clip_trunc(v * 128.0 + 128.0);
    }
    rec
}

/// Encode all splats, importance-sorted.
pub fn encode_splat(s: &Splats) -> Result<Vec<u8>> {
    crate::error::check_splats(s)?;
    super::check_finite(s)?;
    let mut out = Vec::with_capacity(s.len() * SPLAT_RECORD_BYTES);
    for i in importance_order(s) {
        out.extend_from_slice(&encode_record(s, i));
    }
    Ok(out)
}

/// Decode a `.splat` byte stream back to splats (SH degree 0). Inverse of the
/// encoding up to its quantisation: the colour becomes the DC coefficient
/// (c/255 − 0.5)/SH_C0, alpha the logit of a/255 (clamped away from 0 and 1),
/// the rotation (b − 128)/128 renormalised.
pub fn decode_splat(bytes: &[u8]) -> Result<Splats> {
    if !bytes.len().is_multiple_of(SPLAT_RECORD_BYTES) {
        return Err(SplatError::Invalid(format!(
            ".splat: {} bytes is not a multiple of {SPLAT_RECORD_BYTES}",
            bytes.len()
        )));
    }
    let n = bytes.len() / SPLAT_RECORD_BYTES;
    let mut s = Splats {
        sh_degree: 0,
        ..Default::default()
    };
    for rec in bytes.chunks_exact(SPLAT_RECORD_BYTES) {
        let f = |o: usize| f32::from_le_bytes([rec[o], rec[o + 1], rec[o + 2], rec[o + 3]]);
        s.means.push([f(0), f(4), f(8)]);
        s.log_scales.push([f(12).ln(), f(16).ln(), f(20).ln()]);
        for a in 0..3 {
            s.sh.push((f32::from(rec[24 + a]) / 255.0 - 0.5) / SH_C0);
        }
        let p = (f32::from(rec[27]) / 255.0).clamp(1e-6, 1.0 - 1e-6);
        s.opacity_logits.push((p / (1.0 - p)).ln());
        let q = [0, 1, 2, 3].map(|a| (f32::from(rec[28 + a]) - 128.0) / 128.0);
        s.rotations.push(normalized_wxyz(q));
    }
    debug_assert_eq!(s.len(), n);
    Ok(s)
}

/// Write the `.splat` file atomically; returns its size in bytes.
pub fn write_splat(path: &Path, s: &Splats) -> Result<u64> {
    let bytes = encode_splat(s).map_err(|e| super::name_file(path, e))?;
    loader::io::write_bytes_atomic(path, &bytes)?;
    Ok(bytes.len() as u64)
}

/// Read a `.splat` file.
pub fn read_splat(path: &Path) -> Result<Splats> {
    let bytes = loader::io::read_bytes(path)?;
    decode_splat(&bytes).map_err(|e| super::name_file(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_splat_known_bytes() {
        // Hand-computed expected record:
        //   dc = (1, 0, -3): colour 0.5 + 0.28209479·dc → 0.78209 · 255 = 199.43 → 199,
        //   127.5 → 127, −0.34628 → clipped 0; opacity logit 0 → 0.5 · 255 = 127.5 → 127;
        //   rotation (2, 0, 0, 0) → unit (1, 0, 0, 0) → 256 → clipped 255, 128, 128, 128.
        let s = Splats {
            means: vec![[1.0, -2.0, 0.5]],
            log_scales: vec![[0.0, 2f32.ln(), -(4f32.ln())]],
            rotations: vec![[2.0, 0.0, 0.0, 0.0]],
            opacity_logits: vec![0.0],
            sh: vec![1.0, 0.0, -3.0],
            sh_degree: 0,
        };
        let b = encode_splat(&s).unwrap();
        let mut want = Vec::new();
        for v in [1.0f32, -2.0, 0.5, 1.0, 2.0, 0.25] {
            want.extend_from_slice(&v.to_le_bytes());
        }
        want.extend_from_slice(&[199, 127, 0, 127, 255, 128, 128, 128]);
        assert_eq!(b.len(), 32);
        assert_eq!(&b[..12], &want[..12]);
        for a in 0..3 {
            let got = f32::from_le_bytes(b[12 + 4 * a..16 + 4 * a].try_into().unwrap());
            let exp = f32::from_le_bytes(want[12 + 4 * a..16 + 4 * a].try_into().unwrap());
            assert!((got - exp).abs() <= 1e-6 * exp, "scale {a}: {got} vs {exp}");
        }
        assert_eq!(&b[24..], &want[24..]);
    }

    #[test]
    fn negative_rotation_components_and_sorting() {
        // q = (0.5, -0.5, 0.5, -0.5) → 192, 64, 192, 64.
        let s = Splats {
            means: vec![[0.0; 3], [1.0; 3], [2.0; 3]],
            log_scales: vec![[0.0; 3], [1.0; 3], [0.5; 3]],
            rotations: vec![[0.5, -0.5, 0.5, -0.5]; 3],
            opacity_logits: vec![0.0, -20.0, 3.0],
            sh: vec![0.0; 9],
            sh_degree: 0,
        };
        // keys: 1·0.5, e^3·2e-9 ≈ 4e-8, e^1.5·0.9526 ≈ 4.27 → order 2, 0, 1.
        assert_eq!(importance_order(&s), vec![2, 0, 1]);
        let b = encode_splat(&s).unwrap();
        assert_eq!(&b[28..32], &[192, 64, 192, 64]);
        assert_eq!(f32::from_le_bytes(b[0..4].try_into().unwrap()), 2.0);
        assert_eq!(f32::from_le_bytes(b[32..36].try_into().unwrap()), 0.0);
        assert_eq!(f32::from_le_bytes(b[64..68].try_into().unwrap()), 1.0);
        let d = decode_splat(&b).unwrap();
        assert_eq!(d.len(), 3);
        assert!((d.log_scales[0][0] - 0.5).abs() < 1e-6);
    }

    #[test]
    fn bad_length_is_an_error() {
        assert!(decode_splat(&[0u8; 33]).is_err());
    }
}
