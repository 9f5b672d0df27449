#![allow(clippy::needless_range_loop)]
use super::*;
use crate::export::test_data::random_splats;

/// Read accessor `idx` as f32 values (checks it is a tightly packed float accessor).
fn read_f32(g: &Glb, idx: u64) -> (String, usize, Vec<f32>) {
    let acc = &g.json["accessors"][idx as usize];
    assert_eq!(acc["componentType"], 5126, "accessor {idx} is not float");
    let ty = acc["type"].as_str().unwrap().to_string();
    let count = acc["count"].as_u64().unwrap() as usize;
    let view = &g.json["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
    let off = view["byteOffset"].as_u64().unwrap_or(0) as usize;
    let len = view["byteLength"].as_u64().unwrap() as usize;
    assert_eq!(off % 4, 0, "view offset alignment");
    let vals: Vec<f32> = g.bin[off..off + len]
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    (ty, count, vals)
}

#[test]
fn glb_parses_back_with_counts_types_and_extension() {
    let s = random_splats(37, 2, 11);
    let bytes = encode_glb(&s, &GlbOptions::default()).unwrap();
    // The file holds the splats rotated into glTF's y-up frame.
    let r = crate::export::rdf_to_rub(&s);
    assert_eq!(bytes.len() % 4, 0);
    assert_eq!(&bytes[..4], b"glTF");
    // JSON chunk padded with spaces.
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let json_end = 20 + json_len;
    let trimmed = String::from_utf8(bytes[20..json_end].to_vec()).unwrap();
    assert!(trimmed.trim_end().ends_with('}'));
    assert!(
        trimmed[trimmed.trim_end().len()..]
            .bytes()
            .all(|b| b == b' ')
    );

    let g = parse_glb(&bytes).unwrap();
    let j = &g.json;
    assert_eq!(j["asset"]["version"], "2.0");
    assert_eq!(j["extensionsUsed"], serde_json::json!([EXTENSION]));
    assert_eq!(
        j["buffers"][0]["byteLength"].as_u64().unwrap() as usize,
        g.bin.len()
    );
    let prim = &j["meshes"][0]["primitives"][0];
    assert_eq!(prim["mode"], 0); // POINTS
    let ext = &prim["extensions"][EXTENSION];
    assert_eq!(ext["kernel"], "ellipse");
    assert_eq!(ext["colorSpace"], "srgb_rec709_display");
    assert_eq!(ext["projection"], "perspective");
    assert_eq!(ext["sortingMethod"], "cameraDistance");
    assert_eq!(j["nodes"][0]["mesh"], 0);
    assert!(j["nodes"][0].get("rotation").is_none());

    let attrs = prim["attributes"].as_object().unwrap();
    // POSITION, COLOR_0, ROTATION, SCALE, OPACITY + 9 SH coefficients (degree 2).
    assert_eq!(attrs.len(), 5 + 9);
    let idx = |name: &str| attrs[name].as_u64().unwrap();

    let (ty, count, pos) = read_f32(&g, idx("POSITION"));
    assert_eq!((ty.as_str(), count), ("VEC3", 37));
    let acc = &j["accessors"][idx("POSITION") as usize];
    for a in 0..3 {
        let lo = r.means.iter().map(|m| m[a]).fold(f32::INFINITY, f32::min);
        let hi = r
            .means
            .iter()
            .map(|m| m[a])
            .fold(f32::NEG_INFINITY, f32::max);
        assert_eq!(acc["min"][a].as_f64().unwrap() as f32, lo);
        assert_eq!(acc["max"][a].as_f64().unwrap() as f32, hi);
    }
    assert_eq!(pos[3 * 5 + 1], -s.means[5][1]);

    let (ty, count, rot) = read_f32(&g, idx("KHR_gaussian_splatting:ROTATION"));
    assert_eq!((ty.as_str(), count), ("VEC4", 37));
    let q = normalized_wxyz(s.rotations[4]);
    assert_eq!(&rot[16..20], &[q[1], -q[2], -q[3], q[0]]); // x y z w, rotated
    let norm: f32 = rot[16..20].iter().map(|v| v * v).sum();
    assert!((norm - 1.0).abs() < 1e-5);

    let (ty, _, sc) = read_f32(&g, idx("KHR_gaussian_splatting:SCALE"));
    assert_eq!(ty, "VEC3");
    assert!(sc.iter().all(|&v| v > 0.0));
    assert_eq!(sc[7 * 3 + 2], s.log_scales[7][2].exp());

    let (ty, _, op) = read_f32(&g, idx("KHR_gaussian_splatting:OPACITY"));
    assert_eq!(ty, "SCALAR");
    assert!(op.iter().all(|&o| (0.0..=1.0).contains(&o)));
    assert!((op[9] - sigmoid(s.opacity_logits[9])).abs() < 1e-7);

    // SH: degree 2 coefficient 3 is the 8th coefficient overall (index 7).
    let (ty, count, sh) = read_f32(&g, idx("KHR_gaussian_splatting:SH_DEGREE_2_COEF_3"));
    assert_eq!((ty.as_str(), count), ("VEC3", 37));
    // That basis function is ∝ xz, odd in z: its sign flips with the axes.
    let k = 9;
    let o = 10 * k * 3 + 7 * 3;
    assert_eq!(
        &sh[3 * 10..3 * 10 + 3],
        &[-s.sh[o], -s.sh[o + 1], -s.sh[o + 2]]
    );
    assert!(!attrs.contains_key("KHR_gaussian_splatting:SH_DEGREE_3_COEF_0"));

    let color = &j["accessors"][idx("COLOR_0") as usize];
    assert_eq!(color["type"], "VEC4");
    assert_eq!(color["componentType"], 5121);
    assert_eq!(color["normalized"], true);
    // Colour of splat 2: linear(clamp(0.5 + C0·dc)), alpha = opacity.
    let off = j["bufferViews"][color["bufferView"].as_u64().unwrap() as usize]["byteOffset"]
        .as_u64()
        .unwrap() as usize;
    for c in 0..3 {
        let srgb = (0.5 + SH_C0 * s.sh[2 * k * 3 + c]).clamp(0.0, 1.0);
        assert_eq!(
            g.bin[off + 8 + c],
            (srgb_to_linear(srgb) * 255.0).round() as u8
        );
    }
    assert_eq!(
        g.bin[off + 8 + 3],
        (sigmoid(s.opacity_logits[2]) * 255.0).round() as u8
    );
}

#[test]
fn srgb_decoding_known_values() {
    assert_eq!(srgb_to_linear(0.0), 0.0);
    assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-6);
    assert!((srgb_to_linear(0.5) - 0.214_041).abs() < 1e-5);
    assert!((srgb_to_linear(0.04) - 0.04 / 12.92).abs() < 1e-7);
}

#[test]
fn glb_rejects_empty_and_bad_containers() {
    assert!(encode_glb(&Splats::default(), &GlbOptions::default()).is_err());
    let bytes = encode_glb(&random_splats(3, 0, 1), &GlbOptions::default()).unwrap();
    assert!(parse_glb(&bytes[..bytes.len() - 4]).is_err());
    let mut bad = bytes.clone();
    bad[0] = b'x';
    assert!(parse_glb(&bad).is_err());
}
