//! PLY header parsing and vertex decoding for the splat reader: ASCII,
//! binary little-endian and big-endian; any scalar property type. Elements
//! before `vertex` are skipped (list properties included).

use super::{PlySplats, degree_from_rest};
use crate::error::{LoaderError, Result};
use crate::io::read_bytes;
use rayon::prelude::*;
use std::collections::HashMap;
use std::path::Path;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Format {
    Ascii,
    BinLe,
    BinBe,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Scalar> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
    /// Decode one value at the start of `b` (which holds at least `size()` bytes).
    #[inline]
    fn decode(self, b: &[u8], le: bool) -> f64 {
        macro_rules! get {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&b[..$n]);
                (if le {
                    <$t>::from_le_bytes(a)
                } else {
                    <$t>::from_be_bytes(a)
                }) as f64
            }};
        }
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => get!(i16, 2),
            Scalar::U16 => get!(u16, 2),
            Scalar::I32 => get!(i32, 4),
            Scalar::U32 => get!(u32, 4),
            Scalar::F32 => get!(f32, 4),
            Scalar::F64 => get!(f64, 8),
        }
    }
}

#[derive(Debug, Clone)]
struct Prop {
    name: String,
    ty: Scalar,
    /// Count type when this is a list property.
    list: Option<Scalar>,
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Prop>,
}

struct Header {
    format: Format,
    elements: Vec<Element>,
    data_start: usize,
}

fn parse_header(bytes: &[u8], path: &Path) -> Result<Header> {
    let bad = |m: String| LoaderError::format(path, format!("bad PLY header: {m}"));
    if !bytes.starts_with(b"ply\n") && !bytes.starts_with(b"ply\r\n") {
        return Err(LoaderError::format(
            path,
            "not a PLY file (missing 'ply' magic)",
        ));
    }
    let limit = bytes.len().min(1 << 20);
    let pos = bytes[..limit]
        .windows(10)
        .position(|w| w == b"end_header")
        .ok_or_else(|| bad("no end_header".into()))?;
    let nl = bytes[pos..]
        .iter()
        .position(|b| *b == b'\n')
        .ok_or_else(|| bad("truncated after end_header".into()))?;
    let text = std::str::from_utf8(&bytes[..pos]).map_err(|_| bad("header is not text".into()))?;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    for (ln, line) in text.lines().enumerate().skip(1) {
        let t: Vec<&str> = line.split_whitespace().collect();
        match t.first().copied() {
            None | Some("comment") | Some("obj_info") => {}
            Some("format") => {
                format = Some(match t.get(1).copied() {
                    Some("ascii") => Format::Ascii,
                    Some("binary_little_endian") => Format::BinLe,
                    Some("binary_big_endian") => Format::BinBe,
                    f => return Err(bad(format!("line {}: unknown format {f:?}", ln + 1))),
                })
            }
            Some("element") => {
                let (Some(name), Some(count)) =
                    (t.get(1), t.get(2).and_then(|c| c.parse::<usize>().ok()))
                else {
                    return Err(bad(format!(
                        "line {}: malformed element line {line:?}",
                        ln + 1
                    )));
                };
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            Some("property") => {
                let el = elements
                    .last_mut()
                    .ok_or_else(|| bad(format!("line {}: property before element", ln + 1)))?;
                let prop = if t.get(1) == Some(&"list") {
                    match (
                        t.get(2).and_then(|s| Scalar::parse(s)),
                        t.get(3).and_then(|s| Scalar::parse(s)),
                        t.get(4),
                    ) {
                        (Some(c), Some(ty), Some(n)) => Prop {
                            name: n.to_string(),
                            ty,
                            list: Some(c),
                        },
                        _ => {
                            return Err(bad(format!(
                                "line {}: malformed list property {line:?}",
                                ln + 1
                            )));
                        }
                    }
                } else {
                    match (t.get(1).and_then(|s| Scalar::parse(s)), t.get(2)) {
                        (Some(ty), Some(n)) => Prop {
                            name: n.to_string(),
                            ty,
                            list: None,
                        },
                        _ => {
                            return Err(bad(format!(
                                "line {}: malformed property {line:?}",
                                ln + 1
                            )));
                        }
                    }
                };
                el.props.push(prop);
            }
            Some(k) => return Err(bad(format!("line {}: unknown keyword {k:?}", ln + 1))),
        }
    }
    let format = format.ok_or_else(|| bad("no format line".into()))?;
    Ok(Header {
        format,
        elements,
        data_start: pos + nl + 1,
    })
}

/// Read a splat PLY (INRIA layout) from a file.
pub fn read_ply(path: impl AsRef<Path>) -> Result<PlySplats> {
    let path = path.as_ref();
    read_ply_bytes(&read_bytes(path)?, path)
}

/// Read a splat PLY from bytes; `path` names it in errors.
pub fn read_ply_bytes(bytes: &[u8], path: &Path) -> Result<PlySplats> {
    let h = parse_header(bytes, path)?;
    let vi = h
        .elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| LoaderError::format(path, "bad PLY header: no 'vertex' element"))?;
    let vertex = &h.elements[vi];
    if vertex.props.iter().any(|p| p.list.is_some()) {
        return Err(LoaderError::format(
            path,
            "bad PLY header: list property in 'vertex'",
        ));
    }
    let np = vertex.props.len();
    let n = vertex.count;
    let col: HashMap<&str, usize> = vertex
        .props
        .iter()
        .enumerate()
        .map(|(i, p)| (p.name.as_str(), i))
        .collect();
    let need = |name: &str| -> Result<usize> {
        col.get(name).copied().ok_or_else(|| {
            LoaderError::format(path, format!("bad PLY header: missing property '{name}'"))
        })
    };
    let take3 =
        |a: &str, b: &str, c: &str| -> Result<[usize; 3]> { Ok([need(a)?, need(b)?, need(c)?]) };
    let nrest = vertex
        .props
        .iter()
        .filter(|p| p.name.starts_with("f_rest_"))
        .count();
    let sh_degree = degree_from_rest(nrest).ok_or_else(|| {
        LoaderError::format(
            path,
            format!("bad PLY header: {nrest} f_rest properties (expected 0, 9, 24 or 45)"),
        )
    })?;
    let cols = Cols {
        pos: take3("x", "y", "z")?,
        normals: take3("nx", "ny", "nz").ok(),
        dc: take3("f_dc_0", "f_dc_1", "f_dc_2")?,
        rest: (0..nrest)
            .map(|k| need(&format!("f_rest_{k}")))
            .collect::<Result<Vec<usize>>>()?,
        op: need("opacity")?,
        sc: take3("scale_0", "scale_1", "scale_2")?,
        rot: [
            need("rot_0")?,
            need("rot_1")?,
            need("rot_2")?,
            need("rot_3")?,
        ],
    };
    let data = &bytes[h.data_start..];
    let mut splats = match h.format {
        Format::Ascii => {
            let values = decode_ascii(data, &h.elements[..vi], vertex, path)?;
            assemble(n, &cols, sh_degree, |i, c| values[i * np + c])
        }
        Format::BinLe | Format::BinBe => {
            let le = h.format == Format::BinLe;
            let mut off = 0;
            for el in &h.elements[..vi] {
                off += skip_binary(&data[off..], el, le, path)?;
            }
            let data = &data[off..];
            let offsets: Vec<(usize, Scalar)> = vertex
                .props
                .iter()
                .scan(0usize, |o, p| {
                    let r = (*o, p.ty);
                    *o += p.ty.size();
                    Some(r)
                })
                .collect();
            let stride: usize = vertex.props.iter().map(|p| p.ty.size()).sum();
            let need = stride
                .checked_mul(n)
                .ok_or_else(|| truncated(path, "vertex count too large"))?;
            if data.len() < need {
                let what = format!(
                    "{n} vertices × {stride} bytes need {need} bytes, file has {}",
                    data.len()
                );
                return Err(truncated(path, &what));
            }
            if le && vertex.props.iter().all(|p| p.ty == Scalar::F32) {
                assemble(n, &cols, sh_degree, |i, c| {
                    let o = i * stride + 4 * c;
                    f32::from_le_bytes([data[o], data[o + 1], data[o + 2], data[o + 3]])
                })
            } else {
                assemble(n, &cols, sh_degree, |i, c| {
                    let (o, ty) = offsets[c];
                    ty.decode(&data[i * stride + o..], le) as f32
                })
            }
        }
    };
    if cols.normals.is_none() {
        splats.normals = None;
    }
    splats.validate(path)?;
    Ok(splats)
}

/// Column index of each field in the vertex element.
struct Cols {
    pos: [usize; 3],
    normals: Option<[usize; 3]>,
    dc: [usize; 3],
    rest: Vec<usize>,
    op: usize,
    sc: [usize; 3],
    rot: [usize; 4],
}

/// Fill a [`PlySplats`] in one parallel pass; `get(i, c)` is vertex i, column c.
fn assemble(
    n: usize,
    cols: &Cols,
    sh_degree: u32,
    get: impl Fn(usize, usize) -> f32 + Sync,
) -> PlySplats {
    const C: usize = 4096;
    let r = cols.rest.len();
    let mut means = vec![[0f32; 3]; n];
    let mut normals = vec![[0f32; 3]; if cols.normals.is_some() { n } else { 0 }];
    let mut f_dc = vec![[0f32; 3]; n];
    let mut f_rest = vec![0f32; n * r];
    let mut opacities = vec![0f32; n];
    let mut scales = vec![[0f32; 3]; n];
    let mut rotations = vec![[0f32; 4]; n];
    let g3 = |i: usize, c: &[usize; 3]| [get(i, c[0]), get(i, c[1]), get(i, c[2])];
    {
        let rest_it: Box<dyn Iterator<Item = &mut [f32]>> = if r > 0 {
            Box::new(f_rest.chunks_mut(C * r))
        } else {
            Box::new(std::iter::repeat_with(Default::default))
        };
        let norm_it: Box<dyn Iterator<Item = &mut [[f32; 3]]>> = if cols.normals.is_some() {
            Box::new(normals.chunks_mut(C))
        } else {
            Box::new(std::iter::repeat_with(Default::default))
        };
        type Chunk<'a> = (
            usize,
            &'a mut [[f32; 3]],
            &'a mut [[f32; 3]],
            &'a mut [[f32; 3]],
            &'a mut [f32],
            &'a mut [f32],
            &'a mut [[f32; 3]],
            &'a mut [[f32; 4]],
        );
        let chunks: Vec<Chunk> = means
            .chunks_mut(C)
            .zip(norm_it)
            .zip(f_dc.chunks_mut(C))
            .zip(rest_it)
            .zip(opacities.chunks_mut(C))
            .zip(scales.chunks_mut(C))
            .zip(rotations.chunks_mut(C))
            .enumerate()
            .map(|(k, ((((((m, nn), d), re), o), s), ro))| (k * C, m, nn, d, re, o, s, ro))
            .collect();
        chunks
            .into_par_iter()
            .for_each(|(start, m, nn, d, re, o, s, ro)| {
                for j in 0..m.len() {
                    let i = start + j;
                    m[j] = g3(i, &cols.pos);
                    if let Some(nc) = &cols.normals {
                        nn[j] = g3(i, nc);
                    }
                    d[j] = g3(i, &cols.dc);
                    for (k, c) in cols.rest.iter().enumerate() {
                        re[j * r + k] = get(i, *c);
                    }
                    o[j] = get(i, cols.op);
                    s[j] = g3(i, &cols.sc);
                    ro[j] = [
                        get(i, cols.rot[0]),
                        get(i, cols.rot[1]),
                        get(i, cols.rot[2]),
                        get(i, cols.rot[3]),
                    ];
                }
            });
    }
    PlySplats {
        means,
        normals: Some(normals),
        f_dc,
        f_rest,
        opacities,
        scales,
        rotations,
        sh_degree,
    }
}

fn truncated(path: &Path, what: &str) -> LoaderError {
    LoaderError::format(path, format!("truncated PLY data: {what}"))
}

/// Skip the binary rows of an element; returns the bytes consumed.
fn skip_binary(data: &[u8], el: &Element, le: bool, path: &Path) -> Result<usize> {
    let mut off = 0usize;
    if el.props.iter().all(|p| p.list.is_none()) {
        let stride: usize = el.props.iter().map(|p| p.ty.size()).sum();
        off = stride
            .checked_mul(el.count)
            .ok_or_else(|| truncated(path, "element too large"))?;
    } else {
        for _ in 0..el.count {
            for p in &el.props {
                match p.list {
                    None => off += p.ty.size(),
                    Some(c) => {
                        let cb = data
                            .get(off..off + c.size())
                            .ok_or_else(|| truncated(path, &el.name))?;
                        let cnt = c.decode(cb, le).max(0.0) as usize;
                        off += c.size() + cnt * p.ty.size();
                    }
                }
            }
        }
    }
    if off > data.len() {
        return Err(truncated(path, &format!("element '{}'", el.name)));
    }
    Ok(off)
}

fn decode_ascii(
    data: &[u8],
    before: &[Element],
    vertex: &Element,
    path: &Path,
) -> Result<Vec<f32>> {
    let text = std::str::from_utf8(data)
        .map_err(|_| LoaderError::format(path, "ASCII PLY data is not text"))?;
    let mut tok = text.split_ascii_whitespace();
    let mut next = |what: &str| tok.next().ok_or_else(|| truncated(path, what));
    for el in before.iter().filter(|e| !e.props.is_empty()) {
        for _ in 0..el.count {
            for p in &el.props {
                let cnt = match p.list {
                    None => 1,
                    Some(_) => next(&el.name)?
                        .parse::<usize>()
                        .map_err(|_| truncated(path, "bad list count"))?,
                };
                for _ in 0..cnt {
                    next(&el.name)?;
                }
            }
        }
    }
    // Every value takes at least two bytes (a digit and a separator), so the
    // file's size, not the header's count, bounds the allocation.
    let values = vertex.count.saturating_mul(vertex.props.len());
    let mut out = Vec::with_capacity(values.min(data.len() / 2 + 1));
    for i in 0..vertex.count {
        for p in &vertex.props {
            let t = tok
                .next()
                .ok_or_else(|| truncated(path, &format!("vertex {i} of {}", vertex.count)))?;
            let v: f64 = t.parse().map_err(|_| {
                LoaderError::format(path, format!("vertex {i}: bad value {t:?} for {}", p.name))
            })?;
            out.push(v as f32);
        }
    }
    Ok(out)
}
