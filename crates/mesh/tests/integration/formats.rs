//! File formats: round trips, files as common exporters write them, malformed input.

use crate::common;

use std::io::Write;

use common::*;
use volmorph_mesh::{
    DVec3, Location, Mesh, MeshError, MeshFormat, MeshWriteOptions, read, read_bytes,
    read_obj_bytes, read_off_bytes, read_ply_bytes, read_stl_bytes, to_bytes, write, write_with,
};
use volmorph_testkit::Rng;

fn opts(binary: bool, big_endian: bool) -> MeshWriteOptions {
    MeshWriteOptions {
        binary,
        big_endian,
        single_precision: false,
    }
}

fn round_trip(m: &Mesh, format: MeshFormat, o: MeshWriteOptions) -> Mesh {
    let bytes = to_bytes(m, format, &o).unwrap();
    read_bytes(&bytes, format).unwrap()
}

/// A cube with f32-representable coordinates (what STL can store exactly).
fn f32_cube() -> Mesh {
    let mut c = cube();
    c.transform(|p| p * 0.25 + DVec3::new(3.5, -1.125, 1e6));
    c
}

#[test]
fn exact_round_trips_obj_off_ply() {
    let m = mixed();
    for (format, o) in [
        (MeshFormat::Obj, opts(false, false)),
        (MeshFormat::Off, opts(false, false)),
        (MeshFormat::Ply, opts(false, false)),
        (MeshFormat::Ply, opts(true, false)),
        (MeshFormat::Ply, opts(true, true)),
    ] {
        let back = round_trip(&m, format, o);
        assert_identical(&m, &back);
    }
}

#[test]
fn extreme_values_round_trip_in_text() {
    let p = vec![
        DVec3::new(f64::MAX, f64::MIN_POSITIVE, 5e-324),
        DVec3::new(-0.0, 1e-300, -1e300),
        DVec3::new(0.1 + 0.2, 1.0 / 3.0, 123_456_789.123_456_78),
    ];
    let m = Mesh::from_triangles(p, &[[0, 1, 2]]).unwrap();
    for format in [MeshFormat::Obj, MeshFormat::Off, MeshFormat::Ply] {
        for o in [opts(false, false), opts(true, true)] {
            assert_identical(&m, &round_trip(&m, format, o));
        }
    }
}

#[test]
fn non_finite_coordinates_are_data() {
    let p = vec![
        DVec3::new(f64::NAN, 0.0, 1.0),
        DVec3::new(f64::INFINITY, f64::NEG_INFINITY, 1.0),
        DVec3::ONE,
    ];
    let m = Mesh::from_triangles(p, &[[0, 1, 2]]).unwrap();
    for format in MeshFormat::ALL {
        for o in [opts(false, false), opts(true, false)] {
            let back = round_trip(&m, format, o);
            let q = back.positions();
            assert!(q[0].x.is_nan(), "{format}");
            assert_eq!(q[1].x, f64::INFINITY);
            assert_eq!(q[1].y, f64::NEG_INFINITY);
            assert_eq!(back.validate().non_finite_vertices.count, 2);
        }
    }
}

#[test]
fn ply_single_precision_rounds_to_f32() {
    let m = mixed();
    for o in [
        MeshWriteOptions {
            single_precision: true,
            ..opts(true, false)
        },
        MeshWriteOptions {
            single_precision: true,
            ..opts(false, false)
        },
    ] {
        let back = round_trip(&m, MeshFormat::Ply, o);
        let rounded: Vec<DVec3> = m
            .positions()
            .iter()
            .map(|p| p.as_vec3().as_dvec3())
            .collect();
        assert!(same_bits(back.positions(), &rounded));
        assert_eq!(faces_of(&back), faces_of(&m));
    }
}

#[test]
fn stl_round_trip_recovers_topology() {
    let c = f32_cube();
    for binary in [true, false] {
        let bytes = to_bytes(&c, MeshFormat::Stl, &opts(binary, false)).unwrap();
        if binary {
            assert_eq!(bytes.len(), 84 + 50 * 12);
            assert!(!bytes.starts_with(b"solid"));
        } else {
            assert!(bytes.starts_with(b"solid volmorph\n"));
        }
        let back = read_stl_bytes(&bytes).unwrap();
        assert_eq!(back.vertex_count(), 8, "exactly equal corners merged");
        assert_eq!(corner_bits(&back), corner_bits(&c.triangulated().unwrap()));
        let r = back.validate();
        assert!(r.is_closed_manifold(), "{r}");
        assert_eq!(r.euler_characteristic, 2);
        // Writing the re-read mesh again gives the same bytes.
        assert_eq!(
            to_bytes(&back, MeshFormat::Stl, &opts(binary, false)).unwrap(),
            bytes
        );
    }
}

#[test]
fn stl_rounds_to_f32_and_writes_unit_normals() {
    let m = mixed();
    let bytes = to_bytes(&m, MeshFormat::Stl, &opts(true, false)).unwrap();
    let back = read_stl_bytes(&bytes).unwrap();
    let expected: Vec<Vec<[u64; 3]>> = corner_bits(&m.triangulated().unwrap())
        .into_iter()
        .map(|f| {
            f.into_iter()
                .map(|c| c.map(|b| f64::from(f64::from_bits(b) as f32).to_bits()))
                .collect()
        })
        .collect();
    assert_eq!(corner_bits(&back), expected);
    // Facet normals of the cube's first triangle (bottom face): −z.
    let c = f32_cube();
    let bytes = to_bytes(&c, MeshFormat::Stl, &opts(true, false)).unwrap();
    let n: Vec<f32> = (0..3)
        .map(|k| f32::from_le_bytes(bytes[84 + 4 * k..88 + 4 * k].try_into().unwrap()))
        .collect();
    assert_eq!(n, vec![0.0, 0.0, -1.0]);
    let ascii =
        String::from_utf8(to_bytes(&c, MeshFormat::Stl, &opts(false, false)).unwrap()).unwrap();
    assert!(ascii.contains("facet normal 0 0 -1\n"), "{ascii}");
}

#[test]
fn files_by_extension_with_gzip() {
    use flate2::{Compression, write::GzEncoder};
    let dir = tempfile::tempdir().unwrap();
    let m = mixed();
    for (name, o) in [
        ("a.obj", opts(false, false)),
        ("a.OFF", opts(false, false)),
        ("a.ply", opts(true, false)),
        ("b.ply", opts(true, true)),
        ("c.ply", opts(false, false)),
    ] {
        let path = dir.path().join(name);
        write_with(&path, &m, &o).unwrap();
        assert_identical(&m, &read(&path).unwrap());
        // Same content gzip-compressed, named .gz or not.
        let raw = std::fs::read(&path).unwrap();
        let mut enc = GzEncoder::new(Vec::new(), Compression::fast());
        enc.write_all(&raw).unwrap();
        let gz = enc.finish().unwrap();
        let gz_path = dir.path().join(format!("{name}.gz"));
        std::fs::write(&gz_path, &gz).unwrap();
        assert_identical(&m, &read(&gz_path).unwrap());
        std::fs::write(&path, &gz).unwrap();
        assert_identical(&m, &read(&path).unwrap());
    }
    let stl = dir.path().join("d.stl");
    write(&stl, &f32_cube()).unwrap();
    assert_eq!(std::fs::read(&stl).unwrap().len(), 84 + 50 * 12);
    assert_eq!(read(&stl).unwrap().vertex_count(), 8);
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        11,
        "no temporary files left"
    );

    // Unknown extension, .gz output, missing file: errors naming the path.
    let e = write(&dir.path().join("x.vtk"), &m).unwrap_err();
    assert!(e.to_string().contains("x.vtk"), "{e}");
    // Output is never compressed: `.ply.gz` is refused as an extension not written, naming
    // the extension found and the ones written, and nothing is created.
    let e = write(&dir.path().join("x.ply.gz"), &m).unwrap_err();
    assert!(e.to_string().contains("x.ply.gz"), "{e}");
    assert!(
        e.to_string()
            .contains("extension .ply.gz is not written here; use .obj, .stl, .ply or .off"),
        "{e}"
    );
    assert!(!dir.path().join("x.ply.gz").exists());
    let e = read(&dir.path().join("missing.obj")).unwrap_err();
    assert!(e.to_string().contains("missing.obj"), "{e}");
    assert!(matches!(e, MeshError::Io(_)));
    assert_eq!(e.to_string().matches("missing.obj").count(), 1, "{e}");
    // Corrupt gzip stream.
    std::fs::write(dir.path().join("bad.ply.gz"), [0x1f, 0x8b, 8, 0, 1, 2, 3]).unwrap();
    assert!(read(&dir.path().join("bad.ply.gz")).is_err());
    // A parse error carries the path and the line.
    std::fs::write(dir.path().join("bad.obj"), "v 0 0 0\nf 1 2 3\n").unwrap();
    let e = read(&dir.path().join("bad.obj")).unwrap_err().to_string();
    assert!(e.contains("bad.obj") && e.contains("OBJ line 2"), "{e}");
}

/// Every format and encoding, written, then gzipped (as one member, and split in two members
/// at an odd place), reads through `read` and `read_with_colors` exactly as the uncompressed
/// file does, and a truncated file gives the same error either way.
#[test]
fn gzipped_files_read_like_uncompressed_ones() {
    use flate2::{Compression, write::GzEncoder};
    use volmorph_mesh::format::ply::{PlyEncoding, PlyProperties, PlyProperty, PlyValues};
    use volmorph_mesh::read_with_colors;
    let gzip = |bytes: &[u8], split: usize| {
        let mut out = Vec::new();
        for part in [&bytes[..split], &bytes[split..]] {
            let mut enc = GzEncoder::new(Vec::new(), Compression::fast());
            enc.write_all(part).unwrap();
            out.extend(enc.finish().unwrap());
        }
        out
    };
    let dir = tempfile::tempdir().unwrap();
    let m = mixed();
    let red: Vec<u8> = (0..m.vertex_count()).map(|i| (i * 29) as u8).collect();
    let colored = {
        let props = PlyProperties {
            vertex: ["red", "green", "blue"]
                .map(|name| PlyProperty {
                    name,
                    values: PlyValues::U8(&red),
                })
                .to_vec(),
            face: Vec::new(),
        };
        let mut b = Vec::new();
        volmorph_mesh::format::ply::write_ply_with_properties(
            &mut b,
            &m,
            PlyEncoding::BinaryBigEndian,
            false,
            &props,
        )
        .unwrap();
        b
    };
    let mut files: Vec<(String, Vec<u8>)> = vec![("colored.ply".into(), colored)];
    for format in MeshFormat::ALL {
        for (k, o) in [opts(false, false), opts(true, false), opts(true, true)]
            .into_iter()
            .enumerate()
        {
            let mesh = if format == MeshFormat::Stl {
                f32_cube()
            } else {
                m.clone()
            };
            let name = format!("m{k}.{}", format.extension());
            files.push((name, to_bytes(&mesh, format, &o).unwrap()));
        }
    }
    for (name, bytes) in &files {
        let plain = dir.path().join(name);
        std::fs::write(&plain, bytes).unwrap();
        let want = read(&plain).unwrap();
        let want_colors = read_with_colors(&plain).unwrap();
        assert_identical(
            &want,
            &read_bytes(bytes, MeshFormat::from_path(&plain).unwrap()).unwrap(),
        );
        for split in [0, 1, bytes.len() / 3, bytes.len()] {
            let gz = dir.path().join(format!("{name}.gz"));
            std::fs::write(&gz, gzip(bytes, split)).unwrap();
            assert_identical(&want, &read(&gz).unwrap());
            let (mesh, colors) = read_with_colors(&gz).unwrap();
            assert_identical(&want_colors.0, &mesh);
            assert_eq!(want_colors.1, colors, "{name}");
        }
        // A gzip file cut inside its trailer (the checksum after the data) is refused, as
        // when it was inflated whole before parsing.
        let gz = dir.path().join(format!("{name}.gz"));
        let whole = gzip(bytes, bytes.len());
        std::fs::write(&gz, &whole[..whole.len() - 3]).unwrap();
        let e = read(&gz).unwrap_err();
        assert!(
            matches!(&e, MeshError::Io(_)) && e.to_string().contains(&format!("{name}.gz")),
            "{name}: {e}"
        );
        // Truncated: the same error (naming each file) plain and gzipped (OBJ may read).
        let cut = &bytes[..bytes.len() * 2 / 3];
        std::fs::write(&plain, cut).unwrap();
        let gz = dir.path().join(format!("{name}.gz"));
        std::fs::write(&gz, gzip(cut, cut.len() / 2)).unwrap();
        let outcome = |p: &std::path::Path| match read(p) {
            Ok(m) => format!("{m:?}"),
            Err(e) => e.to_string().replacen(&p.display().to_string(), "FILE", 1),
        };
        let (o_plain, o_gz) = (outcome(&plain), outcome(&gz));
        assert_eq!(o_plain, o_gz, "{name}");
        assert!(
            o_plain.starts_with("FILE: ") || name.ends_with(".obj"),
            "{name}: {o_plain}"
        );
    }
}

#[test]
fn format_from_path() {
    use std::path::Path;
    let f = |s: &str| MeshFormat::from_path(Path::new(s)).ok();
    assert_eq!(f("dragon.ply.gz"), Some(MeshFormat::Ply));
    assert_eq!(f("/a/b.c/Bunny.OBJ"), Some(MeshFormat::Obj));
    assert_eq!(f("part.stl"), Some(MeshFormat::Stl));
    assert_eq!(f("m.off.GZ"), Some(MeshFormat::Off));
    assert_eq!(f("m.gz"), None);
    assert_eq!(f("ply"), None);
    assert_eq!(f("m.nii.gz"), None);
    for format in MeshFormat::ALL {
        assert_eq!(f(&format!("x.{}", format.extension())), Some(format));
    }
}

// ---------------------------------------------------------------- files from exporters

#[test]
fn blender_style_obj() {
    let text = "\
# Blender 4.1.1
# www.blender.org
mtllib untitled.mtl
o Cube
v 1.000000 1.000000 -1.000000
v 1.000000 -1.000000 -1.000000
v 1.000000 1.000000 1.000000
v 1.000000 -1.000000 1.000000 0.5 0.2 0.1
vn -0.0000 1.0000 -0.0000
vn -0.0000 -0.0000 1.0000
vt 0.625000 0.500000
vt 0.375000 0.500000
vt 0.625000 0.750000
vt 0.375000 0.750000
s 0
usemtl Material
f 1/1/1 3/3/1 4/4/1 2/2/1
g second   # trailing comment
l 1 2
f 1//2 -3//2 -1//2
f 3/1 4/2 1/3\r
f 1 2 3 4
vp 0.5
";
    let m = read_obj_bytes(text.as_bytes()).unwrap();
    assert_eq!(m.vertex_count(), 4);
    assert_eq!(m.positions()[3], DVec3::new(1.0, -1.0, 1.0));
    assert_eq!(
        faces_of(&m),
        vec![
            vec![0, 2, 3, 1],
            vec![0, 1, 3],
            vec![2, 3, 0],
            vec![0, 1, 2, 3]
        ]
    );
}

/// Little-endian binary PLY the way MeshLab/VCG writes it: float coordinates, normals,
/// colours, a `uchar int` face list followed by a face colour and a texcoord list, and an
/// extra `edge` element between vertices and faces.
fn meshlab_ply() -> Vec<u8> {
    let mut b = b"ply\r
format binary_little_endian 1.0\r
comment VCGLIB generated\r
obj_info some info\r
element vertex 4\r
property float x\r
property float y\r
property float z\r
property float nx\r
property float ny\r
property float nz\r
property uchar red\r
property uchar green\r
property uchar blue\r
property uchar alpha\r
property list uchar float extra\r
element edge 1\r
property int vertex1\r
property int vertex2\r
element face 2\r
property list uchar int vertex_indices\r
property uchar red\r
property list uchar float texcoord\r
end_header\r
"
    .to_vec();
    let pts = [
        [0.0f32, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.5],
        [0.0, 1.0, 0.25],
    ];
    for (k, p) in pts.iter().enumerate() {
        for x in p {
            b.extend_from_slice(&x.to_le_bytes());
        }
        for x in [0.0f32, 0.0, 1.0] {
            b.extend_from_slice(&x.to_le_bytes());
        }
        b.extend_from_slice(&[200, 100, 50, 255]);
        b.push(k as u8); // list of k floats
        for _ in 0..k {
            b.extend_from_slice(&7.5f32.to_le_bytes());
        }
    }
    b.extend_from_slice(&0i32.to_le_bytes());
    b.extend_from_slice(&2i32.to_le_bytes());
    for face in [[0i32, 1, 2], [0, 2, 3]] {
        b.push(3);
        for i in face {
            b.extend_from_slice(&i.to_le_bytes());
        }
        b.push(9);
        b.push(6);
        for t in [0.0f32, 0.0, 1.0, 0.0, 1.0, 1.0] {
            b.extend_from_slice(&t.to_le_bytes());
        }
    }
    b
}

#[test]
fn meshlab_style_binary_ply() {
    let m = read_ply_bytes(&meshlab_ply()).unwrap();
    assert_eq!(
        m.positions(),
        &[
            DVec3::ZERO,
            DVec3::X,
            DVec3::new(1.0, 1.0, 0.5),
            DVec3::new(0.0, 1.0, 0.25)
        ]
    );
    assert_eq!(faces_of(&m), vec![vec![0, 1, 2], vec![0, 2, 3]]);
    // Trailing bytes after the declared data are ignored.
    let mut extra = meshlab_ply();
    extra.extend_from_slice(b"\0\0\0");
    assert_eq!(read_ply_bytes(&extra).unwrap(), m);
}

#[test]
fn big_endian_ply_with_integer_coordinates_and_vertex_index() {
    let mut b = b"ply
format binary_big_endian 1.0
element vertex 3
property short x
property uint8 flags
property int16 y
property uchar z
property double confidence
element face 1
property list ushort uint vertex_index
end_header
"
    .to_vec();
    for (x, y, z) in [(-3i16, 7i16, 200u8), (4, -8, 0), (0, 1, 1)] {
        b.extend_from_slice(&x.to_be_bytes());
        b.push(0xff);
        b.extend_from_slice(&y.to_be_bytes());
        b.push(z);
        b.extend_from_slice(&0.5f64.to_be_bytes());
    }
    b.extend_from_slice(&3u16.to_be_bytes());
    for i in [2u32, 0, 1] {
        b.extend_from_slice(&i.to_be_bytes());
    }
    let m = read_ply_bytes(&b).unwrap();
    assert_eq!(
        m.positions(),
        &[
            DVec3::new(-3.0, 7.0, 200.0),
            DVec3::new(4.0, -8.0, 0.0),
            DVec3::new(0.0, 1.0, 1.0)
        ]
    );
    assert_eq!(faces_of(&m), vec![vec![2, 0, 1]]);
}

#[test]
fn ascii_ply_with_extras() {
    let text = "ply
format ascii 1.0
comment made by hand
obj_info nothing
element vertex 4
property float32 x
property float32 y
property float32 z
property list uint8 int32 neighbours
property uchar red
element face 2
property uchar flags
property list uchar int vertex_indices
property float quality
element material 1
property float shininess
end_header
0 0 0 2 1 3 255
1 0 0 0 0
0.1 1 0 1 2 12
0 1e0 -0.0 0 7
1 3 0 1 2 0.5
2 4 0 2 3 1 0.25
9.5
";
    let m = read_ply_bytes(text.as_bytes()).unwrap();
    assert_eq!(m.vertex_count(), 4);
    // float32 text is read to the nearest f32, like a binary float.
    assert_eq!(m.positions()[2].x, f64::from(0.1f32));
    assert!(m.positions()[3].z.is_sign_negative());
    assert_eq!(faces_of(&m), vec![vec![0, 1, 2], vec![0, 2, 3, 1]]);
    // Point cloud: no face element.
    let pc = "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\n\
              property double z\nend_header\n1 2 3\n4 5 6\n";
    let m = read_ply_bytes(pc.as_bytes()).unwrap();
    assert_eq!((m.vertex_count(), m.face_count()), (2, 0));
}

/// Binary STL whose 80-byte header starts with "solid", as SolidWorks and others write.
fn solid_header_binary_stl() -> Vec<u8> {
    let mut b = vec![b' '; 80];
    b[..31].copy_from_slice(b"solid part exported by some CAD");
    b.extend_from_slice(&2u32.to_le_bytes());
    let tris = [
        [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
    ];
    for t in tris {
        for x in [0.0f32, 0.0, 1.0] {
            b.extend_from_slice(&x.to_le_bytes());
        }
        for p in t {
            for x in p {
                b.extend_from_slice(&x.to_le_bytes());
            }
        }
        b.extend_from_slice(&0x7c00u16.to_le_bytes()); // colour attribute, ignored
    }
    b
}

#[test]
fn binary_stl_starting_with_solid() {
    let m = read_stl_bytes(&solid_header_binary_stl()).unwrap();
    assert_eq!(m.vertex_count(), 4);
    assert_eq!(faces_of(&m), vec![vec![0, 1, 2], vec![1, 3, 2]]);
    let r = m.validate();
    assert_eq!(
        (
            r.boundary_edges.count,
            r.boundary_loops,
            r.euler_characteristic
        ),
        (4, 1, 1)
    );
}

#[test]
fn ascii_stl_with_several_solids() {
    let text = "solid first one
  facet normal 0 0 1
    outer loop
      vertex 0 0 0
      vertex 1 0 0
      vertex 0 1 0
    endloop
  endfacet
endsolid first one
SOLID second
 FACET NORMAL nan nan nan
  OUTER LOOP
   VERTEX 1 0 0
   VERTEX 1 1 0
   VERTEX 0 1.0e0 0
   VERTEX -1 2 0
  ENDLOOP
 ENDFACET
ENDSOLID
";
    let m = read_stl_bytes(text.as_bytes()).unwrap();
    assert_eq!(m.vertex_count(), 5);
    assert_eq!(faces_of(&m), vec![vec![0, 1, 2], vec![1, 3, 2, 4]]);
    // Missing final endsolid is tolerated.
    let cut = &text[..text.len() - "ENDSOLID\n".len()];
    assert_eq!(read_stl_bytes(cut.as_bytes()).unwrap(), m);
}

#[test]
fn off_variants() {
    let coff = "COFF
# a comment
4 2 5
0 0 0 255 0 0 255
1 0 0 0 255 0 255   # trailing comment
1 1 0 0 0 255 255

0 1 0 1 1 1 1
3 0 1 2 255 0 0
3 0 2 3
";
    let m = read_off_bytes(coff.as_bytes()).unwrap();
    assert_eq!(m.vertex_count(), 4);
    assert_eq!(m.positions()[2], DVec3::new(1.0, 1.0, 0.0));
    assert_eq!(faces_of(&m), vec![vec![0, 1, 2], vec![0, 2, 3]]);
    let noff = "NOFF 3 1 0\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n";
    let m2 = read_off_bytes(noff.as_bytes()).unwrap();
    assert_eq!(faces_of(&m2), vec![vec![0, 1, 2]]);
    let headerless = "3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 2 1 0\n";
    assert_eq!(
        faces_of(&read_off_bytes(headerless.as_bytes()).unwrap()),
        vec![vec![2, 1, 0]]
    );
    let st = "STCNOFF\n3 1 0\n0 0 0 0 0 1 1 0 0 1 0.5 0.5\n1 0 0 0 0 1 1 0 0 1 0 0\n\
              0 1 0 0 0 1 1 0 0 1 1 1\n3 0 1 2\n";
    assert_eq!(read_off_bytes(st.as_bytes()).unwrap().vertex_count(), 3);
    for bad in ["4OFF\n1 0 0\n0 0 0 0\n", "nOFF\n4 1 0 0\n", "OFF BINARY\n"] {
        assert!(matches!(
            read_off_bytes(bad.as_bytes()),
            Err(MeshError::Unsupported(_))
        ));
    }
}

// ---------------------------------------------------------------- malformed input

fn parse_err(r: Result<Mesh, MeshError>) -> (MeshFormat, Location, String) {
    match r {
        Err(MeshError::Parse {
            format,
            location,
            message,
        }) => (format, location, message),
        other => panic!("expected a parse error, got {other:?}"),
    }
}

#[test]
fn malformed_obj() {
    let (_, loc, msg) = parse_err(read_obj_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n"));
    assert_eq!(loc, Location::Line(4));
    assert!(msg.contains("index 0"), "{msg}");
    // Positive indices are checked against all vertices in the file: 4 is defined later.
    let fwd = read_obj_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\nv 1 1 1\nv 2 2 2\n").unwrap();
    assert_eq!(faces_of(&fwd), vec![vec![0, 1, 3]]);
    let (_, loc, msg) = parse_err(read_obj_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"));
    assert_eq!(loc, Location::Line(4));
    assert!(
        msg.contains("index 9") && msg.contains("3 vertices"),
        "{msg}"
    );
    let (_, loc, msg) = parse_err(read_obj_bytes(b"v 0 0 0\nf -1 -2 -3\n"));
    assert_eq!(loc, Location::Line(2));
    assert!(msg.contains("relative index -2"), "{msg}");
    let (_, _, msg) = parse_err(read_obj_bytes(b"v 0 0 0\nv 1 1 1\nf 1 2\n"));
    assert!(msg.contains("2 vertices"), "{msg}");
    let (_, loc, msg) = parse_err(read_obj_bytes(b"\n\nv 0 zero 0\n"));
    assert_eq!(loc, Location::Line(3));
    assert!(msg.contains("'zero'"), "{msg}");
    let (_, _, msg) = parse_err(read_obj_bytes(b"v 0 0\n"));
    assert!(msg.contains("2 coordinates"), "{msg}");
    let (_, _, msg) = parse_err(read_obj_bytes(b"v 0 0 0\nf 1 a/2 1\n"));
    assert!(msg.contains("'a/2'"), "{msg}");
    let (_, _, msg) = parse_err(read_obj_bytes(b"v 0 0 0\nf 1 1 99999999999999999999\n"));
    assert!(msg.contains("99999999999999999999"), "{msg}");
    assert_eq!(read_obj_bytes(b"").unwrap(), Mesh::new());
}

#[test]
fn malformed_stl() {
    let good = to_bytes(&f32_cube(), MeshFormat::Stl, &opts(true, false)).unwrap();
    let (_, loc, msg) = parse_err(read_stl_bytes(&good[..good.len() - 7]));
    assert_eq!(loc, Location::Byte(80));
    assert!(
        msg.contains("12 triangles") && msg.contains("truncated"),
        "{msg}"
    );
    // Truncated binary STL whose header says "solid": the binary problem is reported.
    let sb = solid_header_binary_stl();
    let (_, _, msg) = parse_err(read_stl_bytes(&sb[..sb.len() - 1]));
    assert!(msg.contains("2 triangles"), "{msg}");
    let (_, _, msg) = parse_err(read_stl_bytes(b"hello"));
    assert!(msg.contains("too short"), "{msg}");
    // Absurd triangle count: refused before allocating.
    let mut absurd = good.clone();
    absurd[80..84].copy_from_slice(&u32::MAX.to_le_bytes());
    let (_, _, msg) = parse_err(read_stl_bytes(&absurd));
    assert!(msg.contains("4294967295 triangles"), "{msg}");
    let (_, loc, msg) = parse_err(read_stl_bytes(
        b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nendloop\nendfacet\n",
    ));
    assert_eq!(loc, Location::Line(6));
    assert!(msg.contains("2 vertices"), "{msg}");
    let (_, loc, msg) = parse_err(read_stl_bytes(
        b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 x 0\n",
    ));
    assert_eq!(loc, Location::Line(5));
    assert!(msg.contains("'x'"), "{msg}");
    let (_, _, msg) = parse_err(read_stl_bytes(b"solid x\nfacet normal 0 0 1\nouter loop\n"));
    assert!(msg.contains("ended"), "{msg}");
    let (_, _, msg) = parse_err(read_stl_bytes(b"solid x\n  facets\n"));
    assert!(msg.contains("'facets'"), "{msg}");
}

#[test]
fn malformed_ply_header() {
    let cases: &[(&str, usize, &str)] = &[
        ("plx\nformat ascii 1.0\nend_header\n", 1, "not a PLY file"),
        ("ply\nformat ascii 2.0\nend_header\n", 2, "version"),
        ("ply\nformat utf8 1.0\nend_header\n", 2, "unknown format"),
        (
            "ply\nformat ascii 1.0\nproperty float x\nend_header\n",
            3,
            "before any 'element'",
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n",
            4,
            "float128",
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex -5\nend_header\n",
            3,
            "'-5'",
        ),
        ("ply\nformat ascii 1.0\nelement vertex 1\n", 4, "end_header"),
        ("ply\nelement vertex 1\nend_header\n", 3, "no 'format'"),
        ("ply\nformat ascii 1.0\nfoo\nend_header\n", 3, "'foo'"),
        (
            "ply\nformat ascii 1.0\nelement vertex 0\nproperty list float int v\nend_header\n",
            4,
            "count type",
        ),
    ];
    for &(text, line, needle) in cases {
        let (format, loc, msg) = parse_err(read_ply_bytes(text.as_bytes()));
        assert_eq!(format, MeshFormat::Ply);
        assert_eq!(loc, Location::Line(line), "{text}: {msg}");
        assert!(msg.contains(needle), "{text}: {msg}");
    }
    let (_, _, msg) = parse_err(read_ply_bytes(
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n",
    ));
    assert!(msg.contains("no 'z'"), "{msg}");
    let e =
        read_ply_bytes(b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nend_header\n")
            .unwrap_err();
    assert_eq!(
        e.to_string(),
        "PLY header: vertex element has no 'y' property"
    );
    let (_, _, msg) = parse_err(read_ply_bytes(
        b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\n\
          element face 0\nproperty list uchar int corners\nend_header\n",
    ));
    assert!(msg.contains("vertex_indices"), "{msg}");
}

#[test]
fn malformed_ply_data() {
    let m = mixed();
    let le = to_bytes(&m, MeshFormat::Ply, &opts(true, false)).unwrap();
    let header_len = le.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    // Truncated inside the vertices (fixed-size element: refused up front).
    let (_, loc, msg) = parse_err(read_ply_bytes(&le[..header_len + 100]));
    assert_eq!(loc, Location::Byte(header_len));
    assert!(msg.contains("element 'vertex' declares 8 items"), "{msg}");
    // Truncated inside the faces.
    let (_, loc, msg) = parse_err(read_ply_bytes(&le[..le.len() - 3]));
    assert!(
        matches!(loc, Location::Byte(b) if b > header_len),
        "{loc:?}"
    );
    assert!(msg.contains("truncated"), "{msg}");
    // Absurd counts: no allocation, immediate error.
    let absurd = b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\n\
        property double x\nproperty double y\nproperty double z\nend_header\n\0\0\0\0";
    let (_, _, msg) = parse_err(read_ply_bytes(absurd));
    assert!(msg.contains("4000000000 items"), "{msg}");
    let beyond = b"ply\nformat ascii 1.0\nelement vertex 1000000000000\n\
        property double x\nproperty double y\nproperty double z\nend_header\n";
    assert!(matches!(
        read_ply_bytes(beyond),
        Err(MeshError::TooLarge(_))
    ));
    let absurd = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty uchar x\n\
        property uchar y\nproperty uchar z\nelement face 999999999999\n\
        property list uint int vertex_indices\nend_header\n\0\0\0\0\0\0\0\0\0\xff\xff\xff\xff";
    let (_, _, msg) = parse_err(read_ply_bytes(absurd));
    assert!(msg.contains("truncated"), "{msg}");
    let absurd = "ply\nformat ascii 1.0\nelement vertex 4294967295\nproperty float x\n\
        property float y\nproperty float z\nend_header\n1 2 3\n";
    let (_, loc, msg) = parse_err(read_ply_bytes(absurd.as_bytes()));
    assert_eq!(loc, Location::Line(9), "end of input, after the last line");
    assert!(msg.contains("vertex 1 of 4294967295"), "{msg}");
    // Bad indices and faces.
    let tri = |face: &str| {
        format!(
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
             property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\
             0 0 0\n1 0 0\n0 1 0\n{face}\n"
        )
    };
    assert!(read_ply_bytes(tri("3 0 1 2").as_bytes()).is_ok());
    let (_, loc, msg) = parse_err(read_ply_bytes(tri("3 0 1 3").as_bytes()));
    assert_eq!(loc, Location::Line(13));
    assert!(
        msg.contains("vertex 3") && msg.contains("3 vertices"),
        "{msg}"
    );
    let (_, _, msg) = parse_err(read_ply_bytes(tri("3 0 -1 2").as_bytes()));
    assert!(msg.contains("vertex -1"), "{msg}");
    let (_, _, msg) = parse_err(read_ply_bytes(tri("2 0 1").as_bytes()));
    assert!(msg.contains("2 vertices"), "{msg}");
    let (_, _, msg) = parse_err(read_ply_bytes(tri("3 0 1 two").as_bytes()));
    assert!(msg.contains("'two'"), "{msg}");
    let (_, _, msg) = parse_err(read_ply_bytes(tri("3 0 1").as_bytes()));
    assert!(msg.contains("data ends in face 0"), "{msg}");
    // Binary index out of range.
    let mut bad = le.clone();
    let n = bad.len();
    bad[n - 4..].copy_from_slice(&100i32.to_le_bytes());
    let (_, _, msg) = parse_err(read_ply_bytes(&bad));
    assert!(msg.contains("vertex 100"), "{msg}");
}

#[test]
fn malformed_off() {
    let (_, loc, msg) = parse_err(read_off_bytes(b"OFF\n3 1 0\n0 0 0\n1 0 0\n"));
    assert_eq!(loc, Location::Line(4));
    assert!(msg.contains("2 of the 3 declared vertices"), "{msg}");
    let (_, _, msg) = parse_err(read_off_bytes(
        b"OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
    ));
    assert!(msg.contains("1 of the 2 declared faces"), "{msg}");
    let (_, loc, msg) = parse_err(read_off_bytes(
        b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n",
    ));
    assert_eq!(loc, Location::Line(6));
    assert!(msg.contains("vertex 3"), "{msg}");
    let (_, _, msg) = parse_err(read_off_bytes(
        b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2\n",
    ));
    assert!(msg.contains("declares 4 vertices but lists 3"), "{msg}");
    let (_, _, msg) = parse_err(read_off_bytes(b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n"));
    assert!(msg.contains("2 vertices"), "{msg}");
    let (_, _, msg) = parse_err(read_off_bytes(b"OFF\n3 x 0\n"));
    assert!(msg.contains("bad face count 'x'"), "{msg}");
    let (_, _, msg) = parse_err(read_off_bytes(b"OFF\n"));
    assert!(msg.contains("counts"), "{msg}");
    let (_, _, msg) = parse_err(read_off_bytes(b"XOFF\n1 0 0\n0 0 0\n"));
    assert!(msg.contains("XOFF"), "{msg}");
    let (_, _, msg) = parse_err(read_off_bytes(b"OFF\n1 0 0\n0 0 nope\n"));
    assert!(msg.contains("'nope'"), "{msg}");
    // Absurd counts are bounded by the data, not allocated.
    let (_, _, msg) = parse_err(read_off_bytes(b"OFF\n4294967295 999999999999 0\n0 0 0\n"));
    assert!(msg.contains("1 of the 4294967295"), "{msg}");
    assert!(matches!(
        read_off_bytes(b"OFF\n999999999999999 1 0\n"),
        Err(MeshError::TooLarge(_))
    ));
}

#[test]
fn truncated_and_mutated_inputs_never_panic() {
    let m = mixed();
    let mut samples: Vec<(MeshFormat, Vec<u8>)> = Vec::new();
    for format in MeshFormat::ALL {
        for o in [opts(false, false), opts(true, false), opts(true, true)] {
            samples.push((format, to_bytes(&m, format, &o).unwrap()));
        }
    }
    samples.push((MeshFormat::Ply, meshlab_ply()));
    samples.push((MeshFormat::Stl, solid_header_binary_stl()));
    let mut rng = Rng::new(0x9e37_79b9_7f4a_7c15);
    for (format, bytes) in &samples {
        for cut in 0..bytes.len() {
            let _ = read_bytes(&bytes[..cut], *format);
        }
        for _ in 0..300 {
            let mut b = bytes.clone();
            for _ in 0..1 + rng.index(4) {
                let i = rng.index(b.len());
                b[i] = match rng.index(4) {
                    0 => rng.next_u64() as u8,
                    1 => b'9',
                    2 => 0xff,
                    _ => b' ',
                };
            }
            if let Ok(mesh) = read_bytes(&b, *format) {
                // Whatever a reader accepts is structurally valid.
                let r = mesh.validate();
                assert!(r.out_of_range_faces.is_empty() && r.small_faces.is_empty());
            }
        }
    }
}

#[test]
fn ply_extra_properties_are_declared_written_and_skipped_by_the_reader() {
    use volmorph_mesh::format::ply::{
        PlyEncoding, PlyProperties, PlyProperty, PlyValues, write_ply_with_properties,
    };
    let m = Mesh::from_triangles(
        vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(0.0, 1.0, 0.5),
        ],
        &[[0, 1, 2]],
    )
    .unwrap();
    let red = [255u8, 0, 7];
    let temp = [1.5f32, -2.25, 3.0];
    let par = [0.125f64, 0.5, 1.0];
    let area = [0.75f32];
    let extra = PlyProperties {
        vertex: vec![
            PlyProperty {
                name: "u",
                values: PlyValues::F64(&par),
            },
            PlyProperty {
                name: "temperature",
                values: PlyValues::F32(&temp),
            },
            PlyProperty {
                name: "red",
                values: PlyValues::U8(&red),
            },
        ],
        face: vec![PlyProperty {
            name: "mean",
            values: PlyValues::F32(&area),
        }],
    };
    for enc in [
        PlyEncoding::Ascii,
        PlyEncoding::BinaryLittleEndian,
        PlyEncoding::BinaryBigEndian,
    ] {
        let mut out = Vec::new();
        write_ply_with_properties(&mut out, &m, enc, false, &extra).unwrap();
        let text = String::from_utf8_lossy(&out);
        let header = &text[..text.find("end_header").unwrap()];
        assert!(header.contains(
            "property double z\nproperty double u\nproperty float temperature\nproperty uchar red\nelement face 1\n"
        ));
        assert!(header.contains("vertex_indices\nproperty float mean\n"));
        let back = volmorph_mesh::read_ply_bytes(&out).unwrap();
        assert_eq!(back, m);
        if enc == PlyEncoding::Ascii {
            assert!(text.contains("\n1 0 0 0.5 -2.25 0\n"), "{text}");
            assert!(text.contains("\n3 0 1 2 0.75\n"), "{text}");
        } else {
            // 3 vertices × (3·8 + 8 + 4 + 1) bytes + face (1 + 3·4 + 4) bytes after the header.
            let body = out.len() - (text.find("end_header\n").unwrap() + 11);
            assert_eq!(body, 3 * 37 + 17);
        }
    }
    // Wrong counts and bad names are refused before writing.
    let bad_len = PlyProperties {
        vertex: vec![PlyProperty {
            name: "t",
            values: PlyValues::F32(&area),
        }],
        face: Vec::new(),
    };
    for bad in [
        bad_len,
        PlyProperties {
            vertex: vec![PlyProperty {
                name: "x",
                values: PlyValues::F32(&temp),
            }],
            face: Vec::new(),
        },
        PlyProperties {
            vertex: vec![PlyProperty {
                name: "two words",
                values: PlyValues::F32(&temp),
            }],
            face: Vec::new(),
        },
    ] {
        let mut out = Vec::new();
        let e = write_ply_with_properties(&mut out, &m, PlyEncoding::Ascii, false, &bad);
        assert!(matches!(e, Err(MeshError::InvalidProperty(_))));
        assert!(out.is_empty());
    }
}

#[test]
fn obj_vertex_colours_are_written_in_unit_range_and_read_back() {
    let m = Mesh::from_triangles(vec![DVec3::ZERO, DVec3::X, DVec3::Y], &[[0, 1, 2]]).unwrap();
    let mut out = Vec::new();
    volmorph_mesh::format::obj::write_obj_with_colors(
        &mut out,
        &m,
        &[[255, 0, 51], [0; 3], [1; 3]],
    )
    .unwrap();
    let text = String::from_utf8(out.clone()).unwrap();
    assert!(text.contains("v 0 0 0 1 0 0.2\n"), "{text}");
    assert_eq!(volmorph_mesh::read_obj_bytes(&out).unwrap(), m);
    let mut out = Vec::new();
    let e = volmorph_mesh::format::obj::write_obj_with_colors(&mut out, &m, &[[0; 3]]);
    assert!(matches!(e, Err(MeshError::InvalidProperty(_))));
}
