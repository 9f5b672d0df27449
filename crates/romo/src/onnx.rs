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
//!
//! Optical flow ([`OnnxFlow`]): two inputs f32 [1, 3, H, W] (the first
//! frame, then the second; RGB, values [0, 1] × `input_scale`), first
//! output f32 [1, 2, h, w], the flow from the first to the second in
//! pixels of its own grid (h × w may be the input size, or a fraction of it
//! as RAFT's 1/8 `flow_low`), or [1, 4, h, w]: forward then backward flow
//! from one run (`scripts/export_gmflow_onnx.py` writes GMFlow so). A
//! model with a static size gets the frames padded at the bottom / right
//! by edge replication, after shrinking them (aspect ratio kept) when they
//! are larger; its flow is cropped back and rescaled ([`Placement`]).
//! Dynamic sizes get the frames padded to a multiple of 32.
//! `scripts/make_lk_flow_onnx.py` writes a Lucas–Kanade model with this
//! signature, used by the tests.

use crate::features::{FeatureExtractor, FeatureMap, HandFeatures};
use crate::flow::{Flow, FlowEstimator, Placement};
use crate::plane::{Plane, Rgb};
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

/// Load the runtime from `$ORT_DYLIB_PATH` (once per process) and a model.
fn load_session(model: &Path) -> Result<(Session, ort::environment::Environment)> {
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
    Ok((session, env))
}

impl OnnxFeatures {
    /// Load the runtime from `$ORT_DYLIB_PATH` and the model file.
    pub fn load(model: &Path) -> Result<Self> {
        let (session, env) = load_session(model)?;
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

/// An optical-flow network run through ONNX Runtime (see the module docs
/// for the signature).
pub struct OnnxFlow {
    session: Mutex<Session>,
    _env: ort::environment::Environment,
    /// Static model input size (w, h), read from the model; None when its
    /// height or width is dynamic.
    pub input_size: Option<(usize, usize)>,
    /// Pixel values are [0, 1] × `input_scale` (1 by default; 255 for RAFT
    /// exports that take 0–255 and normalise inside).
    pub input_scale: f32,
}

/// Dynamic model inputs are padded to a multiple of this (GMFlow's 1/8
/// features split in 2 × 2 windows need 32; RAFT's 8 divides it).
pub const DYNAMIC_MULTIPLE: usize = 32;

impl OnnxFlow {
    /// Load the runtime from `$ORT_DYLIB_PATH` and the model file; checks
    /// the two-input signature.
    pub fn load(model: &Path, input_scale: f32) -> Result<Self> {
        let (session, env) = load_session(model)?;
        let ins = session.inputs();
        if ins.len() != 2 {
            return Err(RomoError::Onnx(format!(
                "{}: a flow model takes two images, this one has {} inputs",
                model.display(),
                ins.len()
            )));
        }
        let shape: Vec<i64> = ins[0]
            .dtype()
            .tensor_shape()
            .map(|s| s.to_vec())
            .unwrap_or_default();
        if shape.len() != 4 || (shape[1] != 3 && shape[1] != -1) {
            return Err(RomoError::Onnx(format!(
                "{}: expected inputs [1, 3, H, W], the first is {shape:?}",
                model.display()
            )));
        }
        let input_size =
            (shape[2] > 0 && shape[3] > 0).then_some((shape[3] as usize, shape[2] as usize));
        if !(input_scale.is_finite() && input_scale > 0.0) {
            return Err(RomoError::Onnx(format!(
                "{}: input scale must be > 0",
                model.display()
            )));
        }
        Ok(Self {
            session: Mutex::new(session),
            _env: env,
            input_size,
            input_scale,
        })
    }

    /// Where frames of `w × h` go in the model's input.
    pub fn placement(&self, w: usize, h: usize) -> Placement {
        match self.input_size {
            Some(size) => Placement::fixed((w, h), size),
            None => Placement::padded((w, h), DYNAMIC_MULTIPLE),
        }
    }

    /// The size (w, h) frames of `w × h` are given to the model at.
    pub fn model_size(&self, w: usize, h: usize) -> (usize, usize) {
        self.placement(w, h).input
    }

    /// Run the model on two frames given as channel planes (1 plane: gray,
    /// repeated; 3: RGB). Returns the forward flow and, when the model
    /// outputs [1, 4, h, w] (forward then backward), the backward flow.
    fn run(&self, a: &[&Plane], b: &[&Plane]) -> Result<(Flow, Option<Flow>)> {
        let (w, h) = (a[0].w, a[0].h);
        if a.iter().chain(b).any(|p| (p.w, p.h) != (w, h)) {
            return Err(RomoError::Input(format!(
                "flow: frames of {}x{} and {}x{}",
                w, h, b[0].w, b[0].h
            )));
        }
        let place = self.placement(w, h);
        let (mw, mh) = place.input;
        let tensor = |planes: &[&Plane]| {
            let mut data = Vec::with_capacity(3 * mw * mh);
            for k in 0..3 {
                let p = place.place(planes[k.min(planes.len() - 1)]);
                data.extend(p.data.iter().map(|v| v * self.input_scale));
            }
            Tensor::from_array(([1usize, 3, mh, mw], data)).map_err(|e| err("input tensor", e))
        };
        let (ta, tb) = (tensor(a)?, tensor(b)?);
        let mut session = self
            .session
            .lock()
            .map_err(|_| RomoError::Onnx("session lock poisoned".into()))?;
        let outputs = session
            .run(ort::inputs![ta, tb])
            .map_err(|e| err("flow inference", e))?;
        let (shape, values) = outputs[0]
            .try_extract_tensor::<f32>()
            .map_err(|e| err("flow output", e))?;
        if shape.len() != 4 || shape[0] != 1 || (shape[1] != 2 && shape[1] != 4) {
            return Err(RomoError::Onnx(format!(
                "expected a [1, 2, h, w] or [1, 4, h, w] flow output, got {shape:?}"
            )));
        }
        let (oc, oh, ow) = (shape[1] as usize, shape[2] as usize, shape[3] as usize);
        if values.len() != oc * oh * ow || values.iter().any(|v| !v.is_finite()) {
            return Err(RomoError::Onnx(
                "flow output has non-finite values or the wrong length".into(),
            ));
        }
        let plane = |k: usize| Plane {
            w: ow,
            h: oh,
            data: values[k * oh * ow..(k + 1) * oh * ow].to_vec(),
        };
        let flow = |k: usize| {
            place.unplace(&Flow {
                u: plane(k),
                v: plane(k + 1),
            })
        };
        Ok((flow(0), (oc == 4).then(|| flow(2))))
    }
}

impl FlowEstimator for OnnxFlow {
    fn name(&self) -> &str {
        "onnx-flow"
    }

    /// Gray frames are given to the model as three equal channels.
    fn flow(&self, i0: &Plane, i1: &Plane) -> Result<Flow> {
        Ok(self.run(&[i0], &[i1])?.0)
    }

    /// A model with a fixed input gets the video's frames at full size
    /// when they fit, else as large as fits (aspect ratio kept); one with
    /// dynamic sizes gets them at the pipeline's flow resolution.
    fn frame_size(&self, full: (usize, usize), working: (usize, usize)) -> (usize, usize) {
        match self.input_size {
            Some(size) => Placement::fixed(full, size).content,
            None => working,
        }
    }

    /// RGB frames; one run when the model outputs both directions.
    fn flow_pair(&self, a: &Rgb, b: &Rgb) -> Result<(Flow, Flow)> {
        let (ca, cb) = ([&a.c[0], &a.c[1], &a.c[2]], [&b.c[0], &b.c[1], &b.c[2]]);
        let (fwd, bwd) = self.run(&ca, &cb)?;
        let bwd = match bwd {
            Some(f) => f,
            None => self.run(&cb, &ca)?.0,
        };
        Ok((fwd, bwd))
    }
}
