//! The handle suite of `volmorph bench handles` under criterion, at the sizes of its
//! targets, plus the 2D segment plan, dragging a selected 3D handle, `apply` and `jacobian` of
//! the four 3D MLS maps at 1000 points, and the thin-plate spline on a batch of points; and
//! the compactly supported Wendland map with 3k, 10k and 30k handles (set-up, re-solve after
//! one handle moves, 32³ evaluation).

mod common;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use volmorph_bench::handles::{HandlesConfig, HandlesInputs};
use volmorph_deform::SpaceMap;
use volmorph_handles::WendlandMap;
use volmorph_testkit::Rng;
use volmorph_volume::Geometry;

fn bench(c: &mut Criterion) {
    let inputs = HandlesInputs::new(&HandlesConfig::default()).expect("handle sets");
    let mut cases = inputs.cases().expect("cases");
    cases.extend(inputs.extra_cases().expect("extra cases"));
    common::bench_cases(c, "handles", 10, cases);
}

/// Landmark-dense registration: the compactly supported Wendland map through 3k, 10k and 30k
/// handles scattered in a 256 mm cube (each moved by a smooth field plus noise): set-up
/// (neighbour grid, assembly, sparse Cholesky, solve), the re-solve after one target moves
/// (live edits keep the factorisation) and evaluation on a 32³ grid.
fn bench_wendland(c: &mut Criterion) {
    let mut g = c.benchmark_group("wendland");
    g.sample_size(10);
    let grid = Geometry::new([32, 32, 32]).with_spacing(DVec3::splat(8.0));
    for n in [3_000usize, 10_000, 30_000] {
        let mut r = Rng::new(n as u64);
        let src: Vec<DVec3> = (0..n)
            .map(|_| r.point_in(DVec3::ZERO, DVec3::splat(256.0)))
            .collect();
        let dst: Vec<DVec3> = src
            .iter()
            .map(|&p| {
                p + DVec3::new((p.y * 0.02).sin(), (p.z * 0.03).cos(), (p.x * 0.025).sin()) * 4.0
                    + r.point_in(DVec3::ZERO, DVec3::ONE)
            })
            .collect();
        g.bench_function(format!("factorise {n} handles"), |b| {
            b.iter(|| WendlandMap::new(&src, &dst, 0.0).expect("wendland"));
        });
        let mut map = WendlandMap::new(&src, &dst, 0.0).expect("wendland");
        // A live edit: one target moves, the kept factorisation re-solves.
        let mut moved = dst.clone();
        g.bench_function(format!("move one handle, {n} handles"), |b| {
            b.iter(|| {
                moved[n / 2].x += 1e-3;
                map.set_targets(&moved).expect("re-solve");
            });
        });
        map.set_targets(&dst).expect("re-solve");
        let mut out = vec![DVec3::ZERO; grid.len()];
        g.bench_function(format!("evaluate 32³ grid, {n} handles"), |b| {
            b.iter(|| map.apply_grid(&grid, &mut out).expect("grid"));
        });
    }
    g.finish();
}

criterion_group!(benches, bench, bench_wendland);
criterion_main!(benches);
