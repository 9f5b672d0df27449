//! Splat PLY in the INRIA 3D Gaussian Splatting layout (Kerbl et al. 2023,
//! `graphdeco-inria/gaussian-splatting`, `GaussianModel.save_ply`): one
//! `vertex` element with float properties
//! `x y z nx ny nz f_dc_0..2 f_rest_0..(3(K-1)-1) opacity scale_0..2 rot_0..3`,
//! K = (degree+1)². Opacity is stored as a logit, scales as logs, rotations as
//! quaternions (w, x, y, z), colours as SH coefficients.
//!
//! `f_rest` is channel-major as INRIA writes it: `f_rest_{c·(K-1)+k}` is
//! channel c (0 = R, 1 = G, 2 = B) of SH coefficient k+1.
//!
//! Hand-written reader and writer (no PLY crate): binary little-endian read
//! and write, plus ASCII and big-endian read. Every property may be any PLY
//! scalar type on read; writing always uses float32 little-endian.

mod read;

pub use read::{read_ply, read_ply_bytes};

use crate::error::{LoaderError, Result};
use crate::io::write_atomic;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;

/// Splats as plain arrays, in the INRIA PLY's own parameterisation.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PlySplats {
    /// Centres (x, y, z), world units.
    pub means: Vec<[f32; 3]>,
    /// Normals (INRIA writes zeros); `None` writes zeros.
    pub normals: Option<Vec<[f32; 3]>>,
    /// Degree-0 SH coefficient per channel (`f_dc_0..2`).
    pub f_dc: Vec<[f32; 3]>,
    /// Higher SH coefficients, `3·(K-1)` per splat, channel-major (see module docs).
    pub f_rest: Vec<f32>,
    /// Opacity logits.
    pub opacities: Vec<f32>,
    /// Log scales.
    pub scales: Vec<[f32; 3]>,
    /// Rotation quaternions (w, x, y, z), not necessarily normalised.
    pub rotations: Vec<[f32; 4]>,
    /// SH degree 0..=3.
    pub sh_degree: u32,
}

/// Number of `f_rest` values per splat for an SH degree: 3·((d+1)² − 1).
pub fn rest_len(sh_degree: u32) -> usize {
    3 * (((sh_degree + 1) * (sh_degree + 1)) as usize - 1)
}

/// SH degree from the per-splat `f_rest` count (0, 9, 24, 45).
pub fn degree_from_rest(n: usize) -> Option<u32> {
    (0..=3).find(|d| rest_len(*d) == n)
}

impl PlySplats {
    /// Number of splats.
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// True when there are no splats.
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// Check array lengths agree and every value is finite; `path` names the
    /// file in errors.
    pub fn validate(&self, path: &Path) -> Result<()> {
        let n = self.len();
        if self.sh_degree > 3 {
            return Err(LoaderError::format(
                path,
                format!("SH degree {} > 3", self.sh_degree),
            ));
        }
        let r = rest_len(self.sh_degree);
        let lens = [
            ("f_dc", self.f_dc.len()),
            ("opacities", self.opacities.len()),
            ("scales", self.scales.len()),
            ("rotations", self.rotations.len()),
            ("normals", self.normals.as_ref().map_or(n, |v| v.len())),
        ];
        for (what, l) in lens {
            if l != n {
                return Err(LoaderError::format(
                    path,
                    format!("{what} has {l} entries for {n} splats"),
                ));
            }
        }
        if self.f_rest.len() != n * r {
            return Err(LoaderError::format(
                path,
                format!(
                    "f_rest has {} values, expected {n} × {r} for SH degree {}",
                    self.f_rest.len(),
                    self.sh_degree
                ),
            ));
        }
        let finite3 = |v: &[[f32; 3]]| v.par_iter().all(|a| a.iter().all(|x| x.is_finite()));
        let all_finite = finite3(&self.means)
            && self.normals.as_deref().is_none_or(finite3)
            && finite3(&self.f_dc)
            && self.f_rest.par_iter().all(|x| x.is_finite())
            && self.opacities.par_iter().all(|x| x.is_finite())
            && finite3(&self.scales)
            && self
                .rotations
                .par_iter()
                .all(|a| a.iter().all(|x| x.is_finite()));
        if all_finite {
            return Ok(());
        }
        // Slow path only on failure: find the first offending value.
        let names = self.property_names();
        let mut row = Vec::with_capacity(names.len());
        for i in 0..n {
            row.clear();
            self.push_row(i, &mut row);
            if let Some(k) = row.iter().position(|v| !v.is_finite()) {
                return Err(LoaderError::format(
                    path,
                    format!(
                        "splat {i}: property {} is {} (NaN/Inf not allowed)",
                        names[k], row[k]
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Property names in INRIA order for this SH degree.
    pub fn property_names(&self) -> Vec<String> {
        property_names(self.sh_degree)
    }

    fn push_row(&self, i: usize, v: &mut Vec<f32>) {
        let r = rest_len(self.sh_degree);
        v.extend_from_slice(&self.means[i]);
        v.extend_from_slice(&self.normals.as_ref().map_or([0.0; 3], |n| n[i]));
        v.extend_from_slice(&self.f_dc[i]);
        v.extend_from_slice(&self.f_rest[i * r..(i + 1) * r]);
        v.push(self.opacities[i]);
        v.extend_from_slice(&self.scales[i]);
        v.extend_from_slice(&self.rotations[i]);
    }
}

/// INRIA property names for an SH degree.
pub fn property_names(sh_degree: u32) -> Vec<String> {
    let mut v: Vec<String> = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ]
    .map(String::from)
    .to_vec();
    v.extend((0..rest_len(sh_degree)).map(|k| format!("f_rest_{k}")));
    v.push("opacity".into());
    v.extend(
        [
            "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
        ]
        .map(String::from),
    );
    v
}

/// Encode splats as a binary little-endian PLY in memory.
pub fn encode_ply(splats: &PlySplats, path: &Path) -> Result<Vec<u8>> {
    splats.validate(path)?;
    let names = splats.property_names();
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\n",
        splats.len()
    );
    for n in &names {
        header.push_str(&format!("property float {n}\n"));
    }
    header.push_str("end_header\n");
    let stride = names.len() * 4;
    let mut out = vec![0u8; header.len() + splats.len() * stride];
    out[..header.len()].copy_from_slice(header.as_bytes());
    const CHUNK: usize = 4096;
    let r = rest_len(splats.sh_degree);
    out[header.len()..]
        .par_chunks_mut(stride * CHUNK)
        .enumerate()
        .for_each(|(c, buf)| {
            for (j, dst) in buf.chunks_exact_mut(stride).enumerate() {
                let i = c * CHUNK + j;
                let mut o = 0;
                let mut put = |vals: &[f32]| {
                    for (d, v) in dst[o..o + 4 * vals.len()].chunks_exact_mut(4).zip(vals) {
                        d.copy_from_slice(&v.to_le_bytes());
                    }
                    o += 4 * vals.len();
                };
                put(&splats.means[i]);
                put(&splats.normals.as_ref().map_or([0.0; 3], |n| n[i]));
                put(&splats.f_dc[i]);
                put(&splats.f_rest[i * r..(i + 1) * r]);
                put(&[splats.opacities[i]]);
                put(&splats.scales[i]);
                put(&splats.rotations[i]);
            }
        });
    Ok(out)
}

/// Write splats as a binary little-endian INRIA PLY, atomically. Fails on
/// NaN/Inf or inconsistent array lengths (naming the file).
pub fn write_ply(path: impl AsRef<Path>, splats: &PlySplats) -> Result<()> {
    let path = path.as_ref();
    let bytes = encode_ply(splats, path)?;
    write_atomic(path, |w: &mut dyn Write| {
        w.write_all(&bytes).map_err(|e| LoaderError::io(path, e))
    })
}

/// Write a coloured point cloud (`x y z` float, `red green blue` uchar) as a
/// binary little-endian PLY, e.g. COLMAP's sparse points for viewing.
pub fn write_points_ply(path: impl AsRef<Path>, xyz: &[[f32; 3]], rgb: &[[u8; 3]]) -> Result<()> {
    let path = path.as_ref();
    if xyz.len() != rgb.len() {
        return Err(LoaderError::Invalid(format!(
            "{}: {} points but {} colours",
            path.display(),
            xyz.len(),
            rgb.len()
        )));
    }
    let header = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
        xyz.len()
    );
    let mut out = Vec::with_capacity(header.len() + xyz.len() * 15);
    out.extend_from_slice(header.as_bytes());
    for (p, c) in xyz.iter().zip(rgb) {
        for v in p {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(c);
    }
    write_atomic(path, |w: &mut dyn Write| {
        w.write_all(&out).map_err(|e| LoaderError::io(path, e))
    })
}

#[cfg(test)]
#[path = "tests.rs"]
mod tests;
