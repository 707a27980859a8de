//! Push-forward of a 256³ u8 volume through True's 9×9×9 cubic lattice with 27 interior
//! control points moved: map-and-round (§5.3) and box-filter antialiasing (§5.4) with averaged
//! (True's) and mapped face centres.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use volmorph_lattice::BSplineLattice;
use volmorph_volume::{Geometry, Volume};
use volmorph_warp::pushforward::{
    AntialiasOptions, FaceCentres, push_forward_antialiased, push_forward_nearest,
};

fn lattice() -> BSplineLattice {
    // 6 regions of 43 voxels: the box [-1, 257] covers the voxel centres 0..=255.
    let mut lat =
        BSplineLattice::uniform_cubic_around(DVec3::splat(-1.0), DVec3::splat(257.0), [9, 9, 9])
            .expect("lattice");
    for k in 3..6 {
        for j in 3..6 {
            for i in 3..6 {
                let d = DVec3::new(i as f64, j as f64 - 4.0, k as f64 * 0.5);
                lat.move_control_point([i, j, k], d).expect("move");
            }
        }
    }
    lat
}

fn bench(c: &mut Criterion) {
    let lat = lattice();
    let grid = Geometry::new([256, 256, 256]);
    let input = Volume::from_fn(grid, |i, j, k| ((i ^ j ^ k) & 0xff) as u8).expect("volume");
    let opts = AntialiasOptions::default();
    let mut g = c.benchmark_group("pushforward_256^3_u8_lattice_9x9x9");
    g.sample_size(10);
    g.bench_function("nearest", |b| {
        b.iter(|| push_forward_nearest(&input, &lat, &grid).expect("nearest"));
    });
    g.bench_function("antialiased", |b| {
        b.iter(|| push_forward_antialiased(&input, &lat, &grid, &opts).expect("antialiased"));
    });
    let mapped = AntialiasOptions {
        face_centres: FaceCentres::Mapped,
        ..opts
    };
    g.bench_function("antialiased_mapped_faces", |b| {
        b.iter(|| push_forward_antialiased(&input, &lat, &grid, &mapped).expect("antialiased"));
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
