//! glTF 2.0 binary (.glb) export with the `KHR_gaussian_splatting` extension
//! (KhronosGroup/glTF, `extensions/2.0/Khronos/KHR_gaussian_splatting`,
//! Release Candidate text of 2026): one mesh primitive with mode POINTS whose
//! attributes are
//!
//! | attribute | accessor | content |
//! |---|---|---|
//! | `POSITION` | VEC3 float, with min/max | splat centre |
//! | `COLOR_0` | VEC4 unsigned byte normalized | fallback colour: 0.5 + SH_C0·dc clamped to [0, 1], decoded sRGB → linear; alpha = opacity |
//! | `KHR_gaussian_splatting:ROTATION` | VEC4 float | unit quaternion x y z w |
//! | `KHR_gaussian_splatting:SCALE` | VEC3 float | linear σ = exp(log scale) (the RC text: "linear and MUST NOT be negative"; earlier drafts stored the log) |
//! | `KHR_gaussian_splatting:OPACITY` | SCALAR float | sigmoid(opacity logit) in [0, 1] |
//! | `KHR_gaussian_splatting:SH_DEGREE_l_COEF_n` | VEC3 float | SH coefficient (r g b) |
//!
//! and the extension object `{kernel: "ellipse", colorSpace:
//! "srgb_rec709_display", projection: "perspective", sortingMethod:
//! "cameraDistance"}`. INRIA's SH basis already carries the Condon–Shortley
//! signs the extension uses, and its coefficient order within a degree is the
//! extension's COEF_0.. order, so coefficients are copied unchanged.
//!
//! The JSON document is built with `gltf-json`; its `Semantic` type cannot name
//! the extension's `KHR_gaussian_splatting:*` attributes, so those are added to
//! the serialised primitive's `attributes` map afterwards. The GLB container
//! (12-byte header, JSON chunk padded with spaces, BIN chunk padded with
//! zeros, all 4-byte aligned) is written by hand.
//!
//! Axes: our splats are in COLMAP's right-down-front frame; glTF is y-up. As
//! the extension recommends for converted data, positions, quaternions and SH
//! are rotated into glTF's frame ([`super::rdf_to_rub`], 180° about x) rather
//! than leaving it to a node transform that renderers would have to apply to
//! the SH as well; [`GlbOptions::to_gltf_axes`] turns this off.

use super::{SH_C0, normalized_wxyz, rdf_to_rub, sigmoid};
use crate::error::{Result, SplatError};
use crate::types::Splats;
use gltf_json as json;
use json::validation::{Checked, USize64};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::path::Path;

/// Name of the extension.
pub const EXTENSION: &str = "KHR_gaussian_splatting";
const GLB_MAGIC: u32 = 0x4654_6C67; // "glTF"
const CHUNK_JSON: u32 = 0x4E4F_534A; // "JSON"
const CHUNK_BIN: u32 = 0x004E_4942; // "BIN\0"

/// How to write the .glb.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct GlbOptions {
    /// Rotate the splats from COLMAP's y-down axes into glTF's y-up axes
    /// (180° about x). Default true.
    pub to_gltf_axes: bool,
}

impl Default for GlbOptions {
    fn default() -> Self {
        GlbOptions { to_gltf_axes: true }
    }
}

/// The attribute name for SH degree `l`, coefficient `n` within the degree.
pub fn sh_attribute(l: u32, n: u32) -> String {
    format!("{EXTENSION}:SH_DEGREE_{l}_COEF_{n}")
}

/// Accumulates buffer views and accessors over one binary buffer.
struct Builder {
    root: json::Root,
    bin: Vec<u8>,
}

impl Builder {
    fn push_view(&mut self, bytes: &[u8]) -> json::Index<json::buffer::View> {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.root.push(json::buffer::View {
            buffer: json::Index::new(0),
            byte_length: USize64::from(bytes.len()),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            extensions: Default::default(),
            extras: Default::default(),
            target: Some(Checked::Valid(json::buffer::Target::ArrayBuffer)),
        })
    }

    /// Push an accessor over f32 data with `dims` components per element.
    fn push_f32(
        &mut self,
        data: &[f32],
        dims: usize,
        min_max: bool,
    ) -> json::Index<json::Accessor> {
        let ty = match dims {
            1 => json::accessor::Type::Scalar,
            3 => json::accessor::Type::Vec3,
            _ => json::accessor::Type::Vec4,
        };
        let (min, max) = if min_max {
            let mut lo = vec![f32::INFINITY; dims];
            let mut hi = vec![f32::NEG_INFINITY; dims];
            for e in data.chunks_exact(dims) {
                for a in 0..dims {
                    lo[a] = lo[a].min(e[a]);
                    hi[a] = hi[a].max(e[a]);
                }
            }
            (Some(Value::from(lo)), Some(Value::from(hi)))
        } else {
            (None, None)
        };
        let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.push_view(&bytes);
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(data.len() / dims),
            component_type: Checked::Valid(json::accessor::GenericComponentType(
                json::accessor::ComponentType::F32,
            )),
            extensions: Default::default(),
            extras: Default::default(),
            type_: Checked::Valid(ty),
            min,
            max,
            normalized: false,
            sparse: None,
        })
    }

    fn push_rgba8(&mut self, data: &[u8]) -> json::Index<json::Accessor> {
        let view = self.push_view(data);
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(data.len() / 4),
            component_type: Checked::Valid(json::accessor::GenericComponentType(
                json::accessor::ComponentType::U8,
            )),
            extensions: Default::default(),
            extras: Default::default(),
            type_: Checked::Valid(json::accessor::Type::Vec4),
            min: None,
            max: None,
            normalized: true,
            sparse: None,
        })
    }
}

fn to_unorm8(x: f32) -> u8 {
    (x.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// The sRGB transfer function's inverse (IEC 61966-2-1), for `COLOR_0`,
/// which glTF defines as linear.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Encode the splats as a .glb byte vector.
pub fn encode_glb(s: &Splats, opts: &GlbOptions) -> Result<Vec<u8>> {
    crate::error::check_splats(s)?;
    super::check_finite(s)?;
    if s.is_empty() {
        // glTF accessors need count ≥ 1.
        return Err(SplatError::Invalid("glb: no splats to export".into()));
    }
    let converted;
    let s = if opts.to_gltf_axes {
        converted = rdf_to_rub(s);
        &converted
    } else {
        s
    };
    let n = s.len();
    let k = s.coeffs_per_channel();
    let mut b = Builder {
        root: json::Root::default(),
        bin: Vec::new(),
    };
    b.root.asset.generator = Some(format!("romosplat {}", env!("CARGO_PKG_VERSION")));

    let pos: Vec<f32> = s.means.iter().flatten().copied().collect();
    let position = b.push_f32(&pos, 3, true);
    let mut rgba = Vec::with_capacity(4 * n);
    for i in 0..n {
        for c in 0..3 {
            let srgb = (0.5 + SH_C0 * s.sh[i * k * 3 + c]).clamp(0.0, 1.0);
            rgba.push(to_unorm8(srgb_to_linear(srgb)));
        }
        rgba.push(to_unorm8(sigmoid(s.opacity_logits[i])));
    }
    let color = b.push_rgba8(&rgba);

    let mut ext_attrs: Vec<(String, json::Index<json::Accessor>)> = Vec::new();
    let rot: Vec<f32> = s
        .rotations
        .iter()
        .flat_map(|r| {
            let [w, x, y, z] = normalized_wxyz(*r);
            [x, y, z, w]
        })
        .collect();
    ext_attrs.push((format!("{EXTENSION}:ROTATION"), b.push_f32(&rot, 4, false)));
    let scale: Vec<f32> = s.log_scales.iter().flatten().map(|v| v.exp()).collect();
    ext_attrs.push((format!("{EXTENSION}:SCALE"), b.push_f32(&scale, 3, false)));
    let opacity: Vec<f32> = s.opacity_logits.iter().map(|&o| sigmoid(o)).collect();
    ext_attrs.push((
        format!("{EXTENSION}:OPACITY"),
        b.push_f32(&opacity, 1, false),
    ));
    for l in 0..=s.sh_degree {
        for m in 0..(2 * l + 1) {
            let j = (l * l + m) as usize;
            let coef: Vec<f32> = (0..n)
                .flat_map(|i| {
                    let o = i * k * 3 + j * 3;
                    [s.sh[o], s.sh[o + 1], s.sh[o + 2]]
                })
                .collect();
            ext_attrs.push((sh_attribute(l, m), b.push_f32(&coef, 3, false)));
        }
    }
    while !b.bin.len().is_multiple_of(4) {
        b.bin.push(0);
    }
    b.root.push(json::Buffer {
        byte_length: USize64::from(b.bin.len()),
        uri: None,
        extensions: Default::default(),
        extras: Default::default(),
    });

    let mut attributes = std::collections::BTreeMap::new();
    attributes.insert(Checked::Valid(json::mesh::Semantic::Positions), position);
    attributes.insert(Checked::Valid(json::mesh::Semantic::Colors(0)), color);
    let primitive = json::mesh::Primitive {
        attributes,
        extensions: Default::default(),
        extras: Default::default(),
        indices: None,
        material: None,
        mode: Checked::Valid(json::mesh::Mode::Points),
        targets: None,
    };
    let mesh = b.root.push(json::Mesh {
        extensions: Default::default(),
        extras: Default::default(),
        primitives: vec![primitive],
        weights: None,
    });
    let node = b.root.push(json::Node {
        mesh: Some(mesh),
        ..Default::default()
    });
    let scene = b.root.push(json::Scene {
        extensions: Default::default(),
        extras: Default::default(),
        nodes: vec![node],
    });
    b.root.scene = Some(scene);
    b.root.extensions_used = vec![EXTENSION.to_string()];

    let mut doc = serde_json::to_value(&b.root)
        .map_err(|e| SplatError::Invalid(format!("glb: json: {e}")))?;
    let prim = doc
        .pointer_mut("/meshes/0/primitives/0")
        .and_then(Value::as_object_mut)
        .ok_or_else(|| SplatError::Invalid("glb: serialised document has no primitive".into()))?;
    if let Some(Value::Object(attrs)) = prim.get_mut("attributes") {
        for (name, idx) in &ext_attrs {
            attrs.insert(name.clone(), Value::from(idx.value()));
        }
    }
    prim.insert(
        "extensions".into(),
        serde_json::json!({ EXTENSION: {
            "kernel": "ellipse",
            "colorSpace": "srgb_rec709_display",
            "projection": "perspective",
            "sortingMethod": "cameraDistance",
        }}),
    );
    let json_bytes =
        serde_json::to_vec(&doc).map_err(|e| SplatError::Invalid(format!("glb: json: {e}")))?;
    Ok(glb_container(json_bytes, b.bin))
}

fn glb_container(mut json_bytes: Vec<u8>, mut bin: Vec<u8>) -> Vec<u8> {
    while !json_bytes.len().is_multiple_of(4) {
        json_bytes.push(b' ');
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + json_bytes.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(&GLB_MAGIC.to_le_bytes());
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json_bytes.len() as u32).to_le_bytes());
    out.extend_from_slice(&CHUNK_JSON.to_le_bytes());
    out.extend_from_slice(&json_bytes);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(&CHUNK_BIN.to_le_bytes());
    out.extend_from_slice(&bin);
    out
}

/// A parsed GLB: the JSON document and the BIN chunk.
#[derive(Debug, Clone)]
pub struct Glb {
    pub json: Value,
    pub bin: Vec<u8>,
}

/// Parse a GLB container (header and the JSON + BIN chunks), checking
/// lengths and alignment as the glTF spec requires.
pub fn parse_glb(bytes: &[u8]) -> Result<Glb> {
    let bad = |m: String| SplatError::Invalid(format!("glb: {m}"));
    let u32_at = |o: usize| -> Result<u32> {
        bytes
            .get(o..o + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .ok_or_else(|| bad(format!("truncated at byte {o}")))
    };
    if u32_at(0)? != GLB_MAGIC {
        return Err(bad("bad magic".into()));
    }
    if u32_at(4)? != 2 {
        return Err(bad(format!(
            "container version {} (expected 2)",
            u32_at(4)?
        )));
    }
    if u32_at(8)? as usize != bytes.len() {
        return Err(bad(format!(
            "header length {} ≠ file length {}",
            u32_at(8)?,
            bytes.len()
        )));
    }
    let mut o = 12;
    let mut chunks = Vec::new();
    while o < bytes.len() {
        let len = u32_at(o)? as usize;
        let ty = u32_at(o + 4)?;
        if !len.is_multiple_of(4) {
            return Err(bad(format!("chunk at {o} has unaligned length {len}")));
        }
        let data = bytes
            .get(o + 8..o + 8 + len)
            .ok_or_else(|| bad(format!("chunk at {o} runs past the end")))?;
        chunks.push((ty, data));
        o += 8 + len;
    }
    let (ty, json_data) = chunks.first().ok_or_else(|| bad("no chunks".into()))?;
    if *ty != CHUNK_JSON {
        return Err(bad("first chunk is not JSON".into()));
    }
    let json = serde_json::from_slice(json_data).map_err(|e| bad(format!("json chunk: {e}")))?;
    let bin = match chunks.get(1) {
        Some((CHUNK_BIN, d)) => d.to_vec(),
        Some(_) => return Err(bad("second chunk is not BIN".into())),
        None => Vec::new(),
    };
    Ok(Glb { json, bin })
}

/// The f32 data of accessor `idx` (tightly packed or strided, in the BIN
/// chunk), `dims` components per element. Sizes are checked against the
/// buffer view before anything is allocated.
fn read_f32_accessor(glb: &Glb, idx: usize, dims: usize, what: &str) -> Result<Vec<f32>> {
    let bad = |m: String| SplatError::Invalid(format!("glb: {what}: {m}"));
    let acc = glb
        .json
        .pointer(&format!("/accessors/{idx}"))
        .ok_or_else(|| bad(format!("accessor {idx} does not exist")))?;
    let field = |v: &Value, k: &str| v.get(k).and_then(Value::as_u64).map(|x| x as usize);
    if field(acc, "componentType") != Some(5126) {
        return Err(bad("component type is not FLOAT".into()));
    }
    let want_ty = match dims {
        1 => "SCALAR",
        3 => "VEC3",
        _ => "VEC4",
    };
    if acc.get("type").and_then(Value::as_str) != Some(want_ty) {
        return Err(bad(format!("accessor type is not {want_ty}")));
    }
    let count = field(acc, "count").ok_or_else(|| bad("accessor has no count".into()))?;
    let view_idx =
        field(acc, "bufferView").ok_or_else(|| bad("accessor has no bufferView".into()))?;
    let view = glb
        .json
        .pointer(&format!("/bufferViews/{view_idx}"))
        .ok_or_else(|| bad(format!("bufferView {view_idx} does not exist")))?;
    if field(view, "buffer") != Some(0) {
        return Err(bad(
            "data outside the GLB's BIN chunk is not supported".into()
        ));
    }
    let view_off = field(view, "byteOffset").unwrap_or(0);
    let view_len =
        field(view, "byteLength").ok_or_else(|| bad("bufferView has no byteLength".into()))?;
    let elem = 4 * dims;
    let stride = field(view, "byteStride").unwrap_or(elem);
    if stride < elem {
        return Err(bad(format!("byteStride {stride} < element size {elem}")));
    }
    let view_bytes = view_off
        .checked_add(view_len)
        .and_then(|end| glb.bin.get(view_off..end))
        .ok_or_else(|| bad("bufferView runs past the BIN chunk".into()))?;
    let acc_off = field(acc, "byteOffset").unwrap_or(0);
    let needed = match count {
        0 => Some(0),
        c => (c - 1)
            .checked_mul(stride)
            .and_then(|x| x.checked_add(elem))
            .and_then(|x| x.checked_add(acc_off)),
    };
    if needed.is_none_or(|n| n > view_bytes.len()) {
        return Err(bad(format!(
            "{count} elements do not fit the {}-byte bufferView",
            view_bytes.len()
        )));
    }
    let data = &view_bytes[acc_off..];
    let mut out = Vec::with_capacity(count * dims);
    for i in 0..count {
        let e = &data[i * stride..i * stride + elem];
        out.extend(
            e.chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        );
    }
    Ok(out)
}

/// Decode the splats of a `KHR_gaussian_splatting` .glb (the first mesh
/// primitive): position, rotation, linear scale, opacity and the
/// `SH_DEGREE_l_COEF_n` coefficients (degree 0 required). `from_gltf_axes`
/// undoes [`GlbOptions::to_gltf_axes`]. Values are not range-checked here;
/// a zero scale decodes to a log scale of −∞, which callers reject.
pub fn decode_glb(bytes: &[u8], from_gltf_axes: bool) -> Result<Splats> {
    let glb = parse_glb(bytes)?;
    let attrs = glb
        .json
        .pointer("/meshes/0/primitives/0/attributes")
        .and_then(Value::as_object)
        .ok_or_else(|| SplatError::Invalid("glb: no mesh primitive".into()))?;
    let get = |name: &str, dims: usize| -> Result<Vec<f32>> {
        let idx = attrs
            .get(name)
            .and_then(Value::as_u64)
            .ok_or_else(|| SplatError::Invalid(format!("glb: no attribute {name}")))?;
        read_f32_accessor(&glb, idx as usize, dims, name)
    };
    let pos = get("POSITION", 3)?;
    let n = pos.len() / 3;
    let rot = get(&format!("{EXTENSION}:ROTATION"), 4)?;
    let scale = get(&format!("{EXTENSION}:SCALE"), 3)?;
    let opacity = get(&format!("{EXTENSION}:OPACITY"), 1)?;
    let degree = (0..=3u32)
        .take_while(|l| attrs.contains_key(&sh_attribute(*l, 0)))
        .last()
        .ok_or_else(|| SplatError::Invalid(format!("glb: no attribute {}", sh_attribute(0, 0))))?;
    let k = crate::types::sh_coeffs(degree);
    let mut coefs = Vec::with_capacity(k);
    for l in 0..=degree {
        for m in 0..(2 * l + 1) {
            coefs.push(get(&sh_attribute(l, m), 3)?);
        }
    }
    for (name, len) in [
        ("ROTATION", rot.len() / 4),
        ("SCALE", scale.len() / 3),
        ("OPACITY", opacity.len()),
    ]
    .into_iter()
    .chain(coefs.iter().map(|c| ("SH", c.len() / 3)))
    {
        if len != n {
            return Err(SplatError::Invalid(format!(
                "glb: {name} has {len} elements for {n} positions"
            )));
        }
    }
    let mut sh = vec![0.0f32; n * k * 3];
    for (i, block) in sh.chunks_exact_mut(k * 3).enumerate() {
        for (j, c) in coefs.iter().enumerate() {
            block[j * 3..j * 3 + 3].copy_from_slice(&c[i * 3..i * 3 + 3]);
        }
    }
    let s = Splats {
        means: pos.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        log_scales: scale
            .chunks_exact(3)
            .map(|c| [c[0].ln(), c[1].ln(), c[2].ln()])
            .collect(),
        rotations: rot
            .chunks_exact(4)
            .map(|c| [c[3], c[0], c[1], c[2]])
            .collect(),
        opacity_logits: opacity
            .iter()
            .map(|&o| {
                let p = o.clamp(1e-6, 1.0 - 1e-6);
                (p / (1.0 - p)).ln()
            })
            .collect(),
        sh,
        sh_degree: degree,
    };
    Ok(if from_gltf_axes { rdf_to_rub(&s) } else { s })
}

/// Read a .glb written with the default [`GlbOptions`] (glTF axes).
pub fn read_glb(path: &Path) -> Result<Splats> {
    let bytes = loader::io::read_bytes(path)?;
    decode_glb(&bytes, true).map_err(|e| super::name_file(path, e))
}

/// Write the .glb atomically; returns its size in bytes.
pub fn write_glb(path: &Path, s: &Splats, opts: &GlbOptions) -> Result<u64> {
    let bytes = encode_glb(s, opts).map_err(|e| super::name_file(path, e))?;
    loader::io::write_bytes_atomic(path, &bytes)?;
    Ok(bytes.len() as u64)
}

#[cfg(test)]
#[path = "glb_tests.rs"]
mod tests;
