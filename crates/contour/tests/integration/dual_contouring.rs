//! Properties of the dual-contouring extractor: closed surfaces, accuracy on smooth and sharp
//! geometry (against marching cubes), edge-manifoldness and orientation on random smooth
//! fields, the QEF solver, degenerate inputs and mirrored geometries.

use glam::{DMat3, DQuat, DVec3};
use volmorph_contour::{
    ContourError, DEFAULT_FEATURE_ANGLE, DEFAULT_SINGULAR_THRESHOLD, DcOptions, IsoSurface,
    McOptions, Qef, dual_contouring, dual_contouring_any, marching_cubes,
};
use volmorph_mesh::{Mesh, ValidationReport};
use volmorph_testkit::Rng;
use volmorph_volume::phantom::{self, Phantom};
use volmorph_volume::{AnyVolume, Geometry, Volume, Voxel};

const SDF: DcOptions = DcOptions {
    inside_below: true,
    feature_angle: DEFAULT_FEATURE_ANGLE,
    singular_threshold: DEFAULT_SINGULAR_THRESHOLD,
};

/// Plain dual contouring: the QEF solved in every cell.
const PLAIN: DcOptions = DcOptions {
    feature_angle: 0.0,
    ..SDF
};

fn close(a: DVec3, b: DVec3, tol: f64) -> bool {
    (a - b).length() <= tol
}

/// Signed distance to a sphere of radius `r` centred at index position `c`.
fn sphere(geometry: Geometry, c: DVec3, r: f64) -> Volume<f64> {
    Volume::from_fn(geometry, |i, j, k| {
        (DVec3::new(i as f64, j as f64, k as f64) - c).length() - r
    })
    .unwrap()
}

/// Exact signed distance to the box of half extents `h` centred at `c`, rotated by `rot`.
fn box_sdf(p: DVec3, c: DVec3, h: DVec3, rot: DQuat) -> f64 {
    let d = (rot.inverse() * (p - c)).abs() - h;
    d.max(DVec3::ZERO).length() + d.max_element().min(0.0)
}

/// Distance from `p` to the triangle `abc`.
fn point_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let n = (b - a).cross(c - a);
    let edges = [(a, b), (b, c), (c, a)];
    let inside = edges
        .iter()
        .all(|&(u, v)| (v - u).cross(p - u).dot(n) >= 0.0);
    if inside && n.length_squared() > 0.0 {
        return (p - a).dot(n).abs() / n.length();
    }
    edges
        .iter()
        .map(|&(u, v)| {
            let e = v - u;
            let t = ((p - u).dot(e) / e.length_squared().max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
            (u + e * t - p).length()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Distance from `p` to the mesh's surface.
fn distance_to_mesh(mesh: &Mesh, p: DVec3) -> f64 {
    let x = mesh.positions();
    mesh.faces()
        .map(|f| point_triangle(p, x[f[0] as usize], x[f[1] as usize], x[f[2] as usize]))
        .fold(f64::INFINITY, f64::min)
}

/// Every triangle's normal points away from `centre`; every vertex normal is a unit vector
/// pointing away from it too.
fn assert_outward_about(surface: &IsoSurface, centre: DVec3) {
    let p = surface.mesh.positions();
    assert_eq!(surface.normals.len(), p.len());
    for f in surface.mesh.faces() {
        assert_eq!(f.len(), 3);
        let [a, b, c] = [f[0], f[1], f[2]].map(|i| p[i as usize]);
        let n = (b - a).cross(c - a);
        assert!(n.dot((a + b + c) / 3.0 - centre) > 0.0, "inward triangle");
    }
    for (x, n) in p.iter().zip(&surface.normals) {
        assert!((n.length() - 1.0).abs() < 1e-9);
        assert!(n.dot((*x - centre).normalize()) > 0.9, "normal {n} at {x}");
    }
}

/// The report of a clean closed 2-manifold.
fn closed(mesh: &Mesh) -> ValidationReport {
    let report = mesh.validate();
    assert!(report.is_clean(), "{report}");
    assert!(report.is_closed_manifold(), "{report}");
    report
}

#[test]
fn sphere_gives_a_closed_manifold_on_the_true_sphere() {
    let c = DVec3::new(11.7, 11.3, 11.5);
    let r = 8.0;
    let v = sphere(Geometry::new([24, 24, 24]), c, r);
    for options in [SDF, PLAIN] {
        let s = dual_contouring(&v, 0.0, &options).unwrap();
        let report = closed(&s.mesh);
        assert_eq!(report.euler_characteristic, 2);
        assert_eq!(report.components, 1);
        let worst = s
            .mesh
            .positions()
            .iter()
            .map(|p| ((*p - c).length() - r).abs())
            .fold(0.0, f64::max);
        assert!(worst < 0.12, "vertex {worst} voxel off the sphere");
        assert_outward_about(&s, c);
        let ball = 4.0 / 3.0 * std::f64::consts::PI * r * r * r;
        assert!((s.mesh.signed_volume() / ball - 1.0).abs() < 0.03);
    }
    // The same surface as a density (inside above the level) of the negated field.
    let neg = Volume::from_fn(Geometry::new([24, 24, 24]), |i, j, k| {
        r - (DVec3::new(i as f64, j as f64, k as f64) - c).length()
    })
    .unwrap();
    let density = DcOptions {
        inside_below: false,
        ..SDF
    };
    let a = dual_contouring(&v, 0.0, &SDF).unwrap();
    let b = dual_contouring(&neg, 0.0, &density).unwrap();
    assert_eq!(a.mesh.face_count(), b.mesh.face_count());
    for (p, q) in a.mesh.positions().iter().zip(b.mesh.positions()) {
        assert!(close(*p, *q, 1e-9));
    }
    assert_outward_about(&b, c);
}

/// A 18 × 14 × 10 voxel box rotated by 30°: the distances from points on its edges and its
/// corners to the extracted surfaces.
#[test]
fn rotated_box_keeps_its_sharp_edges_and_corners() {
    let n = 32;
    let c = DVec3::splat(15.3);
    let h = DVec3::new(9.0, 7.0, 5.0);
    let rot = DQuat::from_axis_angle(DVec3::new(1.0, 2.0, 3.0).normalize(), 30f64.to_radians());
    let v = Volume::from_fn(Geometry::new([n, n, n]), |i, j, k| {
        box_sdf(DVec3::new(i as f64, j as f64, k as f64), c, h, rot)
    })
    .unwrap();
    let dc = dual_contouring(&v, 0.0, &SDF).unwrap();
    let mc = marching_cubes(&v, 0.0, &McOptions { inside_below: true }).unwrap();
    let report = dc.mesh.validate();
    assert!(report.boundary_edges.is_empty(), "{report}");
    assert!(report.misoriented_edges.is_empty(), "{report}");
    assert!(report.degenerate_faces.is_empty(), "{report}");
    assert_eq!(report.euler_characteristic, 2);
    // Outward and enclosing the box's volume (a few triangles may fold at the features).
    let volume = 8.0 * h.x * h.y * h.z;
    assert!((dc.mesh.signed_volume() / volume - 1.0).abs() < 0.01);

    let mut edge_points = Vec::new();
    for axis in 0..3 {
        let (u, w) = ((axis + 1) % 3, (axis + 2) % 3);
        for s1 in [-1.0, 1.0] {
            for s2 in [-1.0, 1.0] {
                for t in 1..=9 {
                    let mut q = DVec3::ZERO;
                    q[u] = s1 * h[u];
                    q[w] = s2 * h[w];
                    q[axis] = h[axis] * (-0.8 + 0.16 * f64::from(t));
                    edge_points.push(c + rot * q);
                }
            }
        }
    }
    let corners: Vec<DVec3> = (0..8)
        .map(|b| {
            let sign = |bit: i32| if b & bit == 0 { -1.0 } else { 1.0 };
            c + rot * (DVec3::new(sign(1), sign(2), sign(4)) * h)
        })
        .collect();
    let mean = |m: &Mesh, pts: &[DVec3]| {
        pts.iter().map(|&p| distance_to_mesh(m, p)).sum::<f64>() / pts.len() as f64
    };
    let (dc_edges, mc_edges) = (mean(&dc.mesh, &edge_points), mean(&mc.mesh, &edge_points));
    let (dc_corners, mc_corners) = (mean(&dc.mesh, &corners), mean(&mc.mesh, &corners));
    // Measured: edges 0.015 vs 0.34 voxel, corners 0.094 vs 0.61 voxel.
    assert!(dc_edges < 0.03, "dc edge error {dc_edges}");
    assert!(10.0 * dc_edges < mc_edges, "dc {dc_edges} vs mc {mc_edges}");
    assert!(
        4.0 * dc_corners < mc_corners,
        "dc {dc_corners} vs mc {mc_corners}"
    );
    // Away from the features the faces are flat: vertices lie on the box.
    for p in dc.mesh.positions() {
        assert!(box_sdf(*p, c, h, rot).abs() < 0.5);
    }
}

/// Whether some cell face has all four edges crossed (two inside corners diagonally
/// opposite), the configuration where one vertex per cell cannot be edge-manifold.
fn has_ambiguous_face<T: Voxel>(v: &Volume<T>, level: f64) -> bool {
    let [nx, ny, nz] = v.geometry().dims;
    let inside = |i: usize, j: usize, k: usize| v.data()[i + nx * (j + ny * k)].to_f64() <= level;
    let d = [[1, 0, 0], [0, 1, 0], [0, 0, 1]];
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                for (a, b) in [(0, 1), (0, 2), (1, 2)] {
                    let (u, w) = (d[a], d[b]);
                    let (i1, j1, k1) = (i + u[0], j + u[1], k + u[2]);
                    let (i2, j2, k2) = (i + w[0], j + w[1], k + w[2]);
                    let (i3, j3, k3) = (i1 + w[0], j1 + w[1], k1 + w[2]);
                    if i3 >= nx || j3 >= ny || k3 >= nz {
                        continue;
                    }
                    let s = [
                        inside(i, j, k),
                        inside(i1, j1, k1),
                        inside(i3, j3, k3),
                        inside(i2, j2, k2),
                    ];
                    if s[0] == s[2] && s[1] == s[3] && s[0] != s[1] {
                        return true;
                    }
                }
            }
        }
    }
    false
}

#[test]
fn random_smooth_fields_give_edge_manifold_consistently_oriented_meshes() {
    let mut rng = Rng::new(0x5eed);
    let mut checked = 0;
    let fields = 40;
    for case in 0..fields {
        let n = 14;
        // A sum of four random Gaussian blobs, widths 2–4 voxels, minus a level.
        let blobs: Vec<(DVec3, f64, f64)> = (0..4)
            .map(|_| {
                let c = rng.point_in(DVec3::ZERO, DVec3::splat(13.0));
                (c, rng.range(2.0, 4.0), rng.range(-0.3, 0.7))
            })
            .collect();
        let geometry = Geometry::new([n, n, n]);
        let v = Volume::from_fn(geometry, |i, j, k| {
            let p = DVec3::new(i as f64, j as f64, k as f64);
            blobs
                .iter()
                .map(|(c, w, a)| a * (-(p - *c).length_squared() / (w * w)).exp())
                .sum::<f64>()
        })
        .unwrap();
        let level = 0.15;
        let options = DcOptions {
            inside_below: false,
            feature_angle: if case % 2 == 0 {
                0.0
            } else {
                DEFAULT_FEATURE_ANGLE
            },
            ..SDF
        };
        let s = dual_contouring(&v, level, &options).unwrap();
        let report = s.mesh.validate();
        assert!(report.misoriented_edges.is_empty(), "{report}");
        assert!(report.unreferenced_vertices.is_empty(), "{report}");
        assert!(report.repeated_vertex_faces.is_empty(), "{report}");
        assert!(report.non_finite_vertices.is_empty(), "{report}");
        assert_eq!(s.normals.len(), s.mesh.vertex_count());
        // Every vertex stays inside the bounding box of the grid.
        for p in s.mesh.positions() {
            assert!(p.min_element() > 0.0 && p.max_element() < 13.0);
        }
        let flipped = {
            let density = DcOptions {
                inside_below: true,
                ..options
            };
            let neg = Volume::from_fn(geometry, |i, j, k| -v.data()[i + n * (j + n * k)]).unwrap();
            dual_contouring(&neg, -level, &density).unwrap()
        };
        assert_eq!(flipped.mesh, s.mesh);
        // Inside ⇔ value ≥ level ⇔ −value ≤ −level; ambiguity is checked on −value.
        let neg = Volume::from_fn(geometry, |i, j, k| -v.data()[i + n * (j + n * k)]).unwrap();
        if !has_ambiguous_face(&neg, -level) {
            checked += 1;
            assert!(report.non_manifold_edges.is_empty(), "{report}");
        }
    }
    assert!(
        checked * 2 >= fields,
        "only {checked} of {fields} fields unambiguous"
    );
}

#[test]
fn qef_recovers_a_corner_from_three_orthogonal_planes() {
    let rot = DMat3::from_quat(DQuat::from_axis_angle(
        DVec3::new(0.3, -1.0, 0.5).normalize(),
        0.7,
    ));
    let corner = DVec3::new(1.25, -0.5, 3.0);
    let mut q = Qef::new(DVec3::new(1.0, 0.0, 3.0));
    for axis in 0..3 {
        let nrm = rot.col(axis);
        let (t1, t2) = (rot.col((axis + 1) % 3), rot.col((axis + 2) % 3));
        q.add(corner + 0.4 * t1 - 0.2 * t2, nrm);
        q.add(corner - 0.3 * t1 + 0.6 * t2, nrm);
    }
    let s = q.solve(DEFAULT_SINGULAR_THRESHOLD).unwrap();
    assert_eq!(s.rank, 3);
    assert!(close(s.position, corner, 1e-12), "{}", s.position);
    assert!(s.error < 1e-12);
}

#[test]
fn qef_recovers_the_edge_point_nearest_the_mass_point() {
    // Planes x = 1 and y = 2: the line (1, 2, z); mass point z = 1.
    let mut q = Qef::new(DVec3::ZERO);
    q.add(DVec3::new(1.0, 0.0, 0.0), DVec3::X);
    q.add(DVec3::new(1.0, 3.0, 2.0), DVec3::X);
    q.add(DVec3::new(3.0, 2.0, 1.0), DVec3::Y);
    q.add(DVec3::new(0.0, 2.0, 1.0), DVec3::Y);
    assert!(close(
        q.mass_point().unwrap(),
        DVec3::new(1.25, 1.75, 1.0),
        1e-15
    ));
    let s = q.solve(0.1).unwrap();
    assert_eq!(s.rank, 2);
    assert!(
        close(s.position, DVec3::new(1.0, 2.0, 1.0), 1e-12),
        "{}",
        s.position
    );
    assert!(s.error < 1e-12);
    // Nearly parallel planes (0.5° apart) are one plane under the default threshold.
    let mut q = Qef::new(DVec3::ZERO);
    let tilted = DVec3::new(0.5f64.to_radians().sin(), 0.0, 0.5f64.to_radians().cos());
    q.add(DVec3::new(0.0, 0.0, 1.0), DVec3::Z);
    q.add(DVec3::new(1.0, 0.0, 1.0), tilted);
    let s = q.solve(DEFAULT_SINGULAR_THRESHOLD).unwrap();
    assert_eq!(s.rank, 1);
    assert!(
        close(s.position, DVec3::new(0.5, 0.0, 1.0), 0.01),
        "{}",
        s.position
    );
    // Without truncation the two planes meet far away (x ≈ 1 − cot(0.5°)…, off the cell).
    assert_eq!(q.solve(0.0).unwrap().rank, 2);
}

#[test]
fn qef_projects_the_mass_point_onto_a_single_plane() {
    let n = DVec3::new(1.0, 2.0, 2.0) / 3.0;
    let on_plane = |p: DVec3| p - n * (n.dot(p) - 1.5);
    let points = [
        DVec3::new(0.0, 0.0, 0.0),
        DVec3::new(4.0, 1.0, -2.0),
        DVec3::new(-1.0, 3.0, 5.0),
    ]
    .map(on_plane);
    let mut q = Qef::new(DVec3::splat(1e6)); // far reference: precision kept
    for p in points {
        q.add(p, n);
    }
    let mass = (points[0] + points[1] + points[2]) / 3.0;
    let s = q.solve(0.1).unwrap();
    assert_eq!(s.rank, 1);
    assert!(close(s.position, mass, 1e-9), "{}", s.position);
    // A point off the plane is pulled onto it along the normal only.
    let mut q = Qef::new(DVec3::ZERO);
    q.add(DVec3::new(0.0, 0.0, 1.0), DVec3::Z);
    q.add(DVec3::new(2.0, 4.0, 0.0), DVec3::Z);
    let s = q.solve(0.1).unwrap();
    assert!(close(s.position, DVec3::new(1.0, 2.0, 0.5), 1e-12));
    assert!((s.error - 0.5).abs() < 1e-12);
    assert!((q.error_at(DVec3::new(7.0, 7.0, 0.5)) - 0.5).abs() < 1e-12);
}

#[test]
fn qef_handles_degenerate_input() {
    let empty = Qef::new(DVec3::ONE);
    assert_eq!(empty.count(), 0);
    assert_eq!(empty.mass_point(), None);
    assert_eq!(empty.solve(0.1), None);
    let mut q = Qef::new(DVec3::ZERO);
    q.add(DVec3::new(f64::NAN, 0.0, 0.0), DVec3::X); // ignored
    q.add(DVec3::new(1.0, 2.0, 3.0), DVec3::ZERO); // mass point only
    q.add(DVec3::new(3.0, 2.0, 1.0), DVec3::new(f64::NAN, 0.0, 0.0)); // mass point only
    assert_eq!(q.count(), 2);
    let s = q.solve(f64::NAN).unwrap();
    assert_eq!(s.rank, 0);
    assert_eq!(s.position, DVec3::new(2.0, 2.0, 2.0));
    assert_eq!(s.error, 0.0);
}

#[test]
fn invalid_input_is_an_error_and_empty_fields_give_empty_meshes() {
    let v = sphere(Geometry::new([8, 8, 8]), DVec3::splat(3.5), 2.5);
    assert!(matches!(
        dual_contouring(&v, f64::NAN, &SDF),
        Err(ContourError::NonFiniteLevel(_))
    ));
    for bad in [
        DcOptions {
            feature_angle: -0.1,
            ..SDF
        },
        DcOptions {
            feature_angle: f64::NAN,
            ..SDF
        },
        DcOptions {
            singular_threshold: 1.0,
            ..SDF
        },
    ] {
        let err = dual_contouring(&v, 0.0, &bad).unwrap_err();
        assert!(matches!(err, ContourError::InvalidOption { .. }), "{err}");
    }
    let thin = Volume::new(Geometry::new([1, 4, 4]), vec![0.0f32; 16]).unwrap();
    assert!(matches!(
        dual_contouring(&thin, 0.0, &SDF),
        Err(ContourError::TooSmall { .. })
    ));
    // No crossing: all outside, all inside.
    for level in [-10.0, 10.0] {
        let s = dual_contouring(&v, level, &SDF).unwrap();
        assert_eq!(s.mesh.vertex_count(), 0);
        assert_eq!(s.mesh.face_count(), 0);
        assert!(s.normals.is_empty());
    }
}

#[test]
fn nan_samples_are_outside() {
    // A ball with a NaN sample at its centre: the NaN is outside, so a small closed cavity
    // surrounds it, oriented inward (its normals point into the cavity).
    let c = DVec3::splat(7.0);
    let mut data = sphere(Geometry::new([15, 15, 15]), c, 5.0).into_data();
    data[7 + 15 * (7 + 15 * 7)] = f64::NAN;
    let v = Volume::new(Geometry::new([15, 15, 15]), data).unwrap();
    let s = dual_contouring(&v, 0.0, &SDF).unwrap();
    let report = s.mesh.validate();
    assert!(report.is_clean(), "{report}");
    assert_eq!(report.components, 2);
    assert!(report.boundary_edges.is_empty() && report.misoriented_edges.is_empty());
    assert!(s.mesh.positions().iter().all(|p| p.is_finite()));
    let ball = 4.0 / 3.0 * std::f64::consts::PI * 125.0;
    let vol = s.mesh.signed_volume();
    assert!(vol > 0.9 * ball && vol < ball, "{vol}");
}

#[test]
fn mirrored_and_anisotropic_geometries_stay_outward() {
    let c = DVec3::new(7.2, 6.9, 7.1);
    let r = 3.0;
    for direction in [
        DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0)),
        DMat3::from_cols(DVec3::Y, DVec3::X, DVec3::Z),
        DMat3::from_quat(DQuat::from_rotation_z(0.4)),
    ] {
        let geometry = Geometry::new([16, 16, 16])
            .with_spacing(DVec3::new(0.5, 0.75, 1.25))
            .with_origin(DVec3::new(3.0, -2.0, 1.0))
            .with_direction(direction);
        let centre = geometry.index_to_physical(c);
        let v = Volume::from_fn(geometry, |i, j, k| {
            let p = geometry.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
            (p - centre).length() - r
        })
        .unwrap();
        let s = dual_contouring(&v, 0.0, &SDF).unwrap();
        let report = closed(&s.mesh);
        assert_eq!(report.euler_characteristic, 2);
        assert_outward_about(&s, centre);
        assert!(s.mesh.signed_volume() > 0.0);
    }
}

#[test]
fn any_volume_matches_the_typed_entry() {
    let v = sphere(Geometry::new([12, 12, 12]), DVec3::splat(5.5), 4.0);
    let typed = dual_contouring(&v, 0.0, &SDF).unwrap();
    let f32s = Volume::new(
        *v.geometry(),
        v.data().iter().map(|&x| x as f32).collect::<Vec<f32>>(),
    )
    .unwrap();
    let any = dual_contouring_any(&AnyVolume::from(f32s), 0.0, &SDF).unwrap();
    assert_eq!(any.mesh.face_count(), typed.mesh.face_count());
    for (p, q) in any.mesh.positions().iter().zip(typed.mesh.positions()) {
        assert!(close(*p, *q, 1e-5));
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
            .install(|| dual_contouring(&sdf, 0.0, &SDF).unwrap())
    };
    let one = run(1);
    assert!(one.mesh.face_count() > 1000);
    assert_eq!(one, run(3));
    assert_eq!(one, run(8));
}

#[test]
fn phantoms_give_closed_meshes_of_the_right_topology() {
    for (phantom, euler) in [
        (Phantom::Sphere, 2),
        (Phantom::Torus, 0),
        (Phantom::RoundedBox, 2),
    ] {
        let sdf = phantom::signed_distance(phantom, [32, 32, 32]).unwrap();
        let s = dual_contouring(&sdf, 0.0, &SDF).unwrap();
        let report = s.mesh.validate();
        assert!(report.boundary_edges.is_empty(), "{phantom:?}: {report}");
        assert!(report.misoriented_edges.is_empty(), "{phantom:?}: {report}");
        assert!(report.degenerate_faces.is_empty(), "{phantom:?}: {report}");
        assert_eq!(report.euler_characteristic, euler, "{phantom:?}");
        // Non-manifold edges only where a cell face is ambiguous (the torus's saddles).
        if has_ambiguous_face(&sdf, 0.0) {
            assert_eq!(phantom, Phantom::Torus);
        } else {
            assert!(report.is_closed_manifold(), "{phantom:?}: {report}");
        }
        let mc = marching_cubes(&sdf, 0.0, &McOptions { inside_below: true }).unwrap();
        let ratio = s.mesh.signed_volume() / mc.mesh.signed_volume();
        assert!(
            (ratio - 1.0).abs() < 0.02,
            "{phantom:?}: volume ratio {ratio}"
        );
    }
}

/// An axis-aligned box whose faces lie between grid planes: its corners and edges are
/// recovered almost exactly (normals there are exact), where marching cubes cuts them off.
#[test]
fn axis_aligned_box_corners_and_edges_are_recovered() {
    let lo = DVec3::new(2.3, 2.7, 3.1);
    let hi = DVec3::new(8.6, 7.2, 6.4);
    let (c, h) = ((lo + hi) / 2.0, (hi - lo) / 2.0);
    let v = Volume::from_fn(Geometry::new([12, 11, 10]), |i, j, k| {
        box_sdf(
            DVec3::new(i as f64, j as f64, k as f64),
            c,
            h,
            DQuat::IDENTITY,
        )
    })
    .unwrap();
    let dc = dual_contouring(&v, 0.0, &SDF).unwrap();
    let mc = marching_cubes(&v, 0.0, &McOptions { inside_below: true }).unwrap();
    let report = closed(&dc.mesh);
    assert_eq!(report.euler_characteristic, 2);
    let nearest_vertex = |m: &Mesh, q: DVec3| {
        m.positions()
            .iter()
            .map(|p| p.distance(q))
            .fold(f64::INFINITY, f64::min)
    };
    for b in 0..8 {
        let pick = |bit: i32, a: f64, z: f64| if b & bit == 0 { a } else { z };
        let corner = DVec3::new(
            pick(1, lo.x, hi.x),
            pick(2, lo.y, hi.y),
            pick(4, lo.z, hi.z),
        );
        assert!(nearest_vertex(&dc.mesh, corner) < 1e-9, "corner {corner}");
        assert!(distance_to_mesh(&mc.mesh, corner) > 0.3);
    }
    // Points along the four edges parallel to x, and the enclosed volume, are exact.
    for (y, z) in [(lo.y, lo.z), (lo.y, hi.z), (hi.y, lo.z), (hi.y, hi.z)] {
        for t in 0..=8 {
            let p = DVec3::new(lo.x + (hi.x - lo.x) * f64::from(t) / 8.0, y, z);
            assert!(distance_to_mesh(&dc.mesh, p) < 1e-9, "edge point {p}");
        }
        assert!(distance_to_mesh(&mc.mesh, DVec3::new(c.x, y, z)) > 0.2);
    }
    let volume = 8.0 * h.x * h.y * h.z;
    assert!((dc.mesh.signed_volume() / volume - 1.0).abs() < 1e-12);
}
