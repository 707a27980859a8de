//! Criterion benchmarks of mesh FFD: the accurate FFD of a 70k-triangle sphere through a
//! 6 × 8 × 6 degree-2 lattice (target ≤ 2 s), and vertex FFD of a 1M-vertex sphere (target
//! ≤ 50 ms).

use std::hint::black_box;
use std::sync::Arc;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use volmorph_deform::SpaceMap;
use volmorph_ffd::accurate::AccuratePlan;
use volmorph_ffd::baseline::vertex_ffd;
use volmorph_ffd::shapes::uv_sphere;
use volmorph_lattice::BSplineLattice;
use volmorph_mesh::Mesh;

fn moved_lattice(mesh: &Mesh, counts: [usize; 3]) -> BSplineLattice {
    let (lo, hi) = mesh.bounding_box().unwrap();
    let mut lat = BSplineLattice::feng_end_interpolating_around(lo, hi, [2, 2, 2], counts).unwrap();
    let mut s = 12_345_u64;
    for k in 0..counts[2] {
        for j in 0..counts[1] {
            for i in 0..counts[0] {
                let mut r = || {
                    s = s.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
                    (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
                };
                let d = DVec3::new(r(), r(), r()) * 0.1;
                lat.move_control_point([i, j, k], d).unwrap();
            }
        }
    }
    lat
}

fn bench(c: &mut Criterion) {
    // 4·133·132 = 70 224 triangles.
    let sphere = uv_sphere(133, 1.0, DVec3::ZERO).unwrap();
    let lat = moved_lattice(&sphere, [6, 8, 6]);
    let mut g = c.benchmark_group("accurate_70k_tri_6x8x6_deg2");
    g.sample_size(10);
    g.bench_function("plan+surfaces", |b| {
        b.iter(|| {
            let plan = Arc::new(AccuratePlan::new(black_box(&sphere), &lat).unwrap());
            black_box(plan.deform(&lat).unwrap())
        });
    });
    let plan = Arc::new(AccuratePlan::new(&sphere, &lat).unwrap());
    g.bench_function("surfaces_only", |b| {
        b.iter(|| black_box(plan.deform(&lat).unwrap()))
    });
    g.finish();

    // 2·708·707 + 2 = 1 001 114 vertices.
    let big = uv_sphere(708, 1.0, DVec3::ZERO).unwrap();
    let lat = moved_lattice(&big, [6, 8, 6]);
    let mut g = c.benchmark_group("vertex_ffd_1M");
    g.sample_size(20);
    g.bench_function("deg2_6x8x6_mesh", |b| {
        b.iter(|| black_box(vertex_ffd(&big, &lat).unwrap()));
    });
    // The deformation itself: positions into a preallocated buffer.
    let mut out = vec![DVec3::ZERO; big.vertex_count()];
    g.bench_function("deg2_6x8x6_positions", |b| {
        b.iter(|| {
            lat.apply_batch(black_box(big.positions()), &mut out)
                .unwrap()
        });
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
