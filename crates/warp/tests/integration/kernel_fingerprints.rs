//! Bit-for-bit fingerprints of the hot kernels' outputs, pinned to the values they had before
//! their inner loops were rewritten for speed (lattice grid evaluation, pull-back sampling,
//! the box-filter tally of the full and incremental push-forward). A faster kernel must
//! produce exactly the same bits: these tests fail on any change of the floating-point
//! operations or their order, so every optimisation here is checked against the code it
//! replaced, not only against a tolerance.
//!
//! The push-forward and engine fingerprints were re-pinned once, deliberately, when every
//! push-forward image moved onto the fixed evaluation tiles that let a chunk of the output
//! recompute them with the same bits (`docs/chunked-pushforward.md`); the lattice and
//! pull-back fingerprints did not change.
//!
//! The fingerprint is FNV-1a over the little-endian bits of every output value. The inputs
//! are small (a 40×36×32 grid with non-unit spacing and an offset origin, a randomly moved
//! 7×7×7 cubic lattice), so the tests run in well under a second.

use glam::DVec3;
use volmorph_deform::SpaceMap;
use volmorph_lattice::BSplineLattice;
use volmorph_testkit::Rng;
use volmorph_testkit::fingerprint::fnv1a as fnv;
use volmorph_volume::sample::Interpolation;
use volmorph_volume::{Geometry, Volume};
use volmorph_warp::incremental::IncrementalPushForward;
use volmorph_warp::pullback::{ResampleOptions, resample};
use volmorph_warp::pushforward::{
    AntialiasOptions, push_forward_antialiased, push_forward_antialiased_f32,
};

fn grid() -> Geometry {
    Geometry::new([40, 36, 32])
        .with_spacing(DVec3::new(0.9, 1.1, 1.3))
        .with_origin(DVec3::new(-3.0, 2.0, 5.5))
}

/// A structured source: a bright ellipsoid over a ramp, values 0..=200.
fn source(g: Geometry) -> Volume<f32> {
    let [nx, ny, nz] = g.dims;
    Volume::from_fn(g, |i, j, k| {
        let d = DVec3::new(
            (i as f64 - nx as f64 / 2.0) / (nx as f64 / 3.0),
            (j as f64 - ny as f64 / 2.0) / (ny as f64 / 3.5),
            (k as f64 - nz as f64 / 2.0) / (nz as f64 / 3.0),
        );
        let ramp = ((i * 7 + j * 13 + k * 3) % 17) as f32 * 3.0;
        if d.length() < 1.0 { 150.0 + ramp } else { ramp }
    })
    .unwrap()
}

/// A 7×7×7 lattice on the grid's voxel centres, inner control points moved at random by up
/// to about half a cell.
fn lattice(g: &Geometry) -> BSplineLattice {
    let mut lat = BSplineLattice::identity_on_voxels(g, [7, 7, 7]).unwrap();
    let mut rng = Rng::new(0xf1_2e_57);
    let cell = 0.5 * DVec3::new(39.0 * 0.9, 35.0 * 1.1, 31.0 * 1.3) / 4.0;
    for k in 1..6 {
        for j in 1..6 {
            for i in 1..6 {
                lat.move_control_point([i, j, k], cell * rng.point(0.5))
                    .unwrap();
            }
        }
    }
    lat
}

fn f32_bits(v: &[f32]) -> u64 {
    fnv(v.iter().map(|x| u64::from(x.to_bits())))
}

/// Print the fingerprints (run with `--nocapture` to re-pin after an intended change).
fn check(name: &str, got: u64, want: u64) {
    println!("{name}: {got:#018x}");
    assert_eq!(got, want, "{name}: output bits changed");
}

#[test]
fn lattice_grid_evaluation_bits_unchanged() {
    let g = grid();
    let lat = lattice(&g);
    let mut out = vec![DVec3::ZERO; g.len()];
    lat.apply_grid(&g, &mut out).unwrap();
    let h = fnv(out.iter().flat_map(|p| p.to_array().map(f64::to_bits)));
    check("lattice apply_grid", h, 0xe5fc_7b8e_1916_808a);
}

#[test]
fn pullback_bits_unchanged() {
    let g = grid();
    let lat = lattice(&g);
    let src = source(g);
    for (interp, want) in [
        (Interpolation::Linear, 0xc1c6_a60a_9950_d241),
        (Interpolation::CubicBSpline, 0x4fbf_71a8_915d_8467),
        (Interpolation::Nearest, 0x0b40_9bff_cd02_32dc),
    ] {
        let out: Volume<f32> =
            resample(&src, &lat, &g, &ResampleOptions::new(interp, 0.0)).unwrap();
        check(&format!("pull-back {interp:?}"), f32_bits(out.data()), want);
    }
}

#[test]
fn pushforward_antialiased_bits_unchanged() {
    let g = grid();
    let lat = lattice(&g);
    let src = source(g);
    let opts = AntialiasOptions::default();
    let full = push_forward_antialiased_f32(&src, &lat, &g, &opts).unwrap();
    check(
        "push-forward f32",
        f32_bits(full.volume.data()),
        0x7821_b608_125b_f9d5,
    );
    let u8src: Volume<u8> = src.cast();
    let typed = push_forward_antialiased(&u8src, &lat, &g, &opts).unwrap();
    check(
        "push-forward u8",
        fnv(typed.volume.data().iter().map(|&x| u64::from(x))),
        0x42e8_c5c1_de8d_00a0,
    );
}

#[test]
fn incremental_update_bits_unchanged() {
    let g = grid();
    let src = source(g);
    let base = BSplineLattice::identity_on_voxels(&g, [7, 7, 7]).unwrap();
    let mut engine =
        IncrementalPushForward::new(&src, base, &g, &AntialiasOptions::default()).unwrap();
    check(
        "engine identity",
        f32_bits(engine.volume().data()),
        0x6479_2d2a_dd5a_dfb0,
    );
    // A cluster of moves, as a drag makes, then a single one.
    let moves = [
        ([3, 3, 3], DVec3::new(2.0, -1.0, 0.5)),
        ([3, 4, 3], DVec3::new(1.5, -0.5, 0.25)),
        ([4, 3, 3], DVec3::new(1.0, 0.5, -0.75)),
        ([4, 4, 4], DVec3::new(-0.5, 1.0, 1.5)),
    ];
    let changes = engine.map().changes_for_displacements(&moves).unwrap();
    engine.set_parameters(&changes).unwrap();
    check(
        "engine after cluster",
        f32_bits(engine.volume().data()),
        0x6836_f887_a00e_43de,
    );
    let changes = engine
        .map()
        .changes_for_displacements(&[([2, 3, 4], DVec3::new(-1.0, 0.7, 0.3))])
        .unwrap();
    engine.set_parameters(&changes).unwrap();
    check(
        "engine after one",
        f32_bits(engine.volume().data()),
        0xf515_f22b_27c0_dfe6,
    );
}
