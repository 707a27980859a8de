//! Ray tracing, volume rendering and optical path tracing (Martin & Cohen §5.2–§5.4).

#![allow(clippy::needless_range_loop)]

use glam::DVec3;
use volmorph_spline::{KnotVector, TensorBSpline};
use volmorph_testkit::Rng;
use volmorph_trivariate::{
    AggregateVolume, GRIN_ATTRIBUTE, GrinLensSpec, HitKind, OpticsOptions, PathMethod, RayTracer,
    RenderOptions, TraceOptions, TransferFunction, TransferPoint, TrivariateError, VolumeRenderer,
    grin_lens, paraxial_focus, refract, trace_optical_path,
};

/// Trilinear box `[0, sx] × [0, sy] × [0, sz]` (identity parametrisation, scaled).
fn box_geometry(s: [f64; 3]) -> TensorBSpline<3> {
    let kv = KnotVector::bezier(1, [0.0, 1.0]).unwrap();
    let mut pts = Vec::new();
    for k in 0..2 {
        for j in 0..2 {
            for i in 0..2 {
                pts.extend([
                    s[0] * f64::from(i),
                    s[1] * f64::from(j),
                    s[2] * f64::from(k),
                ]);
            }
        }
    }
    TensorBSpline::new([kv.clone(), kv.clone(), kv], 3, pts).unwrap()
}

/// A constant scalar attribute.
fn constant(value: f64) -> TensorBSpline<3> {
    let kv = KnotVector::bezier(0, [0.0, 1.0]).unwrap();
    TensorBSpline::new([kv.clone(), kv.clone(), kv], 1, vec![value]).unwrap()
}

/// A smooth rational tricubic volume (deformed cube, weights ≠ 1).
fn curved() -> TensorBSpline<3> {
    let kv = KnotVector::clamped_uniform(3, 5, [0.0, 1.0]).unwrap();
    let mut pts = Vec::new();
    let mut ws = Vec::new();
    for k in 0..5 {
        for j in 0..5 {
            for i in 0..5 {
                let (x, y, z) = (f64::from(i), f64::from(j), f64::from(k));
                pts.extend([
                    x + 0.2 * (y * z).sin(),
                    y + 0.15 * (x * 1.3).cos(),
                    z + 0.1 * x * y / 4.0,
                ]);
                ws.push(1.0 + 0.1 * ((i + 2 * j + k) % 3) as f64);
            }
        }
    }
    TensorBSpline::new_rational([kv.clone(), kv.clone(), kv], 3, pts, ws).unwrap()
}

/// `x = 4u(1 − u)` (folded at `u = 1/2`, where `det J = 0`), `y = v`, `z = w`.
fn folded() -> TensorBSpline<3> {
    let k2 = KnotVector::bezier(2, [0.0, 1.0]).unwrap();
    let k1 = KnotVector::bezier(1, [0.0, 1.0]).unwrap();
    let mut pts = Vec::new();
    for k in 0..2 {
        for j in 0..2 {
            for x in [0.0, 2.0, 0.0] {
                pts.extend([x, f64::from(j), f64::from(k)]);
            }
        }
    }
    TensorBSpline::new([k2, k1.clone(), k1], 3, pts).unwrap()
}

fn on_ray(p: [f64; 3], o: [f64; 3], d: [f64; 3]) -> f64 {
    let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let d = d.map(|x| x / n);
    let w = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
    let t = w[0] * d[0] + w[1] * d[1] + w[2] * d[2];
    let q = [w[0] - t * d[0], w[1] - t * d[1], w[2] - t * d[2]];
    (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt()
}

fn det_j(g: &TensorBSpline<3>, u: [f64; 3]) -> (f64, f64) {
    let (_, j) = g.eval_with_gradient(u).unwrap();
    let c = |a: usize| [j[3 * a], j[3 * a + 1], j[3 * a + 2]];
    let (a, b, e) = (c(0), c(1), c(2));
    let cr = [
        b[1] * e[2] - b[2] * e[1],
        b[2] * e[0] - b[0] * e[2],
        b[0] * e[1] - b[1] * e[0],
    ];
    let n = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    (
        a[0] * cr[0] + a[1] * cr[1] + a[2] * cr[2],
        n(a) * n(b) * n(e),
    )
}

#[test]
fn hits_lie_on_the_boundary_of_a_curved_rational_volume() {
    let g = curved();
    let tracer = RayTracer::from_geometry(&g, TraceOptions::default()).unwrap();
    let scale = tracer.diagonal();
    let mut total = 0;
    let mut rng = Rng::new(40);
    for i in 0..40 {
        let target = rng
            .point_in(DVec3::splat(0.5), DVec3::splat(3.5))
            .to_array();
        let o = [rng.range(-4.0, -2.0), -2.5, rng.range(8.0, 10.0)];
        let d = [target[0] - o[0], target[1] - o[1], target[2] - o[2]];
        let hits = tracer.intersect(o, d).unwrap();
        // The target is inside, so the ray enters and leaves: at least two hits.
        assert!(hits.len() >= 2, "ray {i}: {hits:?}");
        assert!(hits.windows(2).all(|w| w[0].t <= w[1].t));
        for h in &hits {
            let p = g.eval(h.params).unwrap();
            for c in 0..3 {
                assert!((p[c] - h.point[c]).abs() <= 1e-12 * scale);
            }
            assert!(on_ray(h.point, o, d) <= 1e-9 * scale, "{h:?}");
            match h.kind {
                HitKind::Face { axis, side } => {
                    assert_eq!(h.params[axis], side as f64);
                }
                HitKind::Fold => {
                    let (det, s) = det_j(&g, h.params);
                    assert!(det.abs() <= 1e-8 * s);
                }
            }
            total += 1;
        }
    }
    assert!(total >= 80);
    // This volume does not fold: the cones prove det J ≠ 0 in every leaf… or keep few.
    let hits = tracer
        .intersect([-10.0, -10.0, -10.0], [-1.0, 0.0, 0.0])
        .unwrap();
    assert!(hits.is_empty());
}

#[test]
fn a_ray_through_a_box_gets_exactly_entry_and_exit() {
    let g = box_geometry([2.0, 1.0, 1.5]);
    let tracer = RayTracer::from_geometry(&g, TraceOptions::default()).unwrap();
    assert_eq!(tracer.fold_leaf_count(), 0, "a box cannot fold");
    let mut rng = Rng::new(30);
    for i in 0..30 {
        let target = rng
            .point_in(DVec3::splat(0.1), DVec3::new(1.9, 0.9, 1.4))
            .to_array();
        let o = [rng.range(-2.0, -1.0), rng.range(-3.0, 3.0), -2.0];
        let d = [target[0] - o[0], target[1] - o[1], target[2] - o[2]];
        let hits = tracer.intersect(o, d).unwrap();
        assert_eq!(hits.len(), 2, "ray {i}: {hits:?}");
        // Reference by the slab method.
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
        for (c, hi) in [2.0, 1.0, 1.5].into_iter().enumerate() {
            let dc = d[c] / n;
            let (a, b) = ((0.0 - o[c]) / dc, (hi - o[c]) / dc);
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
        assert!((hits[0].t - t0).abs() < 1e-10, "{} vs {t0}", hits[0].t);
        assert!((hits[1].t - t1).abs() < 1e-10, "{} vs {t1}", hits[1].t);
        assert!(matches!(hits[0].kind, HitKind::Face { .. }));
    }
    // A ray through an edge: the two faces' hits are one.
    let hits = tracer
        .intersect([-1.0, -1.0, 0.5], [1.0, 1.0, 0.0])
        .unwrap();
    assert_eq!(hits.len(), 2, "{hits:?}");
}

#[test]
fn jacobian_vanishing_boundary_is_found_on_a_folded_volume() {
    let g = folded();
    let tracer = RayTracer::from_geometry(&g, TraceOptions::default()).unwrap();
    assert!(tracer.fold_leaf_count() > 0);
    let o = [-1.0, 0.4, 0.7];
    let hits = tracer.intersect(o, [1.0, 0.0, 0.0]).unwrap();
    // x = 0 (faces u = 0 and u = 1, merged) and the fold x = 1 (u = 1/2).
    assert_eq!(hits.len(), 2, "{hits:?}");
    assert!((hits[0].t - 1.0).abs() < 1e-10);
    let fold = hits[1];
    assert!((fold.t - 2.0).abs() < 1e-9, "{fold:?}");
    assert!((fold.params[0] - 0.5).abs() < 1e-6, "{fold:?}");
    assert_eq!(fold.kind, HitKind::Fold);
    assert!(fold.normal[0] < -0.999, "{fold:?}");
}

/// Issue: `nurbs render --step 1e-9` had no lower bound and ran without end. The step is
/// now bounded below by the model's diagonal over the samples a ray may take.
#[test]
fn nurbs_render_step_has_no_lower_bound() {
    let g = box_geometry([1.0; 3]);
    let tracer = RayTracer::from_geometry(&g, TraceOptions::default()).unwrap();
    let v = AggregateVolume::new(g)
        .unwrap()
        .with_attribute("d", constant(1.0))
        .unwrap();
    let tf = TransferFunction::parse("0:1,1,1,0.5").unwrap();
    let base = RenderOptions::for_diagonal(tracer.diagonal());
    let tiny = RenderOptions { step: 1e-9, ..base };
    let e = VolumeRenderer::new(&v, &tracer, "d", tf.clone(), tiny).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("1e-9") && msg.contains("could not cross"),
        "{msg}"
    );
    // Just at the bound it is accepted.
    let min = tracer.diagonal() / base.max_samples as f64;
    let ok = RenderOptions {
        step: min * 1.0001,
        ..base
    };
    assert!(VolumeRenderer::new(&v, &tracer, "d", tf.clone(), ok).is_ok());
    // Rendering reports rows and can be cancelled.
    let r = VolumeRenderer::new(&v, &tracer, "d", tf, base).unwrap();
    let cam = volmorph_render::Camera::look_at(
        glam::DVec3::new(3.0, 2.0, 4.0),
        glam::DVec3::splat(0.5),
        glam::DVec3::Z,
        volmorph_render::Projection::Perspective { fov_y: 0.8 },
        8,
        6,
    )
    .unwrap();
    let count = volmorph_io::progress::Counter::new();
    r.render_image_with(&cam, &count).unwrap();
    assert_eq!(count.steps(), 6);
    let stop = volmorph_io::progress::Counter::cancel_after(1);
    assert!(r.render_image_with(&cam, &stop).is_err());
}

#[test]
fn bad_rays_are_errors() {
    let g = box_geometry([1.0; 3]);
    let tracer = RayTracer::from_geometry(&g, TraceOptions::default()).unwrap();
    assert!(tracer.intersect([0.0; 3], [0.0; 3]).is_err());
    assert!(
        tracer
            .intersect([f64::NAN, 0.0, 0.0], [1.0, 0.0, 0.0])
            .is_err()
    );
    assert!(
        tracer
            .intersect([0.0; 3], [f64::INFINITY, 0.0, 0.0])
            .is_err()
    );
    let bad = TraceOptions {
        flatness: -1.0,
        ..TraceOptions::default()
    };
    assert!(RayTracer::from_geometry(&g, bad).is_err());
    let v = AggregateVolume::new(g)
        .unwrap()
        .with_attribute("d", constant(1.0))
        .unwrap();
    let tf = TransferFunction::parse("0:1,1,1,0.5").unwrap();
    let opts = RenderOptions::for_diagonal(tracer.diagonal());
    assert!(matches!(
        VolumeRenderer::new(&v, &tracer, "nope", tf.clone(), opts),
        Err(TrivariateError::UnknownAttribute(_))
    ));
    let r = VolumeRenderer::new(&v, &tracer, "d", tf, opts).unwrap();
    assert!(r.render_ray([0.0; 3], [0.0; 3]).is_err());
    let oo = OpticsOptions::for_diagonal(1.0);
    assert!(matches!(
        trace_optical_path(&v, &tracer, "eta", [-1.0; 3], [1.0; 3], &oo),
        Err(TrivariateError::UnknownAttribute(_))
    ));
    assert!(trace_optical_path(&v, &tracer, "d", [-1.0; 3], [0.0; 3], &oo).is_err());
    for bad in [
        "",
        "x:1,1,1,1",
        "0:1,1,1",
        "0:2,0,0,0.5",
        "0:1,1,1,1;0:0,0,0,0",
    ] {
        assert!(TransferFunction::parse(bad).is_err(), "{bad:?}");
    }
}

#[test]
fn compositing_a_constant_volume_is_beer_lambert() {
    let g = box_geometry([2.0, 1.0, 1.5]);
    let tracer = RayTracer::from_geometry(&g, TraceOptions::default()).unwrap();
    let v = AggregateVolume::new(g)
        .unwrap()
        .with_attribute("d", constant(0.7))
        .unwrap();
    let tf = TransferFunction::new(vec![TransferPoint {
        value: 0.7,
        color: [0.2, 0.6, 1.0],
        opacity: 0.3,
    }])
    .unwrap();
    for step in [0.013, 0.1, 0.37] {
        let opts = RenderOptions {
            step,
            min_transmittance: 0.0,
            ..RenderOptions::for_diagonal(1.0)
        };
        let r = VolumeRenderer::new(&v, &tracer, "d", tf.clone(), opts).unwrap();
        let o = [-1.0, -0.5, 0.2];
        let d = [3.0, 1.2, 0.9];
        let hits = tracer.intersect(o, d).unwrap();
        let chord = hits[1].t - hits[0].t;
        let c = r.render_ray(o, d).unwrap();
        let want = 1.0 - 0.7f64.powf(chord);
        assert!((c.opacity - want).abs() < 1e-9, "{} vs {want}", c.opacity);
        for (k, ch) in [0.2, 0.6, 1.0].into_iter().enumerate() {
            assert!((c.color[k] - ch * want).abs() < 1e-9);
        }
    }
}

#[test]
fn compositing_matches_a_brute_force_reference() {
    // Attribute a = x on the box [0, 2] × [0, 1]², transfer red → blue with rising opacity.
    let s = [2.0, 1.0, 1.0];
    let g = box_geometry(s);
    let tracer = RayTracer::from_geometry(&g, TraceOptions::default()).unwrap();
    let k1 = KnotVector::bezier(1, [0.0, 1.0]).unwrap();
    let k0 = KnotVector::bezier(0, [0.0, 1.0]).unwrap();
    let attr = TensorBSpline::new([k1, k0.clone(), k0], 1, vec![0.0, 2.0]).unwrap();
    let v = AggregateVolume::new(g)
        .unwrap()
        .with_attribute("x", attr)
        .unwrap();
    let tf = TransferFunction::parse("0:1,0,0,0.1; 2:0,0,1,0.8").unwrap();
    let step = 0.01;
    let opts = RenderOptions {
        step,
        min_transmittance: 0.0,
        ..RenderOptions::for_diagonal(1.0)
    };
    let r = VolumeRenderer::new(&v, &tracer, "x", tf.clone(), opts).unwrap();
    let o = [-0.5, 0.1, 0.3];
    let d0: [f64; 3] = [1.0, 0.3, 0.2];
    let n = (d0[0] * d0[0] + d0[1] * d0[1] + d0[2] * d0[2]).sqrt();
    let d = d0.map(|x| x / n);
    let got = r.render_ray(o, d0).unwrap();
    // Reference: samples at the same positions from the analytic attribute.
    let (t0, t1) = (0.5 / d[0], (1.0 - o[1]) / d[1]);
    let t1 = t1.min(2.5 / d[0]).min((1.0 - o[2]) / d[2]);
    let (mut c, mut tr) = ([0.0; 3], 1.0);
    let mut t = t0;
    while t < t1 {
        let len = step.min(t1 - t);
        let x = o[0] + t * d[0];
        let (col, a1) = tf.lookup(x);
        let a = 1.0 - (1.0f64 - a1).powf(len);
        for k in 0..3 {
            c[k] += tr * a * col[k];
        }
        tr *= 1.0 - a;
        t += step;
    }
    assert!((got.opacity - (1.0 - tr)).abs() < 1e-9, "{got:?} vs {tr}");
    for k in 0..3 {
        assert!((got.color[k] - c[k]).abs() < 1e-9, "{got:?} vs {c:?}");
    }
}

#[test]
fn rendering_walks_across_the_seam_and_axis_of_a_revolved_volume() {
    let spec = GrinLensSpec::default();
    let lens = grin_lens(&spec).unwrap();
    let tracer = RayTracer::new(&lens, TraceOptions::default()).unwrap();
    // Constant opacity over the whole index range: the result depends on the chord only.
    let tf = TransferFunction::new(vec![TransferPoint {
        value: 1.3,
        color: [1.0, 1.0, 1.0],
        opacity: 0.4,
    }])
    .unwrap();
    let opts = RenderOptions {
        step: 0.02,
        min_transmittance: 0.0,
        ..RenderOptions::for_diagonal(1.0)
    };
    let r = VolumeRenderer::new(&lens, &tracer, GRIN_ATTRIBUTE, tf, opts).unwrap();
    // In the plane z = 0.5, crossing the seam half-plane y = 0, x > 0 at x = 0.5.
    let o = [-1.5, -0.5, 0.5];
    let d = [1.0, 0.25, 0.0];
    let hits = tracer.intersect(o, d).unwrap();
    assert!(
        hits.iter()
            .any(|h| matches!(h.kind, HitKind::Face { axis: 1, .. })),
        "the seam face is among the hits: {hits:?}"
    );
    let b = (-1.5f64 * 0.25 + 0.5).abs() / 1.0625f64.sqrt();
    let chord = 2.0 * (1.0 - b * b).sqrt();
    let c = r.render_ray(o, d).unwrap();
    let want = 1.0 - 0.6f64.powf(chord);
    assert!((c.opacity - want).abs() < 1e-7, "{} vs {want}", c.opacity);
    // Through the axis itself.
    let c = r.render_ray([-2.0, 0.0, 0.3], [1.0, 0.0, 0.0]).unwrap();
    let want = 1.0 - 0.6f64.powf(2.0);
    assert!((c.opacity - want).abs() < 1e-7, "{} vs {want}", c.opacity);
}

#[test]
fn snell_refraction_and_reflection() {
    // 30° incidence from air into glass.
    let th0 = 30f64.to_radians();
    let v = [th0.sin(), 0.0, -th0.cos()];
    let (r, tir) = refract(v, [0.0, 0.0, 1.0], 1.0, 1.5);
    assert!(!tir);
    let th1 = (th0.sin() / 1.5).asin();
    assert!((r[0] - th1.sin()).abs() < 1e-15 && (r[2] + th1.cos()).abs() < 1e-15);
    // Normal orientation does not matter.
    assert_eq!(refract(v, [0.0, 0.0, -2.0], 1.0, 1.5).0, r);
    // Total internal reflection from glass at 60°.
    let th = 60f64.to_radians();
    let v = [th.sin(), 0.0, -th.cos()];
    let (r, tir) = refract(v, [0.0, 0.0, 1.0], 1.5, 1.0);
    assert!(tir);
    assert!((r[0] - th.sin()).abs() < 1e-15 && (r[2] - th.cos()).abs() < 1e-15);
    // No gradient or normal incidence: unchanged, never NaN.
    assert_eq!(refract(v, [0.0; 3], 1.5, 1.0).0, v);
    assert_eq!(
        refract([0.0, 0.0, 1.0], [0.0, 0.0, 3.0], 1.0, 2.0).0,
        [0.0, 0.0, 1.0]
    );
}

#[test]
fn rays_are_straight_in_constant_index_and_refract_at_flat_faces() {
    let g = box_geometry([2.0, 2.0, 1.0]);
    let tracer = RayTracer::from_geometry(&g, TraceOptions::default()).unwrap();
    let v = AggregateVolume::new(g)
        .unwrap()
        .with_attribute("eta", constant(1.5))
        .unwrap();
    let oo = OpticsOptions::for_diagonal(tracer.diagonal());
    // Normal incidence: one straight line.
    let p = trace_optical_path(&v, &tracer, "eta", [0.7, 1.1, -1.0], [0.0, 0.0, 1.0], &oo).unwrap();
    assert_eq!(p.entries, 1);
    for q in &p.points {
        assert!(
            (q[0] - 0.7).abs() < 1e-12 && (q[1] - 1.1).abs() < 1e-12,
            "{q:?}"
        );
    }
    // Oblique incidence on the face z = 0: Snell inside, original direction restored after the
    // parallel face z = 1.
    let th0 = 40f64.to_radians();
    let d = [th0.sin(), 0.0, th0.cos()];
    let p = trace_optical_path(&v, &tracer, "eta", [0.3, 1.0, -0.5], d, &oo).unwrap();
    let (exit, dir) = p.exit.unwrap();
    assert!((exit[2] - 1.0).abs() < 1e-9, "{exit:?}");
    for c in 0..3 {
        assert!((dir[c] - d[c]).abs() < 1e-12, "{dir:?}");
    }
    // Inside, the path is straight at the refracted angle.
    let entry = p.points[1];
    let th1 = (th0.sin() / 1.5).asin();
    let want_x = entry[0] + th1.tan() * 1.0;
    assert!((exit[0] - want_x).abs() < 1e-9, "{} vs {want_x}", exit[0]);
    for q in &p.points[1..p.points.len() - 1] {
        let x = entry[0] + th1.tan() * q[2];
        assert!((q[0] - x).abs() < 1e-9);
    }
}

#[test]
fn grin_lens_focal_length_matches_paraxial_optics() {
    let spec = GrinLensSpec::default();
    let lens = grin_lens(&spec).unwrap();
    let tracer = RayTracer::new(&lens, TraceOptions::default()).unwrap();
    let focus = paraxial_focus(&spec).unwrap();
    let oo = OpticsOptions::for_diagonal(tracer.diagonal());
    // Rays parallel to the axis in the meridional plane at azimuth 0.3 rad (off the seam).
    let phi: f64 = 0.3;
    let radial = [phi.cos(), phi.sin(), 0.0];
    for r0 in [0.03, 0.06] {
        let o = [r0 * radial[0], r0 * radial[1], -0.5];
        let p =
            trace_optical_path(&lens, &tracer, GRIN_ATTRIBUTE, o, [0.0, 0.0, 1.0], &oo).unwrap();
        let (e, v) = p.exit.unwrap();
        assert!((e[2] - spec.thickness).abs() < 1e-9, "{e:?}");
        let re = e[0] * radial[0] + e[1] * radial[1];
        let vr = v[0] * radial[0] + v[1] * radial[1];
        // The ray stays in its meridional plane.
        assert!((e[0] * radial[1] - e[1] * radial[0]).abs() < 1e-9);
        let s = -re / vr;
        let bfd = e[2] + s * v[2] - spec.thickness;
        let efl = r0 / (-vr / v[2]);
        let rel_b = (bfd - focus.back_focal_distance).abs() / focus.back_focal_distance;
        let rel_e = (efl - focus.effective_focal_length).abs() / focus.effective_focal_length;
        assert!(
            rel_b < 0.02,
            "r0 {r0}: BFD {bfd} vs {}",
            focus.back_focal_distance
        );
        assert!(
            rel_e < 0.02,
            "r0 {r0}: EFL {efl} vs {}",
            focus.effective_focal_length
        );
        // The paper's literal Snell update also focuses, later (it stalls at grazing entry).
        let literal = OpticsOptions {
            method: PathMethod::Snell,
            ..oo
        };
        let p = trace_optical_path(&lens, &tracer, GRIN_ATTRIBUTE, o, [0.0, 0.0, 1.0], &literal)
            .unwrap();
        let (e, v) = p.exit.unwrap();
        let vr = v[0] * radial[0] + v[1] * radial[1];
        let bfd_literal = e[2] + (-(e[0] * radial[0] + e[1] * radial[1]) / vr) * v[2] - 1.0;
        assert!(vr < 0.0 && bfd_literal > bfd, "{bfd_literal} vs {bfd}");
    }
}

#[test]
fn shading_lights_the_attribute_gradient_with_the_camera_light() {
    use volmorph_render::shading::{linear_to_srgb8, srgb8_to_linear};
    use volmorph_render::{Camera, Projection, Shading};
    // Attribute a = 2x on the box [0, 1]³ (gradient along +x, normal −x); camera on +x
    // looking down −x, so the normal (turned to the viewer) points at the camera.
    let g = box_geometry([1.0, 1.0, 1.0]);
    let tracer = RayTracer::from_geometry(&g, TraceOptions::default()).unwrap();
    let k1 = KnotVector::bezier(1, [0.0, 1.0]).unwrap();
    let k0 = KnotVector::bezier(0, [0.0, 1.0]).unwrap();
    let attr = TensorBSpline::new([k1, k0.clone(), k0], 1, vec![0.0, 2.0]).unwrap();
    let v = AggregateVolume::new(g)
        .unwrap()
        .with_attribute("a", attr)
        .unwrap();
    let tf = TransferFunction::parse("0:0.6,0.6,0.6,1; 2:0.6,0.6,0.6,1").unwrap();
    let cam = Camera::look_at(
        [3.0, 0.5, 0.5].into(),
        [0.5, 0.5, 0.5].into(),
        [0.0, 0.0, 1.0].into(),
        Projection::Orthographic { view_height: 0.5 },
        5,
        5,
    )
    .unwrap();
    let render = |shading: Option<Shading>| {
        let opts = RenderOptions {
            shading,
            ..RenderOptions::for_diagonal(1.0)
        };
        VolumeRenderer::new(&v, &tracer, "a", tf.clone(), opts)
            .unwrap()
            .render_image(&cam)
            .unwrap()
            .get(2, 2)
            .unwrap()
    };
    let plain = render(None);
    assert_eq!(plain[3], 255);
    assert_eq!(plain[0], linear_to_srgb8(0.6));
    // Light head-on (camera z): full diffuse, no highlight → the plain colour.
    let head_on = Shading {
        light: [0.0, 0.0, 1.0].into(),
        ambient: 0.3,
        specular: 0.0,
        ..Shading::default()
    };
    assert_eq!(render(Some(head_on)), plain);
    // Light from the picture's right, perpendicular to the normal: ambient only.
    let grazing = Shading {
        light: [1.0, 0.0, 0.0].into(),
        ..head_on
    };
    let c = render(Some(grazing));
    let want = linear_to_srgb8(0.3 * 0.6);
    assert!(c[0].abs_diff(want) <= 1, "{c:?} vs {want}");
    assert!(srgb8_to_linear(c[0]) < 0.5 * srgb8_to_linear(plain[0]));
}

/// A box `[lo, lo + size]` carrying the constant attribute `d`.
fn constant_box(lo: [f64; 3], size: [f64; 3], value: f64) -> AggregateVolume {
    let mut g = box_geometry(size);
    let pts: Vec<f64> = g
        .control_points()
        .chunks_exact(3)
        .flat_map(|p| [p[0] + lo[0], p[1] + lo[1], p[2] + lo[2]])
        .collect();
    g = TensorBSpline::new(g.knots().clone(), 3, pts).unwrap();
    AggregateVolume::new(g)
        .unwrap()
        .with_attribute("d", constant(value))
        .unwrap()
}

fn flat_transfer(value: f64, color: [f64; 3], opacity: f64) -> TransferFunction {
    TransferFunction::new(vec![TransferPoint {
        value,
        color,
        opacity,
    }])
    .unwrap()
}

#[test]
fn a_scene_of_separate_volumes_equals_each_volume_alone() {
    use volmorph_render::{Camera, Projection};
    use volmorph_trivariate::SceneRenderer;
    let a = constant_box([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], 1.0);
    let b = constant_box([2.0, 0.2, -0.5], [1.0, 0.6, 2.0], 2.0);
    let ta = RayTracer::new(&a, TraceOptions::default()).unwrap();
    let tb = RayTracer::new(&b, TraceOptions::default()).unwrap();
    let opts = RenderOptions {
        shading: Some(volmorph_render::Shading::default()),
        ..RenderOptions::for_diagonal(1.0)
    };
    let ra =
        VolumeRenderer::new(&a, &ta, "d", flat_transfer(1.0, [1.0, 0.2, 0.1], 0.6), opts).unwrap();
    let rb =
        VolumeRenderer::new(&b, &tb, "d", flat_transfer(2.0, [0.1, 0.3, 1.0], 0.4), opts).unwrap();
    // Looking down −z at both boxes, side by side in the picture.
    let cam = Camera::look_at(
        [1.5, 0.5, 5.0].into(),
        [1.5, 0.5, 0.0].into(),
        [0.0, 1.0, 0.0].into(),
        Projection::Orthographic { view_height: 2.0 },
        48,
        32,
    )
    .unwrap();
    let scene = SceneRenderer::new(vec![ra.clone(), rb.clone()]).unwrap();
    let both = scene.render_image(&cam).unwrap();
    let only_a = ra.render_image(&cam).unwrap();
    let only_b = rb.render_image(&cam).unwrap();
    let (mut na, mut nb) = (0, 0);
    for y in 0..32 {
        for x in 0..48 {
            let (pa, pb, p) = (
                only_a.get(x, y).unwrap(),
                only_b.get(x, y).unwrap(),
                both.get(x, y).unwrap(),
            );
            assert!(pa[3] == 0 || pb[3] == 0, "the boxes overlap at {x},{y}");
            if pa[3] > 0 {
                assert_eq!(p, pa, "{x},{y}");
                na += 1;
            } else {
                assert_eq!(p, pb, "{x},{y}");
                nb += usize::from(pb[3] > 0);
            }
        }
    }
    assert!(na > 50 && nb > 50, "{na} {nb}");
    // A scene of one volume is that volume.
    let one = SceneRenderer::new(vec![ra]).unwrap();
    assert_eq!(one.render_image(&cam).unwrap().pixels(), only_a.pixels());
    assert!(SceneRenderer::new(Vec::new()).is_err());
}

#[test]
fn a_near_opaque_volume_hides_a_far_one_whatever_the_list_order() {
    use volmorph_trivariate::SceneRenderer;
    let near = constant_box([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], 1.0);
    let far = constant_box([-0.5, -0.5, 3.0], [2.0, 2.0, 1.0], 2.0);
    let tn = RayTracer::new(&near, TraceOptions::default()).unwrap();
    let tf = RayTracer::new(&far, TraceOptions::default()).unwrap();
    let opts = RenderOptions::for_diagonal(1.0);
    let red = [1.0, 0.0, 0.0];
    let blue = [0.0, 0.0, 1.0];
    let rn = VolumeRenderer::new(&near, &tn, "d", flat_transfer(1.0, red, 1.0), opts).unwrap();
    let rf = VolumeRenderer::new(&far, &tf, "d", flat_transfer(2.0, blue, 0.5), opts).unwrap();
    for parts in [vec![rn.clone(), rf.clone()], vec![rf.clone(), rn.clone()]] {
        let scene = SceneRenderer::new(parts).unwrap();
        // From below (−z) the near box is in front: opaque red only.
        let c = scene.render_ray([0.5, 0.5, -2.0], [0.0, 0.0, 1.0]).unwrap();
        assert_eq!(c.color, [1.0, 0.0, 0.0]);
        assert_eq!(c.opacity, 1.0);
        // From above (+z) the far box comes first: its blue (opacity 1 − 0.5¹), then the red
        // box behind it fills the rest.
        let c = scene.render_ray([0.5, 0.5, 6.0], [0.0, 0.0, -1.0]).unwrap();
        assert!((c.color[2] - 0.5).abs() < 1e-9, "{c:?}");
        assert!((c.color[0] - 0.5).abs() < 1e-9, "{c:?}");
        // Beside the near box only the far one is hit.
        let c = scene.render_ray([1.3, 1.3, -2.0], [0.0, 0.0, 1.0]).unwrap();
        assert_eq!(c, rf.render_ray([1.3, 1.3, -2.0], [0.0, 0.0, 1.0]).unwrap());
    }
}

#[test]
fn interpenetrating_volumes_attenuate_by_the_whole_overlap() {
    // Boxes z ∈ [0, 2] and z ∈ [1, 3] on one ray: Beer–Lambert over the union, whatever the
    // sample interleaving — T = (1 − α₁)² (1 − α₂)².
    use volmorph_trivariate::SceneRenderer;
    let a = constant_box([0.0, 0.0, 0.0], [1.0, 1.0, 2.0], 1.0);
    let b = constant_box([0.0, 0.0, 1.0], [1.0, 1.0, 2.0], 1.0);
    let ta = RayTracer::new(&a, TraceOptions::default()).unwrap();
    let tb = RayTracer::new(&b, TraceOptions::default()).unwrap();
    let opts = RenderOptions {
        min_transmittance: 0.0,
        ..RenderOptions::for_diagonal(1.0)
    };
    let ra = VolumeRenderer::new(&a, &ta, "d", flat_transfer(1.0, [1.0; 3], 0.3), opts).unwrap();
    let rb = VolumeRenderer::new(&b, &tb, "d", flat_transfer(1.0, [1.0; 3], 0.2), opts).unwrap();
    let scene = SceneRenderer::new(vec![ra, rb]).unwrap();
    let c = scene.render_ray([0.4, 0.6, -1.0], [0.0, 0.0, 1.0]).unwrap();
    let want = 1.0 - 0.7f64.powi(2) * 0.8f64.powi(2);
    assert!((c.opacity - want).abs() < 1e-9, "{} vs {want}", c.opacity);
    // White light: the colour equals the opacity (premultiplied).
    assert!((c.color[0] - want).abs() < 1e-9);
}
