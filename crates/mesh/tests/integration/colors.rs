//! Colours stored with meshes: PLY `red green blue` per vertex or per face in every encoding
//! and channel type, OBJ `v x y z r g b`, read back by `read_with_colors`.

use volmorph_mesh::format::obj::{read_obj_bytes_with_colors, write_obj_with_colors};
use volmorph_mesh::format::ply::{
    PlyEncoding, PlyProperties, PlyProperty, PlyValues, write_ply_with_properties,
};
use volmorph_mesh::{Mesh, shapes};
use volmorph_mesh::{MeshColors, read_ply_bytes, read_ply_bytes_with_colors, read_with_colors};

fn mesh() -> Mesh {
    shapes::icosphere(1, 1.0, volmorph_mesh::DVec3::ZERO).unwrap()
}

fn vertex_colors(m: &Mesh) -> Vec<[u8; 3]> {
    (0..m.vertex_count())
        .map(|i| {
            [
                (i * 37 % 256) as u8,
                (i * 91 % 256) as u8,
                (255 - i % 256) as u8,
            ]
        })
        .collect()
}

fn channels(c: &[[u8; 3]]) -> [Vec<u8>; 3] {
    [0, 1, 2].map(|k| c.iter().map(|c| c[k]).collect())
}

fn ply(m: &Mesh, encoding: PlyEncoding, props: &PlyProperties<'_>) -> Vec<u8> {
    let mut out = Vec::new();
    write_ply_with_properties(&mut out, m, encoding, false, props).unwrap();
    out
}

const ENCODINGS: [PlyEncoding; 3] = [
    PlyEncoding::Ascii,
    PlyEncoding::BinaryLittleEndian,
    PlyEncoding::BinaryBigEndian,
];

#[test]
fn ply_vertex_colours_round_trip_in_every_encoding() {
    let m = mesh();
    let c = vertex_colors(&m);
    let [r, g, b] = channels(&c);
    // A float attribute before the colours, as `nurbs slice` writes it.
    let attr: Vec<f32> = (0..m.vertex_count()).map(|i| i as f32 * 0.5).collect();
    let props = PlyProperties {
        vertex: vec![
            PlyProperty {
                name: "density",
                values: PlyValues::F32(&attr),
            },
            PlyProperty {
                name: "red",
                values: PlyValues::U8(&r),
            },
            PlyProperty {
                name: "green",
                values: PlyValues::U8(&g),
            },
            PlyProperty {
                name: "blue",
                values: PlyValues::U8(&b),
            },
        ],
        face: vec![],
    };
    for enc in ENCODINGS {
        let bytes = ply(&m, enc, &props);
        let (read, colors) = read_ply_bytes_with_colors(&bytes).unwrap();
        assert_eq!(read, m, "{enc:?}");
        assert_eq!(colors, Some(MeshColors::PerVertex(c.clone())), "{enc:?}");
        assert_eq!(read_ply_bytes(&bytes).unwrap(), m);
    }
}

#[test]
fn ply_face_colours_and_float_channels() {
    let m = mesh();
    let n = m.face_count();
    let r: Vec<u8> = (0..n).map(|f| (f * 13 % 256) as u8).collect();
    let g = vec![7u8; n];
    let b: Vec<u8> = (0..n).map(|f| (255 - f % 256) as u8).collect();
    let props = PlyProperties {
        vertex: vec![],
        face: vec![
            PlyProperty {
                name: "red",
                values: PlyValues::U8(&r),
            },
            PlyProperty {
                name: "green",
                values: PlyValues::U8(&g),
            },
            PlyProperty {
                name: "blue",
                values: PlyValues::U8(&b),
            },
        ],
    };
    let want: Vec<[u8; 3]> = (0..n).map(|f| [r[f], g[f], b[f]]).collect();
    for enc in ENCODINGS {
        let (read, colors) = read_ply_bytes_with_colors(&ply(&m, enc, &props)).unwrap();
        assert_eq!(read, m);
        let colors = colors.unwrap();
        colors.check(&read).unwrap();
        assert_eq!(colors, MeshColors::PerFace(want.clone()), "{enc:?}");
    }
    // Float channels in [0, 1] (also named r g b) scale to 8 bits; out-of-range values clamp.
    let nv = m.vertex_count();
    let fr: Vec<f32> = (0..nv).map(|i| i as f32 / (nv - 1) as f32).collect();
    let fg = vec![0.5f32; nv];
    let fb = vec![2.0f32; nv];
    let props = PlyProperties {
        vertex: vec![
            PlyProperty {
                name: "r",
                values: PlyValues::F32(&fr),
            },
            PlyProperty {
                name: "g",
                values: PlyValues::F32(&fg),
            },
            PlyProperty {
                name: "b",
                values: PlyValues::F32(&fb),
            },
        ],
        face: vec![],
    };
    let (_, colors) = read_ply_bytes_with_colors(&ply(&m, PlyEncoding::Ascii, &props)).unwrap();
    let Some(MeshColors::PerVertex(c)) = colors else {
        panic!("vertex colours expected");
    };
    assert_eq!(c[0], [0, 128, 255]);
    assert_eq!(c[nv - 1], [255, 128, 255]);
    // A mesh without colour properties has none; a wrong count is reported.
    let (_, none) =
        read_ply_bytes_with_colors(&ply(&m, PlyEncoding::Ascii, &PlyProperties::default()))
            .unwrap();
    assert_eq!(none, None);
    assert!(MeshColors::PerFace(vec![[0; 3]; 3]).check(&m).is_err());
}

#[test]
fn ply_non_finite_colour_is_an_error() {
    let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                property float z\nproperty float red\nproperty float green\nproperty float blue\n\
                element face 1\nproperty list uchar int vertex_indices\nend_header\n\
                0 0 0 1 0 0\n1 0 0 nan 0 0\n0 1 0 1 0 0\n3 0 1 2\n";
    let e = read_ply_bytes_with_colors(text.as_bytes())
        .unwrap_err()
        .to_string();
    assert!(e.contains("colour"), "{e}");
    // The geometry-only reader skips colours as before.
    assert_eq!(read_ply_bytes(text.as_bytes()).unwrap().vertex_count(), 3);
}

#[test]
fn obj_vertex_colours_and_files() {
    let m = mesh();
    let c = vertex_colors(&m);
    let mut text = Vec::new();
    write_obj_with_colors(&mut text, &m, &c).unwrap();
    let (read, colors) = read_obj_bytes_with_colors(&text).unwrap();
    assert_eq!(read, m);
    assert_eq!(colors, Some(c.clone()));
    // One vertex without colour: no colours at all.
    let partial = "v 0 0 0 1 0 0\nv 1 0 0\nv 0 1 0 0 0 1\nf 1 2 3\n";
    assert_eq!(
        read_obj_bytes_with_colors(partial.as_bytes()).unwrap().1,
        None
    );
    // `v x y z w` is a weight, not a colour.
    let w = "v 0 0 0 1\nv 1 0 0 1\nv 0 1 0 1\nf 1 2 3\n";
    assert_eq!(read_obj_bytes_with_colors(w.as_bytes()).unwrap().1, None);

    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("c.obj");
    std::fs::write(&obj, &text).unwrap();
    let (_, colors) = read_with_colors(&obj).unwrap();
    assert_eq!(colors, Some(MeshColors::PerVertex(c.clone())));
    let [r, g, b] = channels(&c);
    let props = PlyProperties {
        vertex: vec![
            PlyProperty {
                name: "red",
                values: PlyValues::U8(&r),
            },
            PlyProperty {
                name: "green",
                values: PlyValues::U8(&g),
            },
            PlyProperty {
                name: "blue",
                values: PlyValues::U8(&b),
            },
        ],
        face: vec![],
    };
    let p = dir.path().join("c.ply");
    std::fs::write(&p, ply(&m, PlyEncoding::BinaryLittleEndian, &props)).unwrap();
    let (read, colors) = read_with_colors(&p).unwrap();
    assert_eq!(read, m);
    assert_eq!(colors, Some(MeshColors::PerVertex(c)));
    let stl = dir.path().join("c.stl");
    volmorph_mesh::write(&stl, &m).unwrap();
    assert_eq!(read_with_colors(&stl).unwrap().1, None);
}
