//! Neural feature encoders through ONNX Runtime (cargo feature `onnx`),
//! the paper's route to SAM2 features. The runtime library is loaded at run
//! time with `ort::init_from($ORT_DYLIB_PATH)`, so a missing runtime is an
//! error, not a link failure or a panic.
//!
//! Supported signature (XFeat backbone, Potje et al. CVPR 2024, as in
//! `xfeat.onnx`): input `input` f32 [1, 3, S, S] RGB in [0, 1] (S = 640);
//! first output [1, C, S/8, S/8] dense descriptors (C = 64). SAM2's image
//! encoder has the same shape of contract (input [1, 3, 1024, 1024]
//! ImageNet-normalised RGB, output `image_embed` [1, 256, 64, 64]) and is
//! used by setting `input_size` 1024 and `imagenet_norm`.

use crate::features::{FeatureExtractor, FeatureMap, HandFeatures};
use crate::plane::Rgb;
use crate::{Result, RomoError};
use ort::session::Session;
use ort::value::Tensor;
use std::path::Path;
use std::sync::Mutex;

/// The process's ONNX Runtime environment (at most one may exist).
static ENV: Mutex<Option<ort::environment::Environment>> = Mutex::new(None);

fn err(ctx: &str, e: impl std::fmt::Display) -> RomoError {
    RomoError::Onnx(format!("{ctx}: {e}"))
}

/// A dense-descriptor encoder run through ONNX Runtime.
pub struct OnnxFeatures {
    session: Mutex<Session>,
    _env: ort::environment::Environment,
    /// Square input side S (640 for XFeat, 1024 for SAM2).
    pub input_size: usize,
    /// Normalise with ImageNet mean / std (SAM2) instead of plain [0, 1].
    pub imagenet_norm: bool,
}

impl OnnxFeatures {
    /// Load the runtime from `$ORT_DYLIB_PATH` and the model file.
    pub fn load(model: &Path) -> Result<Self> {
        let lib = std::env::var_os("ORT_DYLIB_PATH").ok_or_else(|| {
            RomoError::Onnx(
                "ORT_DYLIB_PATH is not set: point it at libonnxruntime.so (e.g. the capi/ folder of `pip install onnxruntime`)"
                    .into(),
            )
        })?;
        let lib = std::path::PathBuf::from(lib);
        if !lib.exists() {
            return Err(RomoError::Onnx(format!(
                "{}: ONNX Runtime library not found",
                lib.display()
            )));
        }
        if !model.exists() {
            return Err(RomoError::Onnx(format!(
                "{}: model file not found",
                model.display()
            )));
        }
        // ONNX Runtime allows one environment per process: build it once
        // and share it, so a process can load models (or run RoMo) twice.
        let env = {
            let mut g = ENV
                .lock()
                .map_err(|_| RomoError::Onnx("environment lock poisoned".into()))?;
            match &*g {
                Some(e) => e.clone(),
                None => {
                    let e = ort::init_from(&lib)
                        .map_err(|e| err(&lib.display().to_string(), e))?
                        .build()
                        .map_err(|e| err("ONNX Runtime environment", e))?;
                    *g = Some(e.clone());
                    e
                }
            }
        };
        let session = Session::builder(&env)
            .map_err(|e| err("session", e))?
            .commit_from_file(model)
            .map_err(|e| err(&model.display().to_string(), e))?;
        Ok(Self {
            session: Mutex::new(session),
            _env: env,
            input_size: 640,
            imagenet_norm: false,
        })
    }

    /// Run the encoder on one frame; returns its native-resolution map.
    pub fn encode(&self, frame: &Rgb) -> Result<FeatureMap> {
        let s = self.input_size;
        let img = frame.resize(s, s);
        let (mean, std) = if self.imagenet_norm {
            ([0.485, 0.456, 0.406], [0.229, 0.224, 0.225])
        } else {
            ([0.0; 3], [1.0; 3])
        };
        let mut data = Vec::with_capacity(3 * s * s);
        for k in 0..3 {
            data.extend(img.c[k].data.iter().map(|v| (v - mean[k]) / std[k]));
        }
        let input =
            Tensor::from_array(([1usize, 3, s, s], data)).map_err(|e| err("input tensor", e))?;
        let mut session = self
            .session
            .lock()
            .map_err(|_| RomoError::Onnx("session lock poisoned".into()))?;
        let outputs = session
            .run(ort::inputs![input])
            .map_err(|e| err("inference", e))?;
        let (shape, values) = outputs[0]
            .try_extract_tensor::<f32>()
            .map_err(|e| err("output", e))?;
        if shape.len() != 4 || shape[0] != 1 {
            return Err(RomoError::Onnx(format!(
                "expected a [1, C, h, w] output, got {shape:?}"
            )));
        }
        let (c, h, w) = (shape[1] as usize, shape[2] as usize, shape[3] as usize);
        Ok(FeatureMap {
            c,
            w,
            h,
            data: values.to_vec(),
        })
    }
}

impl FeatureExtractor for OnnxFeatures {
    fn name(&self) -> &str {
        "onnx"
    }

    fn extract(&self, frame: &Rgb, w: usize, h: usize) -> Result<FeatureMap> {
        Ok(self.encode(frame)?.resize(w, h))
    }
}

/// An ONNX encoder's channels concatenated with the built-in descriptor
/// (our prototype found the two best together); the second field sets the
/// descriptor's options (the pipeline passes `chromaticity_features`).
pub struct WithHand(pub OnnxFeatures, pub HandFeatures);

impl FeatureExtractor for WithHand {
    fn name(&self) -> &str {
        "onnx+hand"
    }

    fn extract(&self, frame: &Rgb, w: usize, h: usize) -> Result<FeatureMap> {
        let a = self.1.extract(frame, w, h)?;
        let b = self.0.extract(frame, w, h)?;
        FeatureMap::concat(&[a, b]).ok_or_else(|| RomoError::Onnx("feature sizes differ".into()))
    }
}
