//! Accuracy of the optical path tracers against the GRIN lens's exact meridional trace
//! (`exact_back_focal_distance`: the axial optical momentum is conserved, so a meridional ray
//! obeys a one-dimensional ODE in z that shares no code with the three-dimensional tracer).

use volmorph_trivariate::{
    GRIN_ATTRIBUTE, GrinLensSpec, OpticsOptions, PathMethod, RayTracer, TraceOptions,
    check_grin_lens, exact_back_focal_distance, grin_lens, paraxial_focus, reference_options,
    trace_optical_path,
};

fn lens() -> (
    GrinLensSpec,
    volmorph_trivariate::AggregateVolume,
    RayTracer,
) {
    let spec = GrinLensSpec::default();
    let lens = grin_lens(&spec).unwrap();
    let tracer = RayTracer::new(&lens, TraceOptions::default()).unwrap();
    (spec, lens, tracer)
}

/// Relative difference of the probe's measured back focal distance from the exact trace.
fn probe_error(o: &OpticsOptions) -> (f64, usize) {
    let (spec, lens, tracer) = lens();
    let check = check_grin_lens(&lens, &tracer, GRIN_ATTRIBUTE, &spec, o).unwrap();
    let (m, exact) = check.measured.unwrap();
    assert_eq!(m.height, 0.02 * spec.radius);
    assert_eq!(exact.height, m.height);
    (
        (m.back_focal_distance - exact.back_focal_distance) / exact.back_focal_distance,
        m.steps,
    )
}

#[test]
fn exact_trace_is_converged_and_tends_to_the_paraxial_focus() {
    let spec = GrinLensSpec::default();
    let paraxial = paraxial_focus(&spec).unwrap().back_focal_distance;
    let mut last: Option<f64> = None;
    for h in [0.04, 0.02, 0.01, 0.005] {
        let e = exact_back_focal_distance(&spec, h).unwrap();
        assert!(e.error_estimate < 1e-14, "{e:?}");
        // Spherical aberration: the focus moves towards the lens by c·h² (c < 0).
        let dev = e.back_focal_distance - paraxial;
        assert!(dev < 0.0, "{e:?}");
        if let Some(prev) = last {
            let ratio = prev / dev;
            assert!((ratio - 4.0).abs() < 0.01, "h {h}: ratio {ratio}");
        }
        last = Some(dev);
    }
    assert!(exact_back_focal_distance(&spec, 0.0).is_err());
    assert!(exact_back_focal_distance(&spec, 1.5).is_err());
}

#[test]
fn rk45_default_meets_the_focus_of_the_exact_trace() {
    let (_, _, tracer) = lens();
    let (err, steps) = probe_error(&OpticsOptions::for_diagonal(tracer.diagonal()));
    // The bound is 0.05 %; the integrator is far inside it.
    assert!(err.abs() < 5e-4, "{err:e}");
    assert!(err.abs() < 1e-8, "{err:e}");
    assert!(steps > 0);
    let (err, _) = probe_error(&reference_options(tracer.diagonal()));
    assert!(err.abs() < 1e-10, "reference trace {err:e}");
}

#[test]
fn rk45_steps_adapt_to_the_tolerance() {
    // No step cap: the controller alone sets the steps. Tighter tolerances take more steps and
    // get closer, by about the tolerance (the lens is one unit long).
    let (_, _, tracer) = lens();
    let mut last = (f64::INFINITY, 0);
    for tol in [1e-5, 1e-7, 1e-9, 1e-11] {
        let o = OpticsOptions {
            tolerance: tol,
            max_step: tracer.diagonal(),
            ..OpticsOptions::for_diagonal(tracer.diagonal())
        };
        let (err, steps) = probe_error(&o);
        assert!(err.abs() < 100.0 * tol, "tol {tol}: {err:e}");
        assert!(
            err.abs() < last.0 && steps > last.1,
            "tol {tol}: {err:e}, {steps} steps"
        );
        last = (err.abs(), steps);
    }
}

#[test]
fn stepwise_methods_are_first_order() {
    // Halving the step halves the ray-equation form's error; Richardson extrapolation of the
    // two lands much closer to the exact trace. The literal Snell update stalls (far off).
    let (_, _, tracer) = lens();
    let at = |method, h: f64| {
        probe_error(&OpticsOptions {
            method,
            max_step: h,
            min_step: h / 100.0,
            ..OpticsOptions::for_diagonal(tracer.diagonal())
        })
        .0
    };
    let (e1, e2) = (
        at(PathMethod::RayEquation, 0.01),
        at(PathMethod::RayEquation, 0.005),
    );
    assert!(e1 > 5e-4 && e2 > 5e-4, "{e1:e} {e2:e}");
    let ratio = e1 / e2;
    assert!((ratio - 2.0).abs() < 0.1, "ratio {ratio}");
    let richardson = 2.0 * e2 - e1;
    assert!(richardson.abs() < 0.05 * e2, "{richardson:e} vs {e2:e}");
    assert!(at(PathMethod::Snell, 0.005) > 0.05);
}

#[test]
fn rays_far_from_the_axis_follow_the_exact_trace() {
    // Beyond the paraxial region (aberration of 3–27 %) the integrator still agrees with the
    // exact meridional trace.
    let (spec, lens, tracer) = lens();
    let o = OpticsOptions::for_diagonal(tracer.diagonal());
    let phi: f64 = 0.3;
    let radial = [phi.cos(), phi.sin(), 0.0];
    for h in [0.3, 0.6, 0.85] {
        let exact = exact_back_focal_distance(&spec, h)
            .unwrap()
            .back_focal_distance;
        let origin = [h * radial[0], h * radial[1], -0.5];
        let p = trace_optical_path(&lens, &tracer, GRIN_ATTRIBUTE, origin, [0.0, 0.0, 1.0], &o)
            .unwrap();
        let (e, v) = p.exit.unwrap();
        assert!((e[2] - spec.thickness).abs() < 1e-8, "{e:?}");
        let re = e[0] * radial[0] + e[1] * radial[1];
        let vr = v[0] * radial[0] + v[1] * radial[1];
        let bfd = e[2] + (-re / vr) * v[2] - spec.thickness;
        assert!(
            ((bfd - exact) / exact).abs() < 1e-8,
            "h {h}: {bfd} vs {exact}"
        );
    }
}
