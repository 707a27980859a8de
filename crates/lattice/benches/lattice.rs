//! Dense evaluation of a 9×9×9 cubic lattice on a 256³ grid (True 1992 §5.2): the coefficient
//! table path (integer granularity G = 43 voxels per cell) and the separable path, each with
//! its plan built per call and reused.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use volmorph_deform::SpaceMap;
use volmorph_lattice::BSplineLattice;
use volmorph_lattice::grid::{GridPath, LatticeGridPlan};
use volmorph_volume::Geometry;

fn lattice() -> BSplineLattice {
    // 6 regions of 43 voxels: the box [-1, 257] covers the 256 voxel centres 0..=255.
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
    let mut out = vec![DVec3::ZERO; grid.len()];
    let mut g = c.benchmark_group("lattice_9x9x9_on_256^3");
    g.sample_size(10);
    g.bench_function("table", |b| {
        b.iter(|| lat.apply_grid_table(&grid, &mut out).expect("table path"));
    });
    g.bench_function("separable", |b| {
        b.iter(|| {
            lat.apply_grid_separable(&grid, &mut out)
                .expect("separable path")
        });
    });
    // Plans built once, as in an interactive loop where only control points change.
    let table = LatticeGridPlan::new(&lat, &grid, GridPath::Table).expect("table plan");
    let separable = LatticeGridPlan::new(&lat, &grid, GridPath::Separable).expect("plan");
    g.bench_function("table_plan_reused", |b| {
        b.iter(|| table.apply(&lat, &mut out).expect("table plan"));
    });
    g.bench_function("separable_plan_reused", |b| {
        b.iter(|| separable.apply(&lat, &mut out).expect("separable plan"));
    });
    g.bench_function("apply_grid", |b| {
        b.iter(|| lat.apply_grid(&grid, &mut out).expect("apply_grid"));
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
