//! SPZ, Niantic's compressed Gaussian splat format (nianticlabs/spz,
//! `src/cc/load-spz.cc`), written and read back.
//!
//! The file is one gzip stream holding a 16-byte header followed by the
//! attributes, each for all points in turn:
//!
//! ```text
//! header   u32 magic 0x5053474e ("NGSP"), u32 version (2 or 3), u32 numPoints,
//!          u8 shDegree, u8 fractionalBits, u8 flags (1 = antialiased), u8 reserved
//! position 3 × 24-bit two's-complement fixed point, `fractionalBits` fraction bits
//! alpha    u8 = round(sigmoid(opacity) · 255)
//! colour   3 × u8 = round(dc · 0.15 · 255 + 127.5)   (DC SH coefficient)
//! scale    3 × u8 = round((log_scale + 10) · 16)
//! rotation v2: 3 × u8 = round(xyz · 127.5 + 127.5) of the unit quaternion with w ≥ 0
//!          v3: u32 "smallest three": 2-bit index of the largest |component|,
//!              then for each other component (x, y, z, w order) a sign bit and a
//!              9-bit magnitude of |c| / √½
//! sh       per point, per higher-order coefficient, r g b: u8 = q(c·128 + 128)
//!          rounded to a bucket of 8 (degree 1) or 16 (degrees 2–3)
//! ```
//!
//! SPZ is defined in a right-up-back (OpenGL) frame; our splats live in COLMAP's
//! right-down-front frame, so by default they are rotated with
//! [`super::rdf_to_rub`] (what the reference does with `from = RDF`), and
//! reading rotates them back.
//!
//! Quantisation error bounds (used by the round-trip test): position
//! 2^-(fractionalBits+1); log scale 1/32 inside [-10, 5.94]; opacity 0.5/255
//! after the sigmoid; DC 0.5/(0.15·255); SH (0.5 + bucket/2)/128 inside the
//! representable range; rotation components 0.5/127.5 (v2) or ≈ √½/1022 (v3)
//! up to sign, before the largest/w component is recomputed.

use super::{normalized_wxyz, rdf_to_rub, sigmoid};
use crate::error::{Result, SplatError};
use crate::types::{Splats, sh_coeffs};
use flate2::Compression;
use flate2::read::GzDecoder;
use flate2::write::GzEncoder;
use serde::{Deserialize, Serialize};
use std::io::{Read, Write};
use std::path::Path;

/// "NGSP" read as a little-endian u32.
pub const SPZ_MAGIC: u32 = 0x5053_474e;
/// Header flag: trained with antialiasing (Mip-Splatting style).
pub const FLAG_ANTIALIASED: u8 = 0x1;
/// Header flag: extension records follow the header (not supported here).
pub const FLAG_HAS_EXTENSIONS: u8 = 0x2;
/// Scale of the DC colour term (reference `colorScale`).
const COLOR_SCALE: f32 = 0.15;
/// Fixed-point fraction bits the reference uses (~0.25 mm at metre scale).
const DEFAULT_FRACTIONAL_BITS: u8 = 12;
/// Bucket sizes for SH quantisation: 5 bits for degree 1, 4 bits above.
const SH1_BUCKET: i32 = 1 << (8 - 5);
const SH_REST_BUCKET: i32 = 1 << (8 - 4);
const SQRT1_2: f32 = std::f32::consts::FRAC_1_SQRT_2;

/// How to write an SPZ file.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SpzOptions {
    /// Format version: 2 (3-byte "first three" quaternions) or 3 (4-byte
    /// "smallest three"). Default 3, the gzip-container version the reference
    /// library writes by default before its v4 zstd container.
    pub version: u32,
    /// Convert from COLMAP/PLY right-down-front axes to SPZ's right-up-back
    /// axes (flip y and z), as the reference does with `from = RDF`.
    /// Default true; reading with the same setting undoes it.
    pub convert_axes: bool,
    /// Set the header's antialiased flag. Default false (our trainer's
    /// default render mode is not antialiased).
    pub antialiased: bool,
}

impl Default for SpzOptions {
    fn default() -> Self {
        SpzOptions {
            version: 3,
            convert_axes: true,
            antialiased: false,
        }
    }
}

impl SpzOptions {
    /// Check the options.
    pub fn validate(&self) -> Result<()> {
        if !(2..=3).contains(&self.version) {
            return Err(SplatError::Invalid(format!(
                "spz version {} unsupported (2 or 3)",
                self.version
            )));
        }
        Ok(())
    }
}

/// The 16-byte SPZ header.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct SpzHeader {
    pub version: u32,
    pub num_points: u32,
    pub sh_degree: u8,
    pub fractional_bits: u8,
    pub flags: u8,
}

fn to_u8(x: f32) -> u8 {
    // NaN maps to 0 like the reference's clamp of a NaN-free value would not;
    // non-finite inputs are rejected before quantising anyway.
    x.round().clamp(0.0, 255.0) as u8
}

fn quantize_sh(x: f32, bucket: i32) -> u8 {
    let q = (x * 128.0).round() as i32 + 128;
    let q = (q + bucket / 2) / bucket * bucket;
    q.clamp(0, 255) as u8
}

fn unquantize_sh(q: u8) -> f32 {
    (f32::from(q) - 128.0) / 128.0
}

/// Largest fraction bit count ≤ 12 that keeps every coordinate inside the
/// signed 24-bit range.
fn fractional_bits_for(max_abs: f32) -> Result<u8> {
    let limit = ((1u32 << 23) - 1) as f32;
    let mut bits = DEFAULT_FRACTIONAL_BITS;
    loop {
        if max_abs * (1u32 << bits) as f32 <= limit {
            return Ok(bits);
        }
        if bits == 0 {
            return Err(SplatError::Invalid(format!(
                "spz: coordinate magnitude {max_abs} does not fit 24-bit fixed point"
            )));
        }
        bits -= 1;
    }
}

/// Pack a unit quaternion (x, y, z, w) as v3 "smallest three".
fn pack_smallest_three(q: [f32; 4]) -> [u8; 4] {
    let mut largest = 0;
    for i in 1..4 {
        if q[i].abs() > q[largest].abs() {
            largest = i;
        }
    }
    let negate = q[largest] < 0.0;
    let mask = (1u32 << 9) - 1;
    let mut comp = largest as u32;
    for (i, &c) in q.iter().enumerate() {
        if i != largest {
            let negbit = u32::from((c < 0.0) ^ negate);
            let mag = ((mask as f32) * (c.abs() / SQRT1_2) + 0.5) as u32;
            comp = (comp << 10) | (negbit << 9) | mag.min(mask);
        }
    }
    comp.to_le_bytes()
}

fn unpack_smallest_three(b: [u8; 4]) -> [f32; 4] {
    let mut comp = u32::from_le_bytes(b);
    let mask = (1u32 << 9) - 1;
    let largest = (comp >> 30) as usize;
    let mut q = [0.0f32; 4];
    let mut sum = 0.0;
    for i in (0..4).rev() {
        if i != largest {
            let mag = comp & mask;
            let neg = (comp >> 9) & 1;
            comp >>= 10;
            let v = SQRT1_2 * mag as f32 / mask as f32;
            q[i] = if neg == 1 { -v } else { v };
            sum += q[i] * q[i];
        }
    }
    q[largest] = (1.0 - sum).max(0.0).sqrt();
    q
}

/// Encode splats as an SPZ file (gzip stream).
pub fn encode_spz(s: &Splats, opts: &SpzOptions) -> Result<Vec<u8>> {
    opts.validate()?;
    crate::error::check_splats(s)?;
    super::check_finite(s)?;
    let converted;
    let s = if opts.convert_axes {
        converted = rdf_to_rub(s);
        &converted
    } else {
        s
    };
    let n = s.len();
    let k = s.coeffs_per_channel();
    let rest = k - 1;
    let max_abs = s.means.iter().flatten().fold(0.0f32, |m, v| m.max(v.abs()));
    let bits = fractional_bits_for(max_abs)?;
    let rot_bytes = if opts.version >= 3 { 4 } else { 3 };

    let mut raw = Vec::with_capacity(16 + n * (9 + 1 + 3 + 3 + rot_bytes + rest * 3));
    raw.extend_from_slice(&SPZ_MAGIC.to_le_bytes());
    raw.extend_from_slice(&opts.version.to_le_bytes());
    raw.extend_from_slice(&(n as u32).to_le_bytes());
    let flags = if opts.antialiased {
        FLAG_ANTIALIASED
    } else {
        0
    };
    raw.extend_from_slice(&[s.sh_degree as u8, bits, flags, 0]);

    let scale = (1u32 << bits) as f32;
    for p in &s.means {
        for v in p {
            let fixed = (v * scale).round() as i32;
            raw.extend_from_slice(&fixed.to_le_bytes()[..3]);
        }
    }
    for &o in &s.opacity_logits {
        raw.push(to_u8(sigmoid(o) * 255.0));
    }
    for i in 0..n {
        for c in 0..3 {
            let dc = s.sh[i * k * 3 + c];
            raw.push(to_u8(dc * (COLOR_SCALE * 255.0) + 0.5 * 255.0));
        }
    }
    for ls in &s.log_scales {
        for &v in ls {
            raw.push(to_u8((v + 10.0) * 16.0));
        }
    }
    for r in &s.rotations {
        let [w, x, y, z] = normalized_wxyz(*r);
        let q = [x, y, z, w];
        if opts.version >= 3 {
            raw.extend_from_slice(&pack_smallest_three(q));
        } else {
            let sign = if q[3] < 0.0 { -127.5 } else { 127.5 };
            for &c in &q[..3] {
                raw.push(to_u8(c * sign + 127.5));
            }
        }
    }
    for i in 0..n {
        for j in 0..rest {
            let bucket = if j < 3 { SH1_BUCKET } else { SH_REST_BUCKET };
            for c in 0..3 {
                let v = s.sh[i * k * 3 + (j + 1) * 3 + c];
                raw.push(quantize_sh(v, bucket));
            }
        }
    }
    let mut enc = GzEncoder::new(Vec::with_capacity(raw.len() / 3), Compression::default());
    enc.write_all(&raw)
        .and_then(|_| enc.finish())
        .map_err(|e| SplatError::Invalid(format!("spz: gzip failed: {e}")))
}

/// Decode an SPZ file (the bytes of the gzip stream). `convert_axes` must
/// match the writer's setting to get the original frame back.
pub fn decode_spz(bytes: &[u8], convert_axes: bool) -> Result<(SpzHeader, Splats)> {
    let bad = |msg: String| SplatError::Invalid(format!("spz: {msg}"));
    if bytes.len() < 2 || bytes[0] != 0x1f || bytes[1] != 0x8b {
        return Err(bad(
            "not a gzip stream (SPZ v4 zstd containers are not supported)".into(),
        ));
    }
    let mut raw = Vec::new();
    GzDecoder::new(bytes)
        .read_to_end(&mut raw)
        .map_err(|e| bad(format!("gzip: {e}")))?;
    if raw.len() < 16 {
        return Err(bad(format!(
            "{} bytes, shorter than the 16-byte header",
            raw.len()
        )));
    }
    let u32_at = |o: usize| u32::from_le_bytes([raw[o], raw[o + 1], raw[o + 2], raw[o + 3]]);
    if u32_at(0) != SPZ_MAGIC {
        return Err(bad(format!("bad magic {:#010x}", u32_at(0))));
    }
    let header = SpzHeader {
        version: u32_at(4),
        num_points: u32_at(8),
        sh_degree: raw[12],
        fractional_bits: raw[13],
        flags: raw[14],
    };
    if !(2..=3).contains(&header.version) {
        return Err(bad(format!(
            "version {} unsupported (2 or 3)",
            header.version
        )));
    }
    if header.sh_degree > 3 {
        return Err(bad(format!("SH degree {} unsupported", header.sh_degree)));
    }
    if header.flags & FLAG_HAS_EXTENSIONS != 0 {
        return Err(bad("extension records are not supported".into()));
    }
    if header.fractional_bits > 23 {
        return Err(bad(format!(
            "fractionalBits {} out of range",
            header.fractional_bits
        )));
    }
    let n = header.num_points as usize;
    let k = sh_coeffs(u32::from(header.sh_degree));
    let rest = k - 1;
    let rot_bytes = if header.version >= 3 { 4 } else { 3 };
    let per_point = 9 + 1 + 3 + 3 + rot_bytes + rest * 3;
    let expected = n
        .checked_mul(per_point)
        .and_then(|b| b.checked_add(16))
        .ok_or_else(|| bad(format!("numPoints {n} too large")))?;
    if raw.len() != expected {
        return Err(bad(format!(
            "{} bytes after decompression, expected {expected} for {n} points",
            raw.len()
        )));
    }
    let mut s = Splats::with_capacity(n, u32::from(header.sh_degree));
    let mut o = 16;
    let inv = 1.0 / (1u32 << header.fractional_bits) as f32;
    for _ in 0..n {
        let mut p = [0.0f32; 3];
        for (a, pa) in p.iter_mut().enumerate() {
            let b = &raw[o + 3 * a..o + 3 * a + 3];
            // Sign-extend the 24-bit value through an arithmetic shift.
            let fixed = i32::from_le_bytes([0, b[0], b[1], b[2]]) >> 8;
            *pa = fixed as f32 * inv;
        }
        s.means.push(p);
        o += 9;
    }
    for &a in &raw[o..o + n] {
        let p = (f32::from(a) / 255.0).clamp(1e-6, 1.0 - 1e-6);
        s.opacity_logits.push((p / (1.0 - p)).ln());
    }
    o += n;
    for i in 0..n {
        for c in 0..3 {
            s.sh[i * k * 3 + c] = (f32::from(raw[o + 3 * i + c]) / 255.0 - 0.5) / COLOR_SCALE;
        }
    }
    o += 3 * n;
    for i in 0..n {
        let b = &raw[o + 3 * i..o + 3 * i + 3];
        s.log_scales
            .push([0, 1, 2].map(|a| f32::from(b[a]) / 16.0 - 10.0));
    }
    o += 3 * n;
    for i in 0..n {
        let b = &raw[o + rot_bytes * i..o + rot_bytes * (i + 1)];
        let q = if rot_bytes == 4 {
            unpack_smallest_three([b[0], b[1], b[2], b[3]])
        } else {
            let xyz = [0, 1, 2].map(|a| f32::from(b[a]) / 127.5 - 1.0);
            let w = (1.0 - xyz.iter().map(|v| v * v).sum::<f32>())
                .max(0.0)
                .sqrt();
            [xyz[0], xyz[1], xyz[2], w]
        };
        s.rotations.push([q[3], q[0], q[1], q[2]]);
    }
    o += rot_bytes * n;
    for i in 0..n {
        for j in 0..rest {
            for c in 0..3 {
                let q = raw[o + (i * rest + j) * 3 + c];
                s.sh[i * k * 3 + (j + 1) * 3 + c] = unquantize_sh(q);
            }
        }
    }
    Ok((header, if convert_axes { rdf_to_rub(&s) } else { s }))
}

/// Write `s` as an SPZ file at `path` (atomically).
pub fn write_spz(path: &Path, s: &Splats, opts: &SpzOptions) -> Result<u64> {
    let bytes = encode_spz(s, opts).map_err(|e| super::name_file(path, e))?;
    loader::io::write_bytes_atomic(path, &bytes)?;
    Ok(bytes.len() as u64)
}

/// Read an SPZ file written with `convert_axes` (see [`SpzOptions`]).
pub fn read_spz(path: &Path, convert_axes: bool) -> Result<(SpzHeader, Splats)> {
    let bytes = loader::io::read_bytes(path)?;
    decode_spz(&bytes, convert_axes).map_err(|e| super::name_file(path, e))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::needless_range_loop)]
    use super::*;
    use crate::export::test_data::random_splats;

    /// Largest component error of the stored rotation parts: v3 all four
    /// (sign-aligned), v2 only x, y, z (w ≥ 0 is derived, so near w = 0 its
    /// error is not bounded by the quantisation step).
    fn rot_err(version: u32, orig: [f32; 4], dec: [f32; 4]) -> f32 {
        // The decoded quaternion is compared as stored (v2 can decode to
        // |xyz| slightly above 1 with w = 0).
        let a = normalized_wxyz(orig);
        let b = dec;
        let s = if version == 2 {
            if a[0] < 0.0 { -1.0 } else { 1.0 }
        } else {
            let dot: f32 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
            if dot < 0.0 { -1.0 } else { 1.0 }
        };
        let first = if version == 2 { 1 } else { 0 };
        (first..4)
            .map(|i| (s * a[i] - b[i]).abs())
            .fold(0.0, f32::max)
    }

    fn check_round_trip(version: u32, convert_axes: bool) {
        let s = random_splats(500, 3, 7);
        let opts = SpzOptions {
            version,
            convert_axes,
            antialiased: true,
        };
        let bytes = encode_spz(&s, &opts).unwrap();
        // gzip member header: magic 1f 8b, deflate (8).
        assert_eq!(&bytes[..3], &[0x1f, 0x8b, 8]);
        let (h, d) = decode_spz(&bytes, convert_axes).unwrap();
        assert_eq!(h.version, version);
        assert_eq!(h.num_points, 500);
        assert_eq!(h.sh_degree, 3);
        assert_eq!(h.fractional_bits, 12);
        assert_eq!(h.flags, FLAG_ANTIALIASED);
        assert_eq!(d.len(), s.len());
        assert_eq!(d.sh.len(), s.sh.len());
        let k = 16;
        // v3: stored components ≤ ½·√½/511, recomputed largest ≤ 3× that;
        // v2: ½/127.5.
        let rot_tol = if version == 3 {
            2.2e-3
        } else {
            0.5 / 127.5 + 1e-5
        };
        for i in 0..s.len() {
            for a in 0..3 {
                let e = (d.means[i][a] - s.means[i][a]).abs();
                assert!(e <= 0.5 / 4096.0 + 1e-6, "pos {i}/{a}: {e}");
                let e = (d.log_scales[i][a] - s.log_scales[i][a]).abs();
                assert!(e <= 1.0 / 32.0 + 1e-5, "scale {i}/{a}: {e}");
                let e = (d.sh[i * k * 3 + a] - s.sh[i * k * 3 + a]).abs();
                assert!(e <= 0.5 / (0.15 * 255.0) + 1e-5, "dc {i}/{a}: {e}");
            }
            let e = (sigmoid(d.opacity_logits[i]) - sigmoid(s.opacity_logits[i])).abs();
            assert!(e <= 0.5 / 255.0 + 1e-5, "alpha {i}: {e}");
            let e = rot_err(version, s.rotations[i], d.rotations[i]);
            assert!(e <= rot_tol, "rot {i}: {e}");
            for j in 1..k {
                let bucket = if j <= 3 { 8.0 } else { 16.0 };
                for c in 0..3 {
                    let idx = i * k * 3 + j * 3 + c;
                    let e = (d.sh[idx] - s.sh[idx]).abs();
                    assert!(
                        e <= (0.5 + bucket / 2.0) / 128.0 + 1e-5,
                        "sh {i}/{j}/{c}: {e}"
                    );
                }
            }
        }
    }

    #[test]
    fn round_trip_v3_within_quantisation_bounds() {
        check_round_trip(3, true);
    }

    #[test]
    fn round_trip_v2_within_quantisation_bounds() {
        check_round_trip(2, false);
    }

    #[test]
    fn axis_conversion_flips_y_and_z_in_the_stream() {
        let mut s = random_splats(1, 0, 1);
        s.means[0] = [1.0, 2.0, -3.0];
        let bytes = encode_spz(&s, &SpzOptions::default()).unwrap();
        // Read without undoing the conversion: we see SPZ's RUB frame.
        let (_, d) = decode_spz(&bytes, false).unwrap();
        assert_eq!(d.means[0], [1.0, -2.0, 3.0]);
    }

    #[test]
    fn large_coordinates_lower_fractional_bits() {
        let mut s = random_splats(2, 0, 3);
        s.means[1] = [5000.0, -7000.0, 100.0];
        let bytes = encode_spz(&s, &SpzOptions::default()).unwrap();
        let (h, d) = decode_spz(&bytes, true).unwrap();
        assert_eq!(h.fractional_bits, 10); // 7000 · 2^10 < 2^23 ≤ 7000 · 2^11
        assert!((d.means[1][1] + 7000.0).abs() <= 0.5 / 1024.0);
    }

    #[test]
    fn corrupt_input_is_an_error() {
        let s = random_splats(10, 1, 2);
        let bytes = encode_spz(&s, &SpzOptions::default()).unwrap();
        assert!(decode_spz(&bytes[..bytes.len() / 2], true).is_err());
        assert!(decode_spz(b"not gzip", true).is_err());
        // Valid gzip of a truncated payload.
        let mut raw = Vec::new();
        GzDecoder::new(&bytes[..]).read_to_end(&mut raw).unwrap();
        let mut enc = GzEncoder::new(Vec::new(), Compression::fast());
        enc.write_all(&raw[..raw.len() - 1]).unwrap();
        let err = decode_spz(&enc.finish().unwrap(), true)
            .unwrap_err()
            .to_string();
        assert!(err.contains("expected"), "{err}");
    }
}
