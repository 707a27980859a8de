//! Cube cutting: the three methods cut the same polygons, whose union is the plane ∩ box.

use glam::{DMat3, DVec3};
use proptest::prelude::*;
use volmorph_render::cubecut::{ProxyPolygon, VERTEX_FLOATS, cut_box, cut_octree};
use volmorph_render::{
    CutMethod, DvrOptions, DvrRenderer, DvrVolume, ProxyBox, ProxyGeometry, Slicing,
    TransferFunction,
};
use volmorph_volume::{Geometry, Volume};

const METHODS: [CutMethod; 3] = [CutMethod::Sweep, CutMethod::Rsk, CutMethod::Clip];

/// Area of the section of the box by the plane `s = −f·x` (f unit), from the volume of the
/// part of the box behind it, independently of any cutting method: in box coordinates
/// `w ∈ [0, 1]³` with `s = s0 + m·w`, the volume is `Σ_v (−1)^|v| max(σ − m·v, 0)^n /
/// (n! Π m_i)` over the n axes along which `m` is not zero, so the area is `|det A|` times
/// its derivative.
fn section_area(bx: &ProxyBox, f: DVec3, s: f64) -> f64 {
    let mut m = -(bx.axes.transpose() * f);
    let mut sigma = s + f.dot(bx.origin);
    // Make every component positive by w_a → 1 − w_a.
    for a in 0..3 {
        if m[a] < 0.0 {
            sigma -= m[a];
            m[a] = -m[a];
        }
    }
    let scale = m.max_element();
    let axes: Vec<f64> = (0..3)
        .map(|a| m[a])
        .filter(|&x| x > 1e-12 * scale)
        .collect();
    let n = axes.len() as i32;
    let fact = (1..n).product::<i32>() as f64;
    let mut sum = 0.0;
    for v in 0..(1u32 << n) {
        let dot: f64 = (0..n as usize)
            .filter(|&i| v >> i & 1 == 1)
            .map(|i| axes[i])
            .sum();
        let x = sigma - dot;
        let g = if n == 1 {
            if x >= 0.0 { 1.0 } else { 0.0 }
        } else {
            x.max(0.0).powi(n - 1) / fact
        };
        sum += if v.count_ones() % 2 == 0 { g } else { -g };
    }
    bx.axes.determinant().abs() * sum / axes.iter().product::<f64>()
}

fn polygon(g: &ProxyGeometry, p: &ProxyPolygon) -> Vec<DVec3> {
    (0..p.vertex_count as usize)
        .map(|i| g.position(p.first_vertex as usize + i))
        .collect()
}

/// Area vector (normal times area) of a polygon.
fn area_vector(pts: &[DVec3]) -> DVec3 {
    let mut a = DVec3::ZERO;
    for i in 1..pts.len().saturating_sub(1) {
        a += (pts[i] - pts[0]).cross(pts[i + 1] - pts[0]);
    }
    0.5 * a
}

/// Distinct points (within `tol`).
fn distinct(pts: &[DVec3], tol: f64) -> Vec<DVec3> {
    let mut out: Vec<DVec3> = Vec::new();
    for &p in pts {
        if !out.iter().any(|q| (*q - p).length() <= tol) {
            out.push(p);
        }
    }
    out
}

fn oblique_box(seed: u64) -> ProxyBox {
    let mut rng = volmorph_testkit::Rng::new(seed);
    let mut r = || rng.unit();
    let axes = DMat3::from_cols(
        DVec3::new(3.0 + r(), 0.4 * r(), -0.3 * r()),
        DVec3::new(-0.5 * r(), 2.0 + r(), 0.2 * r()),
        DVec3::new(0.3 * r(), -0.2 * r(), 1.5 + r()),
    );
    ProxyBox {
        origin: DVec3::new(r() * 5.0 - 2.0, r() * 3.0, -r()),
        axes,
        tex_origin: DVec3::splat(0.1),
        tex_size: DVec3::new(0.5, 0.25, 0.75),
    }
}

fn check_box(bx: &ProxyBox, forward: DVec3, spacing: f64) -> Result<(), TestCaseError> {
    let slicing = Slicing::new(forward, spacing).unwrap();
    let f = slicing.forward();
    let cuts: Vec<ProxyGeometry> = METHODS
        .iter()
        .map(|&m| {
            let mut g = ProxyGeometry::default();
            cut_box(bx, &slicing, m, &mut g);
            g
        })
        .collect();
    let scale = bx
        .axes
        .to_cols_array()
        .iter()
        .fold(0.0f64, |a, &x| a.max(x.abs()));
    let tol = 1e-5 * scale.max(1.0);
    // Planes in the same order, one polygon each, back to front.
    let planes: Vec<Vec<i64>> = cuts
        .iter()
        .map(|g| g.polygons.iter().map(|p| p.plane).collect())
        .collect();
    prop_assert_eq!(&planes[0], &planes[1]);
    prop_assert_eq!(&planes[0], &planes[2]);
    prop_assert!(
        planes[0].windows(2).all(|w| w[0] < w[1]),
        "planes not back to front"
    );
    let corners = bx.corners();
    let (smin, smax) = corners
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), c| {
            (a.min(-f.dot(*c)), b.max(-f.dot(*c)))
        });
    let expected = ((smax / spacing).ceil() - (smin / spacing).ceil()) as i64;
    prop_assert!(
        (planes[0].len() as i64 - expected).abs() <= 1,
        "{} planes, expected {expected}",
        planes[0].len()
    );
    let inv = bx.axes.inverse();
    for (n, &k) in planes[0].iter().enumerate() {
        let s = k as f64 * spacing;
        let want = section_area(bx, f, s);
        let mut reference: Option<Vec<DVec3>> = None;
        for (g, method) in cuts.iter().zip(METHODS) {
            let p = &g.polygons[n];
            let pts = polygon(g, p);
            let av = area_vector(&pts);
            // Union is the section: the area matches the independent formula.
            prop_assert!(
                (av.length() - want).abs() <= 1e-4 * want.max(scale * scale * 1e-2),
                "{method:?} plane {k}: area {} vs {want}",
                av.length()
            );
            // Counter-clockwise from the eye: the normal points back along the view.
            prop_assert!(av.dot(-f) > 0.0, "{method:?} plane {k}: clockwise");
            for (i, q) in pts.iter().enumerate() {
                // On the plane, inside the box, texture coordinate consistent.
                prop_assert!(
                    (-f.dot(*q) - s).abs() <= tol,
                    "{method:?}: vertex off its plane"
                );
                let w = inv * (*q - bx.origin);
                prop_assert!(
                    w.min_element() >= -1e-6 && w.max_element() <= 1.0 + 1e-6,
                    "{method:?}: vertex outside the box {w}"
                );
                let t = g.texcoord(p.first_vertex as usize + i);
                prop_assert!((t - (bx.tex_origin + bx.tex_size * w)).length() <= 1e-5);
            }
            // The same polygon for every method (RSK repeats vertices).
            let d = distinct(&pts, tol);
            match &reference {
                None => reference = Some(d),
                Some(r) => {
                    prop_assert_eq!(r.len(), d.len(), "{:?} plane {}: vertex count", method, k);
                    for q in &d {
                        prop_assert!(
                            r.iter().any(|x| (*x - *q).length() <= 10.0 * tol),
                            "{method:?}: vertex {q} not in the sweep's polygon"
                        );
                    }
                }
            }
        }
    }
    // Index buffers: fans of each polygon.
    for g in &cuts {
        let tris: usize = g.polygons.iter().map(|p| p.vertex_count as usize - 2).sum();
        prop_assert_eq!(g.indices.len(), 3 * tris);
        prop_assert_eq!(g.vertices.len(), VERTEX_FLOATS * g.vertex_count());
        prop_assert!(g.indices.iter().all(|&i| (i as usize) < g.vertex_count()));
    }
    Ok(())
}

#[test]
fn a_unit_cube_seen_along_an_axis_gives_squares() {
    let bx = ProxyBox {
        origin: DVec3::ZERO,
        axes: DMat3::IDENTITY,
        tex_origin: DVec3::ZERO,
        tex_size: DVec3::ONE,
    };
    for m in METHODS {
        let mut g = ProxyGeometry::default();
        cut_box(&bx, &Slicing::new(DVec3::NEG_Z, 0.25).unwrap(), m, &mut g);
        // Planes z = 0, 0.25, 0.5, 0.75 (z = 1 is the far end of [s_min, s_max)).
        assert_eq!(g.polygons.len(), 4, "{m:?}");
        for p in &g.polygons {
            let pts = distinct(&polygon(&g, p), 1e-9);
            assert_eq!(pts.len(), 4, "{m:?}: {pts:?}");
            assert!((area_vector(&polygon(&g, p)).length() - 1.0).abs() < 1e-9);
        }
    }
    // Looking down −z the eye is at +z, s = z: back to front is increasing z.
    let mut g = ProxyGeometry::default();
    cut_box(
        &bx,
        &Slicing::new(DVec3::NEG_Z, 0.25).unwrap(),
        CutMethod::Sweep,
        &mut g,
    );
    let z: Vec<f64> = g
        .polygons
        .iter()
        .map(|p| g.position(p.first_vertex as usize).z)
        .collect();
    assert_eq!(z, vec![0.0, 0.25, 0.5, 0.75]);
}

#[test]
fn every_patch_of_view_directions_agrees() {
    // Directions near the centre of each of the 96 patches and on their boundaries.
    let bx = oblique_box(7);
    let cube = ProxyBox {
        origin: DVec3::new(-0.3, 0.2, 0.1),
        axes: DMat3::IDENTITY * 2.0,
        tex_origin: DVec3::ZERO,
        tex_size: DVec3::ONE,
    };
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            for sz in [-1.0, 1.0] {
                for mags in [
                    [3.0, 2.0, 1.5],
                    [3.0, 1.5, 2.0],
                    [2.0, 3.0, 1.5],
                    [1.5, 3.0, 2.0],
                    [2.0, 1.5, 3.0],
                    [1.5, 2.0, 3.0],
                    [5.0, 2.0, 1.0],
                    [5.0, 1.0, 2.0],
                    [2.0, 5.0, 1.0],
                    [1.0, 5.0, 2.0],
                    [2.0, 1.0, 5.0],
                    [1.0, 2.0, 5.0],
                    [1.0, 1.0, 1.0],
                    [1.0, 1.0, 0.0],
                    [1.0, 0.0, 0.0],
                    [2.0, 1.0, 1.0],
                ] {
                    let f = DVec3::new(sx * mags[0], sy * mags[1], sz * mags[2]);
                    check_box(&cube, f, 0.137).unwrap();
                    check_box(&bx, f, 0.21).unwrap();
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]
    #[test]
    fn cut_methods_agree_and_cover_the_section(
        f in proptest::array::uniform3(-1.0f64..1.0),
        seed in any::<u64>(),
        spacing in 0.05f64..1.0,
        mirror in any::<bool>(),
    ) {
        let f = DVec3::from_array(f);
        prop_assume!(f.length() > 0.05);
        let mut bx = oblique_box(seed);
        if mirror {
            // A left-handed box (a reflected volume direction): orientation still CCW.
            bx.axes = DMat3::from_cols(bx.axes.y_axis, bx.axes.x_axis, bx.axes.z_axis);
        }
        check_box(&bx, f, spacing)?;
    }
}

/// A mostly empty volume with a ball of value 1000.
fn ball_volume() -> DvrVolume {
    let g = Geometry::new([33, 29, 25])
        .with_spacing(DVec3::new(1.0, 1.2, 1.5))
        .with_direction(DMat3::from_rotation_z(0.3))
        .with_origin(DVec3::new(-10.0, 5.0, 2.0));
    let v = Volume::<i16>::from_fn(g, |i, j, k| {
        let p = DVec3::new(i as f64 - 20.0, j as f64 - 12.0, (k as f64 - 14.0) * 1.2);
        if p.length() < 6.0 { 1000 } else { 0 }
    })
    .unwrap();
    DvrVolume::from_volume(&v).unwrap()
}

#[test]
fn octree_culled_cutting_covers_the_visible_bricks_and_nothing_else() {
    let dv = ball_volume();
    let tf = TransferFunction::parse("0:0,0,0,0; 500:1,1,1,0.5; 1000:1,1,1,1").unwrap();
    let r = DvrRenderer::new(&dv, DvrOptions::new(tf)).unwrap();
    let forward = DVec3::new(0.3, -0.5, 0.8);
    let slicing = Slicing::across(forward, &dv.geometry().corner_points(), 64).unwrap();
    let f = slicing.forward();
    for level in 0..dv.octree().level_count() {
        let mut all = ProxyGeometry::default();
        cut_octree(&dv, None, level, &slicing, CutMethod::Sweep, &mut all).unwrap();
        let culled = r.proxy_geometry(&slicing, level, CutMethod::Sweep).unwrap();
        // Without culling, each plane's polygons add up to the volume box's section.
        let whole = ProxyBox::of_cells(&dv, DVec3::ZERO, DVec3::new(32.0, 28.0, 24.0));
        let mut by_plane = std::collections::BTreeMap::<i64, f64>::new();
        for p in &all.polygons {
            *by_plane.entry(p.plane).or_default() += area_vector(&polygon(&all, p)).length();
        }
        for (&k, &area) in &by_plane {
            let want = section_area(&whole, f, k as f64 * slicing.spacing());
            assert!(
                (area - want).abs() <= 1e-6 * want.max(1.0),
                "level {level} plane {k}: {area} vs {want}"
            );
        }
        // Culling keeps every polygon through the ball, and drops most of the rest.
        let inside_ball = |g: &ProxyGeometry, p: &ProxyPolygon| {
            polygon(g, p).iter().any(|q| {
                let u = dv.index_of(*q);
                let c = DVec3::new(u.x - 20.0, u.y - 12.0, (u.z - 14.0) * 1.2);
                c.length() < 5.0
            })
        };
        let kept: usize = culled
            .polygons
            .iter()
            .filter(|p| inside_ball(&culled, p))
            .count();
        let needed: usize = all.polygons.iter().filter(|p| inside_ball(&all, p)).count();
        assert_eq!(
            kept, needed,
            "level {level}: a polygon through the ball was culled"
        );
        if level <= 1 {
            assert!(
                culled.polygons.len() * 2 < all.polygons.len(),
                "level {level}: little culled"
            );
        }
        // Texture coordinates address the voxel under each vertex.
        for i in 0..culled.vertex_count() {
            let n = DVec3::new(33.0, 29.0, 25.0);
            let u = dv.index_of(culled.position(i));
            assert!((culled.texcoord(i) * n - DVec3::splat(0.5) - u).length() < 1e-3);
        }
    }
    assert!(
        cut_octree(
            &dv,
            None,
            99,
            &slicing,
            CutMethod::Sweep,
            &mut ProxyGeometry::default()
        )
        .is_err()
    );
}

#[test]
fn bricks_come_back_to_front() {
    let dv = ball_volume();
    for forward in [
        DVec3::new(-0.4, 0.7, 0.6),
        DVec3::new(0.9, 0.1, -0.3),
        DVec3::NEG_Z,
    ] {
        let slicing = Slicing::across(forward, &dv.geometry().corner_points(), 40).unwrap();
        let level = 1;
        let node = (dv.octree().brick() << level) as f64;
        let mut g = ProxyGeometry::default();
        cut_octree(&dv, None, level, &slicing, CutMethod::Sweep, &mut g).unwrap();
        // The brick of each polygon, from its centroid.
        let brick = |p: &ProxyPolygon| {
            let c = polygon(&g, p).iter().sum::<DVec3>() / f64::from(p.vertex_count);
            let u = dv.index_of(c) / node;
            [u.x.floor() as i64, u.y.floor() as i64, u.z.floor() as i64]
        };
        let seq: Vec<[i64; 3]> = g.polygons.iter().map(brick).collect();
        let mut first = std::collections::HashMap::new();
        let mut last = std::collections::HashMap::new();
        for (i, b) in seq.iter().enumerate() {
            first.entry(*b).or_insert(i);
            last.insert(*b, i);
        }
        // Each brick's polygons are contiguous...
        for (b, &f0) in &first {
            assert!(
                seq[f0..=last[b]].iter().all(|x| x == b),
                "brick {b:?} interleaved"
            );
        }
        // ...and of two face neighbours, the one further along the view comes first.
        let f_index = dv.index_of(dv.geometry().origin + slicing.forward())
            - dv.index_of(dv.geometry().origin);
        for (&a, &ia) in &first {
            for axis in 0..3 {
                let mut b = a;
                b[axis] += 1;
                let Some(&ib) = first.get(&b) else { continue };
                // b lies at +axis from a: it is further along the view when f_index[axis] > 0.
                if f_index[axis] > 1e-12 {
                    assert!(ib < ia, "{forward}: brick {b:?} (behind) drawn after {a:?}");
                } else if f_index[axis] < -1e-12 {
                    assert!(ia < ib, "{forward}: brick {a:?} (behind) drawn after {b:?}");
                }
            }
        }
    }
}

#[test]
fn bad_slicing_is_refused() {
    assert!(Slicing::new(DVec3::ZERO, 1.0).is_err());
    assert!(Slicing::new(DVec3::X, 0.0).is_err());
    assert!(Slicing::new(DVec3::X, f64::NAN).is_err());
    assert!(Slicing::across(DVec3::X, &[DVec3::ZERO, DVec3::ONE], 0).is_err());
    assert!(Slicing::across(DVec3::X, &[DVec3::ZERO, DVec3::Y], 10).is_err());
}
