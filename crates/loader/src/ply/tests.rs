//! Tests for the splat PLY reader/writer.

use super::*;

/// Deterministic splats with distinct values everywhere.
pub fn sample(n: usize, deg: u32) -> PlySplats {
    let r = rest_len(deg);
    let f = |i: usize, k: usize| (i * 131 + k * 7) as f32 * 0.001 - 0.5;
    PlySplats {
        means: (0..n).map(|i| [f(i, 0), f(i, 1), f(i, 2)]).collect(),
        normals: None,
        f_dc: (0..n).map(|i| [f(i, 3), f(i, 4), f(i, 5)]).collect(),
        f_rest: (0..n * r)
            .map(|j| f(j / r.max(1), 6 + j % r.max(1)))
            .collect(),
        opacities: (0..n).map(|i| f(i, 60)).collect(),
        scales: (0..n).map(|i| [f(i, 61), f(i, 62), f(i, 63)]).collect(),
        rotations: (0..n)
            .map(|i| [1.0, f(i, 64), f(i, 65), f(i, 66)])
            .collect(),
        sh_degree: deg,
    }
}

#[test]
fn binary_round_trip_all_degrees() {
    let dir = tempfile::tempdir().unwrap();
    for deg in 0..=3 {
        let p = dir.path().join(format!("s{deg}.ply"));
        let s = sample(37, deg);
        write_ply(&p, &s).unwrap();
        let r = read_ply(&p).unwrap();
        assert_eq!(r.sh_degree, deg);
        assert_eq!(r.normals, Some(vec![[0.0; 3]; 37]));
        let mut r2 = r.clone();
        r2.normals = None;
        assert_eq!(r2, s);
        // Re-writing gives identical bytes.
        let p2 = dir.path().join("again.ply");
        write_ply(&p2, &r).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), std::fs::read(&p2).unwrap());
    }
}

#[test]
fn layout_matches_inria() {
    let s = sample(2, 3);
    let bytes = encode_ply(&s, Path::new("x.ply")).unwrap();
    let text = String::from_utf8_lossy(
        &bytes[..bytes.windows(10).position(|w| w == b"end_header").unwrap()],
    )
    .to_string();
    let props: Vec<&str> = text
        .lines()
        .filter_map(|l| l.strip_prefix("property float "))
        .collect();
    assert_eq!(props.len(), 62);
    assert_eq!(
        &props[..9],
        &[
            "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"
        ]
    );
    assert_eq!(props[9], "f_rest_0");
    assert_eq!(props[53], "f_rest_44");
    assert_eq!(
        &props[54..],
        &[
            "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"
        ]
    );
    assert_eq!(
        bytes.len() - (text.len() + "end_header\n".len()),
        2 * 62 * 4
    );
}

fn ascii_ply(values: &[&str]) -> String {
    let names = property_names(0);
    let mut s = format!(
        "ply\nformat ascii 1.0\ncomment made by hand\nelement vertex {}\n",
        values.len()
    );
    for n in &names {
        s.push_str(&format!("property float {n}\n"));
    }
    s.push_str("end_header\n");
    for v in values {
        s.push_str(v);
        s.push('\n');
    }
    s
}

#[test]
fn ascii_and_big_endian_read() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("a.ply");
    std::fs::write(
        &p,
        ascii_ply(&["1 2 3 0 0 1 0.5 0.25 0.125 -2 -1 -1.5 -0.5 1 0 0 0"]),
    )
    .unwrap();
    let s = read_ply(&p).unwrap();
    assert_eq!(s.sh_degree, 0);
    assert_eq!(s.means, vec![[1.0, 2.0, 3.0]]);
    assert_eq!(s.normals, Some(vec![[0.0, 0.0, 1.0]]));
    assert_eq!(s.f_dc, vec![[0.5, 0.25, 0.125]]);
    assert_eq!(s.opacities, vec![-2.0]);
    assert_eq!(s.scales, vec![[-1.0, -1.5, -0.5]]);
    assert_eq!(s.rotations, vec![[1.0, 0.0, 0.0, 0.0]]);

    // Big-endian, doubles for positions, properties in another order, an
    // extra uchar property and a face element (with a list) before vertex.
    let mut b = b"ply\nformat binary_big_endian 1.0\nelement face 1\nproperty list uchar int vertex_indices\nelement vertex 1\nproperty double x\nproperty double y\nproperty double z\nproperty uchar red\n".to_vec();
    for n in [
        "opacity", "f_dc_0", "f_dc_1", "f_dc_2", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1",
        "rot_2", "rot_3",
    ] {
        b.extend_from_slice(format!("property float {n}\n").as_bytes());
    }
    b.extend_from_slice(b"end_header\n");
    b.push(2);
    b.extend_from_slice(&7i32.to_be_bytes());
    b.extend_from_slice(&8i32.to_be_bytes());
    for v in [1.5f64, -2.0, 4.0] {
        b.extend_from_slice(&v.to_be_bytes());
    }
    b.push(200);
    for v in [0.3f32, 0.1, 0.2, 0.3, -1.0, -2.0, -3.0, 0.5, 0.5, 0.5, 0.5] {
        b.extend_from_slice(&v.to_be_bytes());
    }
    let p = dir.path().join("be.ply");
    std::fs::write(&p, &b).unwrap();
    let s = read_ply(&p).unwrap();
    assert_eq!(s.means, vec![[1.5, -2.0, 4.0]]);
    assert_eq!(s.opacities, vec![0.3]);
    assert_eq!(s.scales, vec![[-1.0, -2.0, -3.0]]);
    assert_eq!(s.normals, None);
}

#[test]
fn errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.ply");
    let check = |bytes: &[u8], want: &str| {
        std::fs::write(&p, bytes).unwrap();
        let e = read_ply(&p).unwrap_err().to_string();
        assert!(
            e.contains("bad.ply") && e.contains(want),
            "{e} (wanted {want})"
        );
    };
    check(b"PLY\nformat ascii 1.0\n", "not a PLY");
    check(
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n",
        "no end_header",
    );
    check(b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nend_header\n\0\0\0\0", "missing property 'y'");
    check(b"ply\nformat weird 1.0\nend_header\n", "unknown format");
    check(
        ascii_ply(&["1 2 3 0 0 1 0.5 0.25 0.125 nan -1 -1.5 -0.5 1 0 0 0"]).as_bytes(),
        "opacity is NaN",
    );
    check(
        ascii_ply(&["1 2 inf 0 0 1 0.5 0.25 0.125 0 -1 -1.5 -0.5 1 0 0 0"]).as_bytes(),
        "property z is inf",
    );
    check(ascii_ply(&["1 2 3 0 0 1"]).as_bytes(), "truncated");
    let good = encode_ply(&sample(10, 1), &p).unwrap();
    check(&good[..good.len() - 3], "truncated");
    // A rest count that is no SH degree.
    let text = String::from_utf8_lossy(&good).replace("property float f_rest_8\n", "");
    let cut = text.find("end_header\n").unwrap() + 11;
    check(&text.as_bytes()[..cut], "8 f_rest properties");
    // Writing NaN fails too, naming the output.
    let mut s = sample(3, 0);
    s.scales[2][1] = f32::NAN;
    let e = write_ply(dir.path().join("out.ply"), &s)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("out.ply") && e.contains("splat 2") && e.contains("scale_1"),
        "{e}"
    );
    assert!(!dir.path().join("out.ply").exists());
}

#[test]
fn point_cloud_ply_is_readable_header() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("pts.ply");
    write_points_ply(
        &p,
        &[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]],
        &[[255, 0, 0], [0, 255, 0]],
    )
    .unwrap();
    let b = std::fs::read(&p).unwrap();
    let h = b.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    assert_eq!(b.len() - h, 2 * 15);
    assert_eq!(&b[h + 12..h + 15], &[255, 0, 0]);
    assert_eq!(
        f32::from_le_bytes(b[h + 15..h + 19].try_into().unwrap()),
        4.0
    );
}

/// Headers that claim far more data than the file holds give an error, and
/// nothing is allocated for the claimed count (allocating for a 10^12-vertex
/// ASCII header would ask for 248 TB and abort).
#[test]
fn huge_header_counts_are_bounded_by_the_file() {
    let one = "1 2 3 0 0 1 0.5 0.25 0.125 0 -1 -1.5 -0.5 1 0 0 0";
    let ascii = ascii_ply(&[one]).replace("element vertex 1\n", "element vertex 1000000000000\n");
    let e = read_ply_bytes(ascii.as_bytes(), Path::new("huge.ply"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("huge.ply") && e.contains("truncated"), "{e}");
    let good = encode_ply(&sample(2, 0), Path::new("x.ply")).unwrap();
    let text = String::from_utf8_lossy(&good).replace(
        "element vertex 2\n",
        "element vertex 18446744073709551615\n",
    );
    let e = read_ply_bytes(text.as_bytes(), Path::new("huge.ply"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("huge.ply") && e.contains("truncated"), "{e}");
    // A property-less element with an absurd count before the vertices.
    let skip = ascii_ply(&[one]).replace(
        "element vertex 1\n",
        "element junk 18446744073709551615\nelement vertex 1\n",
    );
    assert_eq!(
        read_ply_bytes(skip.as_bytes(), Path::new("s.ply"))
            .unwrap()
            .len(),
        1
    );
}
