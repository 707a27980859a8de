//! Both extractors report their planes and layers exactly, can be cancelled, and give with
//! progress the same surface as without, bit for bit.

use volmorph_contour::{
    ContourError, DcOptions, McOptions, dual_contouring, dual_contouring_any_with,
    dual_contouring_with, marching_cubes, marching_cubes_any_with, marching_cubes_with,
};
use volmorph_testkit::progress;
use volmorph_volume::AnyVolume;
use volmorph_volume::phantom::{self, Phantom};

#[test]
fn marching_cubes_reports_planes_and_layers_and_cancels() {
    let sdf = phantom::signed_distance(Phantom::Torus, [48, 44, 40]).unwrap();
    let o = McOptions { inside_below: true };
    let plain = marching_cubes(&sdf, 0.0, &o).unwrap();
    let with = progress::check(|p| marching_cubes_with(&sdf, 0.0, &o, p));
    assert_eq!(plain, with);
    let total = progress::total_steps(|p| marching_cubes_with(&sdf, 0.0, &o, p));
    assert_eq!(total, 2 * 40 - 1);
    let any = AnyVolume::from(sdf.clone());
    let e = progress::cancelled(|p| marching_cubes_any_with(&any, 0.0, &o, p), 1, total);
    assert!(matches!(e, ContourError::Cancelled(_)), "{e}");
}

#[test]
fn dual_contouring_reports_layers_and_planes_and_cancels() {
    let density = phantom::density(Phantom::RoundedBox, [40, 40, 36]).unwrap();
    let o = DcOptions::default();
    let plain = dual_contouring(&density, 127.0, &o).unwrap();
    let with = progress::check(|p| dual_contouring_with(&density, 127.0, &o, p));
    assert_eq!(plain, with);
    let total = progress::total_steps(|p| dual_contouring_with(&density, 127.0, &o, p));
    assert_eq!(total, 2 * 36 - 1);
    let any = AnyVolume::from(density.clone());
    let e = progress::cancelled(|p| dual_contouring_any_with(&any, 127.0, &o, p), 1, total);
    assert!(matches!(e, ContourError::Cancelled(_)), "{e}");
}
