//! Property tests: random polygon meshes survive every format bit for bit.

use crate::common;

use common::*;
use proptest::prelude::*;
use volmorph_mesh::{DVec3, Mesh, MeshFormat, MeshWriteOptions, read_bytes, to_bytes};

fn finite_f64() -> impl Strategy<Value = f64> + Clone {
    prop_oneof![
        any::<f64>().prop_filter("finite", |x| x.is_finite()),
        -1e3..1e3f64,
        Just(0.0),
        Just(-0.0),
    ]
}

/// Random mesh: 1–30 positions, 0–20 faces of 3–7 vertices (indices may repeat: formats must
/// carry whatever the mesh holds).
fn mesh_with(coord: impl Strategy<Value = f64> + Clone) -> impl Strategy<Value = Mesh> {
    prop::collection::vec((coord.clone(), coord.clone(), coord), 1..30).prop_flat_map(|pts| {
        let n = pts.len() as u32;
        let positions: Vec<DVec3> = pts
            .into_iter()
            .map(|(x, y, z)| DVec3::new(x, y, z))
            .collect();
        prop::collection::vec(prop::collection::vec(0..n, 3..8), 0..20).prop_map(move |faces| {
            Mesh::from_polygons(positions.clone(), faces).expect("indices are in range")
        })
    })
}

const ENCODINGS: [(bool, bool); 3] = [(false, false), (true, false), (true, true)];

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn exact_formats_round_trip(m in mesh_with(finite_f64())) {
        for format in [MeshFormat::Obj, MeshFormat::Off, MeshFormat::Ply] {
            for (binary, big_endian) in ENCODINGS {
                let o = MeshWriteOptions { binary, big_endian, single_precision: false };
                let bytes = to_bytes(&m, format, &o).unwrap();
                let back = read_bytes(&bytes, format).unwrap();
                prop_assert!(same_bits(m.positions(), back.positions()), "{format} {o:?}");
                prop_assert_eq!(faces_of(&m), faces_of(&back));
            }
        }
    }

    #[test]
    fn stl_round_trips_f32_geometry(
        m in mesh_with(any::<f32>()
            .prop_filter("finite", |x| x.is_finite())
            .prop_map(|x| f64::from(x) + 0.0))
    ) {
        let expected = corner_bits(&m.triangulated().unwrap());
        for binary in [true, false] {
            let o = MeshWriteOptions { binary, ..MeshWriteOptions::default() };
            let bytes = to_bytes(&m, MeshFormat::Stl, &o).unwrap();
            let back = read_bytes(&bytes, MeshFormat::Stl).unwrap();
            prop_assert!(back.is_triangle_mesh());
            prop_assert_eq!(corner_bits(&back), expected.clone(), "binary {}", binary);
            // Exactly equal corners are merged: no two vertices share a position.
            let mut merged = back.clone();
            merged.merge_duplicate_vertices(0.0);
            prop_assert_eq!(merged.vertex_count(), back.vertex_count());
        }
    }

    #[test]
    fn merging_keeps_corner_geometry(m in mesh_with(prop_oneof![Just(0.0), Just(1.0), -2.0..2.0f64])) {
        let mut merged = m.clone();
        let remap = merged.merge_duplicate_vertices(0.0);
        prop_assert_eq!(remap.len(), m.vertex_count());
        prop_assert_eq!(corner_bits(&merged), corner_bits(&m));
        // Merging is idempotent: no two remaining vertices share a position.
        let mut again = merged.clone();
        let second = again.merge_duplicate_vertices(0.0);
        prop_assert_eq!(again.vertex_count(), merged.vertex_count());
        prop_assert!(second.iter().enumerate().all(|(i, &j)| i as u32 == j));
    }

    #[test]
    fn triangulation_preserves_face_normal_vectors(
        m in mesh_with(-2.0..2.0f64)
    ) {
        let (t, source) = m.triangulated_with_source().unwrap();
        let mut sums = vec![DVec3::ZERO; m.face_count()];
        for (k, &f) in source.iter().enumerate() {
            sums[f as usize] += t.face_normal_vector(k).unwrap();
        }
        for (f, s) in sums.iter().enumerate() {
            let n = m.face_normal_vector(f).unwrap();
            prop_assert!((*s - n).length() <= 1e-12 * (1.0 + n.length()), "face {}: {} vs {}", f, s, n);
        }
        prop_assert!((t.signed_volume() - m.signed_volume()).abs() <= 1e-12 * (1.0 + m.signed_volume().abs()));
    }
}

/// Arbitrary bytes after a plausible start: readers return errors or valid meshes, never
/// panic.
fn hostile() -> impl Strategy<Value = (MeshFormat, Vec<u8>)> {
    let prefixes: [(MeshFormat, &'static [u8]); 8] = [
        (MeshFormat::Obj, b"v 0 0 0\nv 1 0 0\nv 0 1 0\n"),
        (MeshFormat::Off, b"OFF\n3 1 0\n"),
        (MeshFormat::Ply, b"ply\nformat ascii 1.0\n"),
        (
            MeshFormat::Ply,
            b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\n\
              property float y\nproperty float z\nelement face 1\n\
              property list uchar int vertex_indices\nend_header\n",
        ),
        (
            MeshFormat::Ply,
            b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty list int int x\n",
        ),
        (
            MeshFormat::Stl,
            b"solid s\nfacet normal 0 0 1\nouter loop\n",
        ),
        (MeshFormat::Stl, b""),
        (MeshFormat::Obj, b""),
    ];
    (
        0..prefixes.len(),
        prop::collection::vec(any::<u8>(), 0..400),
    )
        .prop_map(move |(k, tail)| {
            let (format, prefix) = prefixes[k];
            let mut bytes = prefix.to_vec();
            bytes.extend(tail);
            (format, bytes)
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn readers_survive_hostile_bytes((format, bytes) in hostile()) {
        if let Ok(m) = read_bytes(&bytes, format) {
            let r = m.validate();
            prop_assert!(r.out_of_range_faces.is_empty() && r.small_faces.is_empty());
        }
    }
}
