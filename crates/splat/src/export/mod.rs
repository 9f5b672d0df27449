//! Splat exports: the formats other tools read, and the clean-up pass run
//! before exporting.
//!
//! - `.ply`: the INRIA 3DGS layout, our exchange format (written by
//!   `crate::io`, this module only dispatches);
//! - `.splat`: antimatter15's 32-byte web format ([`web_splat`]);
//! - `.spz`: Niantic's gzip-compressed format, written and read ([`spz`]);
//! - `.glb`: glTF binary with `KHR_gaussian_splatting` ([`glb`]);
//! - [`clean`]: removes near-transparent, unseen, oversized and out-of-bounds
//!   splats and reports how many of each.
//!
//! Every writer goes through `loader::io::write_bytes_atomic` (temp + rename).

pub mod clean;
pub mod glb;
pub mod spz;
pub mod web_splat;

#[cfg(test)]
pub(crate) mod test_data;

pub use clean::{CleanOptions, CleanReport, SceneGeometry, clean};
pub use glb::{GlbOptions, decode_glb, encode_glb, parse_glb, read_glb, write_glb};
pub use spz::{SpzOptions, decode_spz, encode_spz, read_spz, write_spz};
pub use web_splat::{decode_splat, encode_splat, read_splat, write_splat};

use crate::error::{Result, SplatError};
use crate::types::Splats;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The degree-0 SH basis constant 1/(2√π): colour = 0.5 + SH_C0 · dc.
pub const SH_C0: f32 = 0.282_094_8;

pub(crate) fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// Normalise a (w, x, y, z) quaternion; a zero or non-finite one becomes the
/// identity.
pub(crate) fn normalized_wxyz(q: [f32; 4]) -> [f32; 4] {
    let n = q.iter().map(|v| v * v).sum::<f32>().sqrt();
    if n > 0.0 && n.is_finite() {
        q.map(|v| v / n)
    } else {
        [1.0, 0.0, 0.0, 0.0]
    }
}

/// SH sign flips of the higher-order coefficients (degree 1..3, INRIA order)
/// under the 180° rotation about x that maps COLMAP's right-down-front axes to
/// the right-up-back axes of SPZ and glTF: with axis flips (x, y, z) =
/// (1, −1, −1) each basis function changes sign with the product of the flips
/// of the axes it is odd in (the table of nianticlabs/spz
/// `coordinateConverter`).
const RUB_SH_FLIP: [f32; 15] = [
    -1.0, -1.0, 1.0, // degree 1: y, z, x
    -1.0, 1.0, 1.0, -1.0, 1.0, // degree 2: xy, yz, 1, xz, 1
    -1.0, 1.0, -1.0, -1.0, 1.0, -1.0, 1.0, // degree 3: y, xyz, y, z, x, z, x
];

/// Rotate splats by 180° about x: COLMAP/OpenCV right-down-front world axes
/// become right-up-back (y up, as glTF and SPZ expect), and back (the map is
/// its own inverse). Positions (x, −y, −z); quaternions (w, x, −y, −z), which
/// is R·Rot(q)·Rᵀ for R = diag(1, −1, −1) and leaves the covariance's
/// principal scales unchanged; SH coefficients sign-flipped per basis
/// function. A proper rotation, so handedness is kept.
pub fn rdf_to_rub(s: &Splats) -> Splats {
    let k = s.coeffs_per_channel();
    let mut out = s.clone();
    for p in &mut out.means {
        p[1] = -p[1];
        p[2] = -p[2];
    }
    for q in &mut out.rotations {
        q[2] = -q[2];
        q[3] = -q[3];
    }
    for coeffs in out.sh.chunks_exact_mut(k * 3) {
        for j in 1..k {
            let f = RUB_SH_FLIP[j - 1];
            for v in &mut coeffs[j * 3..j * 3 + 3] {
                *v *= f;
            }
        }
    }
    out
}

/// Reject NaN / infinite parameters (every format would silently corrupt them).
pub(crate) fn check_finite(s: &Splats) -> Result<()> {
    let bad = s
        .means
        .iter()
        .flatten()
        .chain(s.log_scales.iter().flatten())
        .chain(s.rotations.iter().flatten())
        .chain(&s.opacity_logits)
        .chain(&s.sh)
        .any(|v| !v.is_finite());
    if bad {
        return Err(SplatError::Invalid(
            "splats contain NaN or infinite values".into(),
        ));
    }
    Ok(())
}

/// Attach a file name to an error that lacks one.
pub(crate) fn name_file(path: &Path, e: SplatError) -> SplatError {
    match e {
        SplatError::Invalid(msg) => SplatError::File {
            path: path.to_path_buf(),
            msg,
        },
        other => other,
    }
}

/// An export format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum ExportFormat {
    /// INRIA 3DGS PLY.
    Ply,
    /// antimatter15 `.splat` (32 bytes per splat, no SH beyond the colour).
    Splat,
    /// glTF binary with KHR_gaussian_splatting.
    Glb,
    /// Niantic SPZ (gzip).
    Spz,
}

impl ExportFormat {
    /// All formats.
    pub const ALL: [ExportFormat; 4] = [
        ExportFormat::Ply,
        ExportFormat::Splat,
        ExportFormat::Glb,
        ExportFormat::Spz,
    ];

    /// The lower-case name, also the usual file extension.
    pub fn name(self) -> &'static str {
        match self {
            ExportFormat::Ply => "ply",
            ExportFormat::Splat => "splat",
            ExportFormat::Glb => "glb",
            ExportFormat::Spz => "spz",
        }
    }

    /// The format a file extension names, if any.
    pub fn from_path(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        ext.parse().ok()
    }
}

impl std::str::FromStr for ExportFormat {
    type Err = SplatError;
    fn from_str(s: &str) -> Result<Self> {
        ExportFormat::ALL
            .into_iter()
            .find(|f| f.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| {
                SplatError::Invalid(format!("unknown export format {s:?} (ply|splat|glb|spz)"))
            })
    }
}

impl std::fmt::Display for ExportFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Per-format options of [`export`].
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct ExportOptions {
    pub spz: SpzOptions,
    pub glb: GlbOptions,
}

impl ExportOptions {
    /// Check the options.
    pub fn validate(&self) -> Result<()> {
        self.spz.validate()
    }
}

/// What [`export`] wrote.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ExportSummary {
    pub format: ExportFormat,
    pub path: PathBuf,
    pub splats: usize,
    pub bytes: u64,
    /// SH degree stored in the file (`.splat` keeps only the DC colour).
    pub sh_degree: u32,
}

/// Encode `s` in `format` and decode the bytes again with the reader
/// `inspect` and `export` use, so nothing is written that cannot be read
/// back (e.g. a log scale whose `exp` overflows the linear scales of
/// `.splat` and `.glb`). Returns the bytes and the SH degree stored.
pub fn encode_checked(
    s: &Splats,
    format: ExportFormat,
    path: &Path,
    opts: &ExportOptions,
) -> Result<(Vec<u8>, u32)> {
    opts.validate()?;
    let named = |e| name_file(path, e);
    let (bytes, back) = match format {
        ExportFormat::Ply => {
            let b = crate::io::encode_ply_named(s, path)?;
            let back = crate::io::decode_ply(&b, path)?;
            (b, back)
        }
        ExportFormat::Splat => {
            let b = encode_splat(s).map_err(named)?;
            let back = decode_splat(&b).map_err(named)?;
            (b, back)
        }
        ExportFormat::Glb => {
            let b = encode_glb(s, &opts.glb).map_err(named)?;
            let back = decode_glb(&b, opts.glb.to_gltf_axes).map_err(named)?;
            (b, back)
        }
        ExportFormat::Spz => {
            let b = encode_spz(s, &opts.spz).map_err(named)?;
            let back = decode_spz(&b, opts.spz.convert_axes).map_err(named)?.1;
            (b, back)
        }
    };
    if back.len() != s.len() {
        return Err(SplatError::File {
            path: path.to_path_buf(),
            msg: format!(
                "{format} encoding holds {} splats, not {}",
                back.len(),
                s.len()
            ),
        });
    }
    if let Err(e) = crate::io::to_ply_splats(&back)?.validate(path) {
        let why = match e {
            loader::LoaderError::Format { msg, .. } => msg,
            other => other.to_string(),
        };
        return Err(SplatError::File {
            path: path.to_path_buf(),
            msg: format!("not written: as {format} it would not read back ({why})"),
        });
    }
    Ok((bytes, back.sh_degree))
}

/// Write `s` to `path` in `format` (atomically), after checking that the
/// encoded bytes read back ([`encode_checked`]).
pub fn export(
    s: &Splats,
    format: ExportFormat,
    path: &Path,
    opts: &ExportOptions,
) -> Result<ExportSummary> {
    let (bytes, sh_degree) = encode_checked(s, format, path, opts)?;
    loader::io::write_bytes_atomic(path, &bytes)?;
    Ok(ExportSummary {
        format,
        path: path.to_path_buf(),
        splats: s.len(),
        bytes: bytes.len() as u64,
        sh_degree,
    })
}

#[cfg(test)]
#[path = "tests.rs"]
mod tests;
