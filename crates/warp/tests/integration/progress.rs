//! Every long warp reports its steps exactly, can be cancelled, and gives with progress the
//! same result as without, bit for bit.

use std::sync::Mutex;

use glam::DVec3;
use volmorph_io::Progress;
use volmorph_lattice::BSplineLattice;
use volmorph_testkit::{Rng, progress};
use volmorph_volume::{AnyVolume, Geometry, IndexBox, Volume};
use volmorph_warp::WarpError;
use volmorph_warp::apply::{WarpMethod, WarpOptions, warp_volume, warp_volume_with};
use volmorph_warp::chunked::{warp_chunked, warp_chunked_with};
use volmorph_warp::jacobian::{jacobian_determinant, jacobian_determinant_with};
use volmorph_warp::pullback::{ResampleOptions, resample, resample_with};

fn grid() -> Geometry {
    Geometry::new([40, 33, 29])
        .with_spacing(DVec3::new(0.9, 1.1, 1.2))
        .with_origin(DVec3::new(-4.0, 2.0, 1.0))
}

fn source(g: Geometry) -> Volume<u16> {
    Volume::<u16>::from_fn(g, |i, j, k| {
        ((i * 37 + j * 101 + k * 251) % 4093) as u16 * 13
    })
    .unwrap()
}

/// A cubic lattice around `g` with every control point moved by up to `amp`.
fn bent(g: &Geometry, amp: f64) -> BSplineLattice {
    let c = g.corner_points();
    let lo = c.iter().fold(DVec3::splat(f64::INFINITY), |a, &p| a.min(p));
    let hi = c
        .iter()
        .fold(DVec3::splat(f64::NEG_INFINITY), |a, &p| a.max(p));
    let mut lat = BSplineLattice::uniform_cubic_around(lo, hi, [5, 5, 5]).unwrap();
    let mut rng = Rng::new(3);
    for k in 0..5 {
        for j in 0..5 {
            for i in 0..5 {
                let p = lat.control_point([i, j, k]).unwrap();
                lat.set_control_point([i, j, k], p + rng.point(amp))
                    .unwrap();
            }
        }
    }
    lat
}

#[test]
fn pullback_reports_rows_and_cancels() {
    let g = grid();
    let input = source(g);
    let map = bent(&g, 1.5);
    let o = ResampleOptions::default();
    let plain: Volume<u16> = resample(&input, &map, &g, &o).unwrap();
    let with = progress::check(|p| resample_with::<u16, u16, _>(&input, &map, &g, &o, p));
    assert_eq!(plain, with);
    let c = volmorph_io::Counter::new();
    let _: Volume<u16> = resample_with(&input, &map, &g, &o, &c).unwrap();
    assert_eq!(c.stages()[0].1, 33 * 29, "one step per output row");
    let e = progress::cancelled(
        |p| resample_with::<u16, u16, _>(&input, &map, &g, &o, p),
        1,
        33 * 29,
    );
    assert!(matches!(e, WarpError::Cancelled(_)), "{e}");
}

#[test]
fn every_warp_method_reports_and_cancels() {
    // Push-forward works in slabs of about 2^19 input voxels, several per window of threads:
    // a tall grid gives it enough slabs to stop between them.
    let tall = Geometry::new([16, 16, 6000]);
    for method in WarpMethod::ALL {
        let g = if method.is_pullback() || method.is_inverse() {
            grid()
        } else {
            tall
        };
        let input = AnyVolume::from(source(g));
        let map = bent(&g, 1.0);
        let options = WarpOptions {
            mask: method.is_inverse(),
            ..WarpOptions::default()
        };
        let plain = warp_volume(&input, &map, &g, method, &options).unwrap();
        let with = progress::check(|p| warp_volume_with(&input, &map, &g, method, &options, p));
        assert_eq!(plain.volume, with.volume, "{method}");
        assert_eq!(plain.mask, with.mask, "{method}");
        assert_eq!(plain.push_stats, with.push_stats, "{method}");
        assert_eq!(
            plain.inverse_report.map(|r| r.to_string()),
            with.inverse_report.map(|r| r.to_string()),
            "{method}"
        );
    }
}

#[test]
fn jacobian_reports_slices_and_cancels() {
    let g = Geometry::new([30, 30, 300]);
    let map = bent(&g, 2.0);
    let plain = jacobian_determinant(&map, &g).unwrap();
    let with = progress::check(|p| jacobian_determinant_with(&map, &g, p));
    let bits = |v: &Volume<f32>| v.data().iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&plain), bits(&with));
}

fn boxes(dims: [usize; 3], chunk: [usize; 3]) -> Vec<IndexBox> {
    let mut v = Vec::new();
    for z in (0..dims[2]).step_by(chunk[2]) {
        for y in (0..dims[1]).step_by(chunk[1]) {
            for x in (0..dims[0]).step_by(chunk[0]) {
                v.push(IndexBox {
                    start: [x, y, z],
                    end: [
                        (x + chunk[0]).min(dims[0]),
                        (y + chunk[1]).min(dims[1]),
                        (z + chunk[2]).min(dims[2]),
                    ],
                });
            }
        }
    }
    v
}

#[test]
fn chunked_warp_reports_chunks_and_stops_writing_when_cancelled() {
    let g = grid();
    let input = source(g);
    let map = bent(&g, 1.5);
    let o = ResampleOptions::default();
    let chunks = boxes(g.dims, [16, 16, 8]);
    let read = |b: IndexBox| -> Result<AnyVolume, WarpError> {
        let d = [0, 1, 2].map(|a| b.end[a] - b.start[a]);
        Ok(AnyVolume::from(
            Volume::<u16>::from_fn(Geometry::new(d), |i, j, k| {
                input[[b.start[0] + i, b.start[1] + j, b.start[2] + k]]
            })
            .unwrap(),
        ))
    };
    let run = |p: &dyn Progress| -> Result<Vec<(IndexBox, AnyVolume)>, WarpError> {
        let written = Mutex::new(Vec::new());
        warp_chunked_with(
            &map,
            &g,
            &g,
            &chunks,
            &o,
            read,
            |b, v| {
                written.lock().unwrap().push((b, v));
                Ok(())
            },
            p,
        )?;
        let mut w = written.into_inner().unwrap();
        w.sort_by_key(|(b, _)| (b.start[2], b.start[1], b.start[0]));
        Ok(w)
    };
    let plain = {
        let written = Mutex::new(Vec::new());
        warp_chunked(&map, &g, &g, &chunks, &o, read, |b, v| {
            written.lock().unwrap().push((b, v));
            Ok(())
        })
        .unwrap();
        let mut w = written.into_inner().unwrap();
        w.sort_by_key(|(b, _)| (b.start[2], b.start[1], b.start[0]));
        w
    };
    let with = progress::check(run);
    assert_eq!(with.len(), chunks.len());
    assert_eq!(plain, with);
    // Cancelled after the first chunk: not every chunk reaches `write`.
    let count = Mutex::new(0usize);
    let stop = volmorph_io::Counter::cancel_after(1);
    let e = warp_chunked_with(
        &map,
        &g,
        &g,
        &chunks,
        &o,
        read,
        |_, _| {
            *count.lock().unwrap() += 1;
            Ok(())
        },
        &stop,
    )
    .unwrap_err();
    assert!(matches!(e, WarpError::Cancelled(_)), "{e}");
    assert!(*count.lock().unwrap() < chunks.len());
}

/// The incremental engine's construction (the full antialiased push-forward the scene's
/// warps start from) reports the output's planes, stops when cancelled, and builds the
/// engine of the plain call bit for bit.
#[test]
fn incremental_engine_construction_reports_planes_and_cancels() {
    use volmorph_warp::incremental::IncrementalPushForward;
    use volmorph_warp::pushforward::AntialiasOptions;
    // Tall, so the planes are cut into more slabs than there are threads.
    let g = Geometry::new([12, 12, 2000]);
    let input = source(g);
    let map = bent(&g, 0.8);
    let o = AntialiasOptions::default();
    let plain = IncrementalPushForward::new(&input, map.clone(), &g, &o).unwrap();
    let with =
        progress::check(|p| IncrementalPushForward::new_with(&input, map.clone(), &g, &o, p));
    let bits = |v: &Volume<f32>| v.data().iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(plain.volume()), bits(with.volume()));
    assert_eq!(plain.stats(), with.stats());
    let c = volmorph_io::Counter::new();
    IncrementalPushForward::new_with(&input, map, &g, &o, &c).unwrap();
    assert_eq!(
        c.stages()[1],
        ("antialiased push-forward".to_string(), 2000)
    );
}
