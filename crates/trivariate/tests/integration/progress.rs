//! Isosurface, slice and fit report their steps exactly, can be cancelled, and give with
//! progress the same result as without, bit for bit.

use glam::DVec3;
use volmorph_testkit::progress;
use volmorph_trivariate::fit::{fit_sampled_volume, fit_sampled_volume_with};
use volmorph_trivariate::{
    AggregateVolume, PolygonizeOptions, TrivariateError, isosurface, isosurface_with, slice,
    slice_with,
};
use volmorph_volume::{Geometry, Volume};

/// A tricubic volume of `n³` control points: a bent, twisted box with a wavy attribute.
fn model(n: usize) -> AggregateVolume {
    volmorph_trivariate::examples::twisted_box(n).unwrap()
}

#[test]
fn isosurface_and_slice_report_and_cancel() {
    let m = model(10);
    let o = PolygonizeOptions::default();
    let plain = isosurface(&m, "f", 0.1, &o).unwrap();
    let with = progress::check(|p| isosurface_with(&m, "f", 0.1, &o, p));
    assert_eq!(plain, with);
    assert!(with.mesh.face_count() > 100);
    let plane = [0.3, 0.2, 1.0, -0.5];
    let plain = slice(&m, plane, Some("f"), &o).unwrap();
    let with = progress::check(|p| slice_with(&m, plane, Some("f"), &o, p));
    assert_eq!(plain, with);
    // Three stages: root isolation, the lattice's layers, the vertices.
    let c = volmorph_io::Counter::new();
    isosurface_with(&m, "f", 0.1, &o, &c).unwrap();
    assert_eq!(c.stages().len(), 3, "{:?}", c.stages());
    let total = c.announced();
    // Cancelled in the second stage, after its first layer.
    let roots = c.stages()[0].1;
    let e = progress::cancelled(|p| isosurface_with(&m, "f", 0.1, &o, p), roots + 1, total);
    assert!(matches!(e, TrivariateError::Cancelled(_)), "{e}");
}

#[test]
fn fit_reports_three_steps_and_cancels() {
    let g = Geometry::new([12, 10, 9]).with_spacing(DVec3::new(0.9, 1.1, 1.5));
    let vol = Volume::<f64>::from_fn(g, |i, j, k| {
        ((i * 7 + j * 3 + k) % 11) as f64 + 0.1 * (i as f64).sin()
    })
    .unwrap();
    for counts in [g.dims, [6, 5, 5]] {
        let plain = fit_sampled_volume(&vol, 4, counts, "v").unwrap();
        let with = progress::check(|p| fit_sampled_volume_with(&vol, 4, counts, "v", p));
        assert_eq!(plain.kind, with.kind);
        assert_eq!(plain.model, with.model);
        assert_eq!(
            progress::total_steps(|p| fit_sampled_volume_with(&vol, 4, counts, "v", p)),
            3
        );
        let e = progress::cancelled(|p| fit_sampled_volume_with(&vol, 4, counts, "v", p), 1, 3);
        assert!(matches!(e, TrivariateError::Cancelled(_)), "{e}");
    }
}
