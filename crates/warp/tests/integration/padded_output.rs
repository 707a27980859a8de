//! True 1992 §5.1: a target grid larger than the source (TSIZE > ISIZE). Padding the output
//! then cropping it back gives the unpadded warp, for every method, and a model pushed past
//! the source's bounds is kept whole on the padded grid.

use glam::{DMat3, DVec3};
use volmorph_deform::{Affine, SpaceMap};
use volmorph_lattice::BSplineLattice;
use volmorph_volume::{AnyVolume, Geometry, Volume};
use volmorph_warp::apply::{WarpMethod, WarpOptions, warp_volume};
use volmorph_warp::output::{OutputGrid, PadUnit, Padding};

fn grid() -> Geometry {
    Geometry::new([18, 15, 12])
        .with_spacing(DVec3::new(1.0, 1.25, 1.5))
        .with_origin(DVec3::new(-3.0, 2.0, 1.0))
        .with_direction(DMat3::from_rotation_z(0.25))
}

/// A ball of value 200 (smooth edge) around `centre` of radius `r`, on `g`.
fn ball(g: Geometry, centre_index: DVec3, r: f64) -> Volume<f32> {
    Volume::from_fn(g, |i, j, k| {
        let d = (DVec3::new(i as f64, j as f64, k as f64) - centre_index).length();
        (200.0 * (r - d + 0.5).clamp(0.0, 1.0)) as f32
    })
    .unwrap()
}

/// A wavy lattice (every control point moved) on a box reaching 6 voxels beyond the grid on
/// every side, so the map is continuous over the padded grids (a lattice map jumps at its box
/// surface, where two runs may find different preimages of the same point).
fn wavy(g: &Geometry) -> BSplineLattice {
    let mut l = BSplineLattice::identity_on_voxels(&g.padded([6; 3], [6; 3]), [8, 8, 7]).unwrap();
    let [nx, ny, nz] = l.counts();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let d = DVec3::new(
                    ((i * 3 + j) % 5) as f64 * 0.4 - 0.8,
                    ((j * 2 + k) % 3) as f64 * 0.5 - 0.5,
                    ((i + k) % 4) as f64 * 0.3 - 0.45,
                );
                l.move_control_point([i, j, k], d).unwrap();
            }
        }
    }
    l
}

fn values(v: &AnyVolume) -> Volume<f32> {
    v.to_typed::<f32>()
}

#[test]
fn padding_then_cropping_equals_the_unpadded_warp_for_every_method() {
    let g = grid();
    let input = AnyVolume::from(ball(g, DVec3::new(9.0, 7.0, 6.0), 4.5));
    let map = wavy(&g);
    let (low, high) = ([3, 0, 2], [1, 4, 2]);
    let pad = Padding {
        low: DVec3::new(3.0, 0.0, 2.0),
        high: DVec3::new(1.0, 4.0, 2.0),
        unit: PadUnit::Voxels,
    };
    let padded = OutputGrid::Padded(pad).resolve(&g).unwrap();
    assert_eq!(padded, g.padded(low, high));
    for method in WarpMethod::ALL {
        let o = WarpOptions::default();
        let pw = warp_volume(&input, &map, &g, method, &o).unwrap();
        let bw = warp_volume(&input, &map, &padded, method, &o).unwrap();
        let (plain, big) = (values(&pw.volume), values(&bw.volume));
        assert_eq!(big.dims(), padded.dims);
        let mut worst = 0.0f32;
        for k in 0..12 {
            for j in 0..15 {
                for i in 0..18 {
                    let a = plain[[i, j, k]];
                    let b = big[[i + low[0], j + low[1], k + low[2]]];
                    worst = worst.max((a - b).abs());
                }
            }
        }
        assert!(
            worst < 1e-3,
            "{method}: cropped padded warp differs by {worst}"
        );
    }
}

#[test]
fn a_model_pushed_past_the_source_bounds_is_not_clipped_on_the_padded_grid() {
    let g = Geometry::new([20, 20, 20]);
    // A ball near the +x face, pushed 8 voxels further out.
    let input = AnyVolume::from(ball(g, DVec3::new(14.0, 10.0, 10.0), 4.0));
    let shift = Affine::translation(DVec3::new(8.0, 0.0, 0.0));
    let mass = |v: &Volume<f32>| v.data().iter().map(|&x| f64::from(x)).sum::<f64>();
    let before = mass(&values(&input));
    let pad = OutputGrid::Padded(Padding {
        low: DVec3::ZERO,
        high: DVec3::new(10.0, 0.0, 0.0),
        unit: PadUnit::Physical,
    });
    let padded = pad.resolve(&g).unwrap();
    assert_eq!(padded.dims, [30, 20, 20]);
    for method in [
        WarpMethod::PushforwardAntialiased,
        WarpMethod::InverseLinear,
    ] {
        let o = WarpOptions::default();
        let clipped = values(&warp_volume(&input, &shift, &g, method, &o).unwrap().volume);
        let whole = values(
            &warp_volume(&input, &shift, &padded, method, &o)
                .unwrap()
                .volume,
        );
        assert!(
            mass(&clipped) < 0.7 * before,
            "{method}: the unpadded grid should clip the ball"
        );
        let m = mass(&whole);
        assert!(
            (m - before).abs() < 1e-3 * before,
            "{method}: mass {m} on the padded grid, {before} in the input"
        );
        // The ball's centre lands at x = 22 of the padded grid.
        let c = whole[[22, 10, 10]];
        assert!((c - 200.0).abs() < 1e-3, "{method}: centre {c}");
    }
    assert_eq!(shift.apply(DVec3::ZERO), DVec3::new(8.0, 0.0, 0.0));
}
