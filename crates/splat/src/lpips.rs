//! LPIPS (Zhang et al., "The Unreasonable Effectiveness of Deep Features as
//! a Perceptual Metric", CVPR 2018) through ONNX Runtime, cargo feature
//! `onnx`. NeRF On-the-go and SpotLessSplats report it beside PSNR / SSIM.
//! The network is not shipped (its AlexNet / VGG backbones come from
//! torchvision); a user exports it from the `lpips` PyPI package with
//! `torch.onnx.export` (see the README) and passes the file.
//!
//! Model signature accepted (the layout of `lpips.LPIPS(net=...)` exported
//! with two image arguments):
//! - two f32 inputs, each `[1, 3, H, W]` RGB in [−1, 1] (H, W dynamic, or
//!   fixed — then both images are resized bilinearly to that size);
//! - first output f32: the distance as a scalar, `[1]`, `[1, 1]` or
//!   `[1, 1, 1, 1]` (the package's default), or a spatial map `[1, 1, h, w]`
//!   (`spatial=True`), which is averaged.
//!
//! Anything else is an error naming the model file. The runtime library is
//! loaded at run time with `ort::init_from($ORT_DYLIB_PATH)`, so a missing
//! runtime is a one-line error, not a link failure.

use image::Rgb32FImage;
use image::imageops::FilterType;
use ort::environment::Environment;
use ort::session::Session;
use ort::value::{Tensor, TensorElementType, ValueType};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// LPIPS errors; each message names the model or runtime file.
#[derive(Debug, thiserror::Error)]
pub enum LpipsError {
    /// `ORT_DYLIB_PATH` unset or pointing at nothing.
    #[error("{0}")]
    Runtime(String),
    /// The model file is missing, unreadable or has another signature.
    #[error("{}: {msg}", path.display())]
    Model { path: PathBuf, msg: String },
    /// The two images differ in size or do not match their stated size.
    #[error("LPIPS: {0}")]
    Input(String),
}

type Result<T> = std::result::Result<T, LpipsError>;

/// A loaded LPIPS network.
pub struct Lpips {
    session: Session,
    _env: Environment,
    path: PathBuf,
    /// Fixed input size (W, H) when the model has one.
    fixed: Option<(u32, u32)>,
}

impl std::fmt::Debug for Lpips {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Lpips")
            .field("path", &self.path)
            .field("fixed", &self.fixed)
            .finish()
    }
}

/// ONNX Runtime allows one environment per process: build it once, share it.
static ENV: Mutex<Option<Environment>> = Mutex::new(None);

fn environment(lib: &Path) -> Result<Environment> {
    let mut g = ENV
        .lock()
        .map_err(|_| LpipsError::Runtime("ONNX Runtime environment lock poisoned".into()))?;
    if let Some(env) = g.as_ref() {
        return Ok(env.clone());
    }
    let env = ort::init_from(lib)
        .map_err(|e| LpipsError::Runtime(format!("{}: {e}", lib.display())))?
        .build()
        .map_err(|e| LpipsError::Runtime(format!("ONNX Runtime environment: {e}")))?;
    *g = Some(env.clone());
    Ok(env)
}

/// The fixed (W, H) of a `[1, 3, H, W]` f32 input, `None` when dynamic;
/// an error message when the input is anything else.
fn check_input(t: &ValueType) -> std::result::Result<Option<(u32, u32)>, String> {
    let ValueType::Tensor { ty, shape, .. } = t else {
        return Err(format!("input is {t}, expected an f32 tensor [1, 3, H, W]"));
    };
    if *ty != TensorElementType::Float32 {
        return Err(format!("input is {ty:?}, expected f32 [1, 3, H, W]"));
    }
    let d: &[i64] = shape;
    let ok = |v: i64, want: i64| v == want || v < 0;
    if d.len() != 4 || !ok(d[0], 1) || !ok(d[1], 3) {
        return Err(format!("input shape {d:?}, expected [1, 3, H, W]"));
    }
    match (d[2], d[3]) {
        (h, w) if h > 0 && w > 0 => Ok(Some((w as u32, h as u32))),
        (h, w) if h <= 0 && w <= 0 => Ok(None),
        _ => Err(format!(
            "input shape {d:?}: H and W must both be fixed or both dynamic"
        )),
    }
}

impl Lpips {
    /// Load the runtime from `$ORT_DYLIB_PATH` and the model, checking its
    /// signature (see the module doc).
    pub fn load(model: &Path) -> Result<Self> {
        let lib = std::env::var_os("ORT_DYLIB_PATH").ok_or_else(|| {
            LpipsError::Runtime(
                "ORT_DYLIB_PATH is not set: point it at libonnxruntime.so (e.g. the capi/ folder of `pip install onnxruntime`)"
                    .into(),
            )
        })?;
        let lib = PathBuf::from(lib);
        if !lib.is_file() {
            return Err(LpipsError::Runtime(format!(
                "{}: ONNX Runtime library not found (ORT_DYLIB_PATH)",
                lib.display()
            )));
        }
        let bad = |msg: String| LpipsError::Model {
            path: model.to_path_buf(),
            msg,
        };
        if !model.is_file() {
            return Err(bad("LPIPS model file not found".into()));
        }
        let env = environment(&lib)?;
        let session = Session::builder(&env)
            .map_err(|e| bad(format!("session: {e}")))?
            .commit_from_file(model)
            .map_err(|e| bad(e.to_string()))?;
        let inputs = session.inputs();
        if inputs.len() != 2 {
            return Err(bad(format!(
                "LPIPS model has {} inputs, expected 2 images [1, 3, H, W]",
                inputs.len()
            )));
        }
        let a = check_input(inputs[0].dtype()).map_err(|m| bad(format!("first {m}")))?;
        let b = check_input(inputs[1].dtype()).map_err(|m| bad(format!("second {m}")))?;
        if a != b {
            return Err(bad(format!(
                "the two inputs have different sizes ({a:?} vs {b:?})"
            )));
        }
        match session.outputs().first().map(|o| o.dtype()) {
            Some(ValueType::Tensor {
                ty: TensorElementType::Float32,
                ..
            }) => {}
            Some(t) => return Err(bad(format!("output is {t}, expected an f32 distance"))),
            None => return Err(bad("model has no outputs".into())),
        }
        Ok(Lpips {
            session,
            _env: env,
            path: model.to_path_buf(),
            fixed: a,
        })
    }

    /// The model's fixed input size (W, H), if any.
    pub fn fixed_size(&self) -> Option<(u32, u32)> {
        self.fixed
    }

    /// LPIPS distance between two RGB images in [0, 1] (interleaved,
    /// `w × h × 3`). Lower is more similar; 0 for identical images.
    pub fn distance(&mut self, a: &[f32], b: &[f32], w: u32, h: u32) -> Result<f64> {
        let n = w as usize * h as usize * 3;
        if a.len() != n || b.len() != n {
            return Err(LpipsError::Input(format!(
                "images of {} and {} values for {w}x{h} RGB ({n})",
                a.len(),
                b.len()
            )));
        }
        let tensor = |img: &[f32]| -> Result<Tensor<f32>> {
            let (tw, th, data) = match self.fixed {
                Some((fw, fh)) if (fw, fh) != (w, h) => {
                    let im = Rgb32FImage::from_raw(w, h, img.to_vec())
                        .ok_or_else(|| LpipsError::Input("image buffer size".into()))?;
                    (
                        fw,
                        fh,
                        image::imageops::resize(&im, fw, fh, FilterType::Triangle).into_raw(),
                    )
                }
                _ => (w, h, img.to_vec()),
            };
            let plane = tw as usize * th as usize;
            let mut chw = vec![0f32; plane * 3];
            for (p, px) in data.chunks_exact(3).enumerate() {
                for k in 0..3 {
                    chw[k * plane + p] = 2.0 * px[k] - 1.0;
                }
            }
            Tensor::from_array(([1usize, 3, th as usize, tw as usize], chw))
                .map_err(|e| LpipsError::Input(format!("input tensor: {e}")))
        };
        let (ta, tb) = (tensor(a)?, tensor(b)?);
        let path = self.path.clone();
        let bad = |msg: String| LpipsError::Model {
            path: path.clone(),
            msg,
        };
        let outputs = self
            .session
            .run(ort::inputs![ta, tb])
            .map_err(|e| bad(format!("inference: {e}")))?;
        let (shape, values) = outputs[0]
            .try_extract_tensor::<f32>()
            .map_err(|e| bad(format!("output: {e}")))?;
        let d: &[i64] = shape;
        let spatial = d.len() == 4 && d[0] == 1 && d[1] == 1;
        if values.is_empty() || (values.len() != 1 && !spatial) {
            return Err(bad(format!(
                "output shape {d:?}: expected a scalar, [1, 1, 1, 1] or a [1, 1, h, w] map"
            )));
        }
        let mean = values.iter().map(|&v| v as f64).sum::<f64>() / values.len() as f64;
        if !mean.is_finite() {
            return Err(bad(format!("output is {mean}")));
        }
        Ok(mean)
    }
}
