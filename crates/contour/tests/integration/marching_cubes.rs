//! Properties of the marching-cubes extractor: watertightness, orientation, accuracy,
//! topology of the phantoms, every cube configuration, random fields and geometries.

use glam::{DMat3, DVec3};
use proptest::prelude::*;
use volmorph_contour::{
    ContourError, EDGE_MARGIN, IsoSurface, McOptions, marching_cubes, marching_cubes_any,
};
use volmorph_mesh::{Mesh, ValidationReport};
use volmorph_volume::phantom::{self, Phantom};
use volmorph_volume::{AnyVolume, Geometry, Volume};

const SDF: McOptions = McOptions { inside_below: true };
const DENSITY: McOptions = McOptions {
    inside_below: false,
};

/// The report of a mesh that must be clean (no degenerate faces, edges used at most twice and
/// consistently oriented, manifold vertices, no unreferenced vertices).
fn clean(mesh: &Mesh) -> ValidationReport {
    let report = mesh.validate();
    assert!(report.is_clean(), "{report}");
    report
}

/// The report of a mesh that must be a clean closed 2-manifold.
fn closed(mesh: &Mesh) -> ValidationReport {
    let report = clean(mesh);
    assert!(report.is_closed_manifold(), "{report}");
    report
}

fn assert_distinct_positions(mesh: &Mesh) {
    let mut keys: Vec<[u64; 3]> = mesh
        .positions()
        .iter()
        .map(|p| p.to_array().map(f64::to_bits))
        .collect();
    keys.sort_unstable();
    let n = keys.len();
    keys.dedup();
    assert_eq!(keys.len(), n, "two vertices share a position");
}

/// Every triangle's normal points away from `centre`, and every gradient normal is a unit
/// vector agreeing with the normals of its triangles.
fn assert_outward_about(surface: &IsoSurface, centre: DVec3) {
    let mesh = &surface.mesh;
    let p = mesh.positions();
    assert_eq!(surface.normals.len(), p.len());
    for face in mesh.faces() {
        let [a, b, c] = [face[0], face[1], face[2]].map(|i| p[i as usize]);
        let n = (b - a).cross(c - a);
        let centroid = (a + b + c) / 3.0;
        assert!(
            n.dot(centroid - centre) > 0.0,
            "inward triangle at {centroid}"
        );
        for &i in face {
            let g = surface.normals[i as usize];
            assert!((g.length() - 1.0).abs() < 1e-9);
            assert!(g.dot(n.normalize()) > 0.5, "gradient normal disagrees");
        }
    }
}

fn sphere_field(geometry: Geometry, centre: DVec3, radius: f64) -> Volume<f32> {
    Volume::from_fn(geometry, |i, j, k| {
        let p = geometry.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
        (p.distance(centre) - radius) as f32
    })
    .unwrap()
}

#[test]
fn sphere_sdf_is_an_accurate_outward_sphere() {
    let dims = [40, 40, 40];
    let sdf = phantom::signed_distance(Phantom::Sphere, dims).unwrap();
    let h = sdf.geometry().spacing.x;
    let surface = marching_cubes(&sdf, 0.0, &SDF).unwrap();
    let report = closed(&surface.mesh);
    assert_eq!(report.euler_characteristic, 2);
    assert_eq!(report.components, 1);
    assert_distinct_positions(&surface.mesh);
    let r = phantom::SPHERE_RADIUS;
    for p in surface.mesh.positions() {
        // Linear interpolation of an exact distance: chord error O(h²/r).
        assert!((p.length() - r).abs() < 0.02 * h, "{p} is off the sphere");
    }
    assert_outward_about(&surface, DVec3::ZERO);
    for (p, n) in surface.mesh.positions().iter().zip(&surface.normals) {
        assert!(
            n.dot(p.normalize()) > 0.999,
            "normal {n} at {p} is not radial"
        );
    }
    let ball = 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
    assert!((surface.mesh.signed_volume() / ball - 1.0).abs() < 0.01);
}

#[test]
fn density_sphere_at_iso_value_agrees_with_the_sdf_surface() {
    let density = phantom::density(Phantom::Sphere, [40, 40, 40]).unwrap();
    let surface = marching_cubes(&density, f64::from(phantom::ISO_VALUE), &DENSITY).unwrap();
    let report = closed(&surface.mesh);
    assert_eq!(report.euler_characteristic, 2);
    assert_outward_about(&surface, DVec3::ZERO);
    let h = density.geometry().spacing.x;
    for p in surface.mesh.positions() {
        assert!((p.length() - phantom::SPHERE_RADIUS).abs() < 0.5 * h);
    }
}

#[test]
fn torus_is_closed_with_euler_characteristic_zero() {
    let sdf = phantom::signed_distance(Phantom::Torus, [48, 48, 32]).unwrap();
    let surface = marching_cubes(&sdf, 0.0, &SDF).unwrap();
    let report = closed(&surface.mesh);
    assert_eq!(report.euler_characteristic, 0);
    assert_eq!(report.components, 1);
    assert!(surface.mesh.signed_volume() > 0.0);
    assert_distinct_positions(&surface.mesh);
}

/// Genus of each phantom from its documentation: the torus is a ring; the clay block is
/// pierced by one through-hole; the teapot's handle is a ring whose hole stays open; the
/// others (the tree too: a branching solid without loops) are balls.
fn expected_euler(ph: Phantom) -> i64 {
    match ph {
        Phantom::Sphere | Phantom::RoundedBox | Phantom::Tree => 2,
        Phantom::Torus | Phantom::ClayBlock | Phantom::Teapot => 0,
    }
}

#[test]
fn every_phantom_gives_a_closed_surface_of_its_genus() {
    for ph in Phantom::ALL {
        let dims = [56, 56, 56];
        let sdf = phantom::signed_distance(ph, dims).unwrap();
        let s = marching_cubes(&sdf, 0.0, &SDF).unwrap();
        let report = closed(&s.mesh);
        assert_eq!(report.components, 1, "{ph:?} sdf");
        assert_eq!(
            report.euler_characteristic,
            expected_euler(ph),
            "{ph:?} sdf"
        );
        assert!(s.mesh.signed_volume() > 0.0);

        let density = phantom::density(ph, dims).unwrap();
        let s = marching_cubes(&density, f64::from(phantom::ISO_VALUE), &DENSITY).unwrap();
        let report = closed(&s.mesh);
        assert_eq!(report.components, 1, "{ph:?} density");
        assert_eq!(
            report.euler_characteristic,
            expected_euler(ph),
            "{ph:?} density"
        );
        assert!(s.mesh.signed_volume() > 0.0);
    }
}

#[test]
fn a_surface_cut_by_the_volume_boundary_is_open_there() {
    // A ball larger than the grid's box around one of its corners.
    let g = Geometry::new([9, 8, 7]).with_spacing(DVec3::new(0.5, 0.7, 1.1));
    let (lo, hi) = g.physical_bounds();
    let field = sphere_field(g, lo, 0.6 * (hi - lo).length());
    let surface = marching_cubes(&field, 0.0, &SDF).unwrap();
    let report = clean(&surface.mesh);
    assert!(!report.boundary_edges.is_empty());
    assert_eq!(report.boundary_loops, 1);
    let on_boundary = |p: DVec3| -> [bool; 6] {
        let q = g.physical_to_index(p);
        let n = g.dims.map(|d| (d - 1) as f64);
        [
            q.x.abs() < 1e-9,
            (q.x - n[0]).abs() < 1e-9,
            q.y.abs() < 1e-9,
            (q.y - n[1]).abs() < 1e-9,
            q.z.abs() < 1e-9,
            (q.z - n[2]).abs() < 1e-9,
        ]
    };
    // Every boundary edge lies in one face of the grid's box: find the open edges directly.
    let p = surface.mesh.positions();
    let mut edges = std::collections::HashMap::new();
    for f in surface.mesh.faces() {
        for s in 0..3 {
            let (a, b) = (f[s], f[(s + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    let open: Vec<_> = edges.iter().filter(|&(_, &c)| c == 1).collect();
    assert!(!open.is_empty());
    for (&(a, b), _) in open {
        let (fa, fb) = (on_boundary(p[a as usize]), on_boundary(p[b as usize]));
        assert!(
            (0..6).any(|s| fa[s] && fb[s]),
            "open edge off the box faces"
        );
    }
}

/// A `dims` grid of 0/1 samples at spacing 1, with `inside(i, j, k)` giving 1.
fn binary(dims: [usize; 3], inside: impl Fn(usize, usize, usize) -> bool + Sync) -> Volume<f32> {
    Volume::from_fn(
        Geometry::new(dims),
        |i, j, k| {
            if inside(i, j, k) { 1.0 } else { 0.0 }
        },
    )
    .unwrap()
}

#[test]
fn every_cube_configuration_gives_a_sound_patch() {
    for case in 0u32..256 {
        let bit = |i: usize, j: usize, k: usize| (case >> (i + 2 * j + 4 * k)) & 1 == 1;
        // Level 0.5 puts vertices at edge midpoints; level 1.0 (a sample value, counted as
        // inside) pushes them against the inside ends.
        for level in [0.5, 1.0] {
            let cube = binary([2, 2, 2], bit);
            let s = marching_cubes(&cube, level, &DENSITY).unwrap();
            let report = clean(&s.mesh);
            assert_eq!(report.non_manifold_edges.count, 0, "case {case}");
            if case == 0 || case == 255 {
                assert_eq!(s.mesh.face_count(), 0);
                continue;
            }
            // The patch's open edges lie on the cube's faces: both ends share a coordinate
            // plane x, y or z ∈ {0, 1}.
            for face in s.mesh.faces() {
                for e in 0..3 {
                    let a = s.mesh.positions()[face[e] as usize];
                    let b = s.mesh.positions()[face[(e + 1) % 3] as usize];
                    let on_face =
                        (0..3).any(|ax| [0.0, 1.0].iter().any(|&c| a[ax] == c && b[ax] == c));
                    // Interior edges are shared by two triangles; only those on a face may
                    // be open.
                    if !on_face {
                        let twin = s.mesh.faces().filter(|f| {
                            (0..3).any(|x| f[x] == face[(e + 1) % 3] && f[(x + 1) % 3] == face[e])
                        });
                        assert_eq!(twin.count(), 1, "case {case}: interior edge open");
                    }
                }
            }
            // Surrounded by outside samples, the same configuration is a closed surface.
            let padded = binary([4, 4, 4], |i, j, k| {
                (1..3).contains(&i) && (1..3).contains(&j) && (1..3).contains(&k) && {
                    bit(i - 1, j - 1, k - 1)
                }
            });
            let s = marching_cubes(&padded, level, &DENSITY).unwrap();
            closed(&s.mesh);
            assert!(s.mesh.signed_volume() > 0.0, "case {case}");
            assert_distinct_positions(&s.mesh);
        }
    }
}

#[test]
fn ambiguous_faces_separate_the_inside_corners() {
    // Two inside samples diagonal on a face: two separate pieces, not a tunnel.
    let v = binary([4, 4, 3], |i, j, k| {
        k == 1 && matches!((i, j), (1, 1) | (2, 2))
    });
    let s = marching_cubes(&v, 0.5, &DENSITY).unwrap();
    let report = closed(&s.mesh);
    assert_eq!(report.components, 2);
    assert_eq!(report.euler_characteristic, 4);
}

#[test]
fn oblique_and_mirrored_geometries_keep_outward_orientation() {
    let rot = DMat3::from_axis_angle(DVec3::new(1.0, 2.0, 3.0).normalize(), 0.7);
    let mirror = DMat3::from_diagonal(DVec3::new(1.0, -1.0, 1.0));
    let sheared = DMat3::from_cols(
        DVec3::new(1.0, 0.0, 0.0),
        DVec3::new(0.3, 1.0, 0.0).normalize(),
        DVec3::new(0.0, -0.2, 1.0).normalize(),
    );
    for direction in [
        rot,
        rot * mirror,
        mirror,
        -DMat3::IDENTITY,
        sheared * mirror,
    ] {
        let g = Geometry::new([24, 20, 22])
            .with_spacing(DVec3::new(0.9, 1.1, 1.3))
            .with_origin(DVec3::new(5.0, -3.0, 2.0))
            .with_direction(direction);
        let centre = g.index_to_physical(DVec3::new(11.5, 9.5, 10.5));
        let field = sphere_field(g, centre, 8.0);
        let s = marching_cubes(&field, 0.0, &SDF).unwrap();
        let report = closed(&s.mesh);
        assert_eq!(report.euler_characteristic, 2);
        assert_outward_about(&s, centre);
        let ball = 4.0 / 3.0 * std::f64::consts::PI * 512.0;
        assert!((s.mesh.signed_volume() / ball - 1.0).abs() < 0.03);
        // The same solid as a density (inside above the level) gives the same surface.
        let density = field.map(|d| -d);
        let t = marching_cubes(&density, 0.0, &DENSITY).unwrap();
        assert_eq!(t.mesh.face_count(), s.mesh.face_count());
        assert!((t.mesh.signed_volume() - s.mesh.signed_volume()).abs() < 1e-9);
    }
}

#[test]
fn result_does_not_depend_on_the_thread_count() {
    let sdf = phantom::signed_distance(Phantom::Teapot, [40, 36, 33]).unwrap();
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| marching_cubes(&sdf, 0.0, &SDF).unwrap())
    };
    let one = run(1);
    assert_eq!(one, run(3));
    assert_eq!(one, run(8));
}

#[test]
fn any_volume_entry_matches_the_typed_one() {
    let density = phantom::density(Phantom::RoundedBox, [20, 20, 20]).unwrap();
    let typed = marching_cubes(&density, 127.0, &DENSITY).unwrap();
    let any = marching_cubes_any(&AnyVolume::from(density), 127.0, &DENSITY).unwrap();
    assert_eq!(typed, any);
}

#[test]
fn bad_input_is_an_error() {
    let v = Volume::filled(Geometry::new([4, 4, 4]), 1.0f32).unwrap();
    assert!(matches!(
        marching_cubes(&v, f64::NAN, &SDF),
        Err(ContourError::NonFiniteLevel(_))
    ));
    assert!(matches!(
        marching_cubes(&v, f64::INFINITY, &SDF),
        Err(ContourError::NonFiniteLevel(_))
    ));
    let flat = Volume::filled(Geometry::new([4, 1, 4]), 1.0f32).unwrap();
    let err = marching_cubes(&flat, 0.0, &SDF).unwrap_err();
    assert!(matches!(err, ContourError::TooSmall { dims: [4, 1, 4] }));
    assert!(err.to_string().contains("at least 2"));
    // A field with no crossing gives an empty mesh, not an error.
    let s = marching_cubes(&v, 0.0, &SDF).unwrap();
    assert_eq!(s.mesh.face_count(), 0);
    assert!(s.normals.is_empty());
}

#[test]
fn samples_at_the_level_are_inside_and_vertices_stay_off_the_grid_points() {
    // One sample exactly at the level surrounded by outside samples: a tiny closed
    // octahedron around it, each vertex EDGE_MARGIN from the sample.
    let mut v = Volume::filled(Geometry::new([3, 3, 3]), 0.0f32).unwrap();
    *v.get_mut(1, 1, 1).unwrap() = 2.0;
    let s = marching_cubes(&v, 2.0, &DENSITY).unwrap();
    let report = closed(&s.mesh);
    assert_eq!(s.mesh.vertex_count(), 6);
    assert_eq!(s.mesh.face_count(), 8);
    assert_eq!(report.euler_characteristic, 2);
    for p in s.mesh.positions() {
        assert!((p.distance(DVec3::ONE) - EDGE_MARGIN).abs() < 1e-12);
    }
    assert!(s.mesh.signed_volume() > 0.0);
    // NaN samples are outside.
    let mut w = Volume::filled(Geometry::new([3, 3, 3]), f32::NAN).unwrap();
    *w.get_mut(1, 1, 1).unwrap() = 1.0;
    for opts in [SDF, DENSITY] {
        let s = marching_cubes(&w, 1.0, &opts).unwrap();
        closed(&s.mesh);
        assert_eq!(s.mesh.face_count(), 8);
        assert!(s.normals.iter().all(|n| n.is_finite()));
    }
}

/// Random sample values on a small grid drawn from few integers, so that samples often equal
/// each other and the level.
fn small_field() -> impl Strategy<Value = ([usize; 3], Vec<f32>)> {
    (2usize..6, 2usize..6, 2usize..6).prop_flat_map(|(a, b, c)| {
        (
            Just([a, b, c]),
            proptest::collection::vec((-3i8..=3).prop_map(f32::from), a * b * c),
        )
    })
}

fn pad(dims: [usize; 3], data: &[f32], outside: f32) -> Volume<f32> {
    let g = Geometry::new(dims.map(|d| d + 2));
    Volume::from_fn(g, |i, j, k| {
        let inner =
            (1..=dims[0]).contains(&i) && (1..=dims[1]).contains(&j) && (1..=dims[2]).contains(&k);
        if inner {
            data[(i - 1) + dims[0] * ((j - 1) + dims[1] * (k - 1))]
        } else {
            outside
        }
    })
    .unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn random_fields_give_clean_consistently_oriented_surfaces(
        (dims, data) in small_field(),
        level in prop_oneof![(-3i8..=3).prop_map(f64::from), -3.5f64..3.5],
        below in any::<bool>(),
    ) {
        let options = McOptions { inside_below: below };
        let v = Volume::new(Geometry::new(dims), data.clone()).unwrap();
        let s = marching_cubes(&v, level, &options).unwrap();
        let report = s.mesh.validate();
        prop_assert!(report.is_clean(), "{}", report);
        assert_distinct_positions(&s.mesh);
        // Exactly one vertex per grid edge whose ends are classified differently.
        let inside = |x: f32| {
            let x = f64::from(x);
            if below { x <= level } else { x >= level }
        };
        let at = |i: usize, j: usize, k: usize| inside(data[i + dims[0] * (j + dims[1] * k)]);
        let mut crossed = 0;
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let here = at(i, j, k);
                    crossed += usize::from(i + 1 < dims[0] && here != at(i + 1, j, k));
                    crossed += usize::from(j + 1 < dims[1] && here != at(i, j + 1, k));
                    crossed += usize::from(k + 1 < dims[2] && here != at(i, j, k + 1));
                }
            }
        }
        prop_assert_eq!(s.mesh.vertex_count(), crossed);
        prop_assert_eq!(s.normals.len(), crossed);
        // Padded with outside samples, the surface closes.
        let outside = if below { 10.0 } else { -10.0 };
        let padded = pad(dims, &data, outside);
        let s = marching_cubes(&padded, level, &options).unwrap();
        let report = s.mesh.validate();
        prop_assert!(report.is_clean(), "{}", report);
        if s.mesh.face_count() > 0 {
            prop_assert!(report.is_closed_manifold(), "{}", report);
            prop_assert!(s.mesh.signed_volume() > 0.0);
        }
    }

    #[test]
    fn two_by_two_cell_grids_have_no_cracks(signs in any::<u32>()) {
        // 3×3×3 samples (2×2×2 cells) with random inside/outside, surrounded by outside.
        let bit = |i: usize, j: usize, k: usize| (signs >> (i + 3 * j + 9 * k)) & 1 == 1;
        let v = binary([5, 5, 5], |i, j, k| {
            (1..4).contains(&i) && (1..4).contains(&j) && (1..4).contains(&k)
                && bit(i - 1, j - 1, k - 1)
        });
        let s = marching_cubes(&v, 0.5, &DENSITY).unwrap();
        let report = s.mesh.validate();
        prop_assert!(report.is_clean(), "{}", report);
        if s.mesh.face_count() > 0 {
            prop_assert!(report.is_closed_manifold(), "{}", report);
            prop_assert!(s.mesh.signed_volume() > 0.0);
        }
    }
}

/// FNV-1a fingerprint of a surface: vertex count, every position and normal bit, every
/// triangle index, in order.
fn surface_bits(s: &IsoSurface) -> u64 {
    let m = &s.mesh;
    volmorph_testkit::fingerprint::fnv1a(
        std::iter::once(m.positions().len() as u64)
            .chain(
                m.positions()
                    .iter()
                    .chain(&s.normals)
                    .flat_map(|p| p.to_array().map(f64::to_bits)),
            )
            .chain(
                m.faces()
                    .flat_map(|f| f.iter().map(|&i| u64::from(i)).collect::<Vec<_>>()),
            ),
    )
}

/// The extractor's output bits (vertex and triangle order included) on fields that exercise
/// every path of the scan: rows of 64 samples and of other lengths (word boundaries of a
/// packed classification), whole rows and planes inside or outside, samples exactly at the
/// level, NaN samples, a mirrored oblique geometry (reversed triangles), and a density with
/// the inside above the level. Pinned to the values of the scalar row scan of 2026-12-06: a
/// faster scan must give the same surface bit for bit.
#[test]
fn marching_cubes_bits_unchanged() {
    let mut got = Vec::new();
    let sphere = phantom::signed_distance(Phantom::Sphere, [64, 64, 64]).unwrap();
    got.push(surface_bits(&marching_cubes(&sphere, 0.0, &SDF).unwrap()));
    let teapot = phantom::density(Phantom::Teapot, [70, 66, 40]).unwrap();
    got.push(surface_bits(
        &marching_cubes(&teapot, 127.0, &DENSITY).unwrap(),
    ));
    // Random field on an odd-sized, mirrored, oblique grid; a quarter of the samples exactly
    // at the level, a few NaN, whole rows constant.
    let dims = [131, 67, 33];
    let mut rng = volmorph_testkit::Rng::new(2026);
    let n = dims.iter().product::<usize>();
    let data: Vec<f32> = (0..n)
        .map(|o| {
            let row = o / dims[0];
            if row % 7 == 3 {
                return -1.0;
            }
            if row % 11 == 5 {
                return 2.0;
            }
            match rng.next_u64() % 16 {
                0..=3 => 0.0,
                4 => f32::NAN,
                _ => rng.range(-1.0, 1.0) as f32,
            }
        })
        .collect();
    let angle = 0.3f64;
    let direction = DMat3::from_cols(
        DVec3::new(angle.cos(), angle.sin(), 0.0),
        DVec3::new(-angle.sin(), angle.cos(), 0.0),
        DVec3::new(0.0, 0.0, -1.0),
    );
    let geometry = Geometry::new(dims)
        .with_spacing(DVec3::new(0.7, 1.1, 1.3))
        .with_origin(DVec3::new(-3.0, 2.0, 5.0))
        .with_direction(direction);
    let random = Volume::new(geometry, data).unwrap();
    got.push(surface_bits(&marching_cubes(&random, 0.0, &SDF).unwrap()));
    got.push(surface_bits(
        &marching_cubes(&random, 0.25, &DENSITY).unwrap(),
    ));
    let small: Vec<f32> = (0..3 * 4 * 5)
        .map(|_| rng.range(-1.0, 1.0) as f32)
        .collect();
    let small = Volume::new(Geometry::new([3, 4, 5]), small).unwrap();
    got.push(surface_bits(&marching_cubes(&small, 0.0, &SDF).unwrap()));
    let expected: [u64; 5] = [
        0xdb37_ea53_75de_5c90,
        0x5191_5521_b7d2_8647,
        0xa1a0_ff91_0857_67a6,
        0x1aff_9bf9_30cf_3617,
        0xafa8_ec1b_88cf_c1c7,
    ];
    assert_eq!(got, expected, "{got:#018x?}");
}
