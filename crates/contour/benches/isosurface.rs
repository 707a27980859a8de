//! Isosurface extraction on one input: a 256³ `f32` sphere distance field (radius 100 voxels,
//! about 300 000 triangles), the size the extractors are tuned for.
//!
//! * `marching_cubes/sphere_f32_256`;
//! * `dual_contouring/sphere_f32_256_feature_30deg` — the default feature threshold (mass
//!   points almost everywhere) — and `…_qef_everywhere` — the QEF solved in every cell.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::DVec3;
use volmorph_contour::{DcOptions, IsoSurface, McOptions, dual_contouring, marching_cubes};
use volmorph_volume::{Geometry, Volume};

const N: usize = 256;

fn sphere() -> Volume<f32> {
    let c = DVec3::splat((N - 1) as f64 / 2.0);
    Volume::from_fn(Geometry::new([N, N, N]), |i, j, k| {
        ((DVec3::new(i as f64, j as f64, k as f64) - c).length() - 100.0) as f32
    })
    .expect("256³ f32 volume fits")
}

fn describe(name: &str, surface: &IsoSurface) {
    eprintln!(
        "{name}, sphere 256³: {} vertices, {} triangles",
        surface.mesh.positions().len(),
        surface.mesh.face_count()
    );
}

fn bench(c: &mut Criterion) {
    let volume = sphere();

    let options = McOptions { inside_below: true };
    describe(
        "marching cubes",
        &marching_cubes(&volume, 0.0, &options).expect("valid input"),
    );
    let mut group = c.benchmark_group("marching_cubes");
    group.sample_size(20);
    group.throughput(Throughput::Elements((N * N * N) as u64));
    group.bench_function("sphere_f32_256", |b| {
        b.iter(|| marching_cubes(black_box(&volume), 0.0, &options).expect("valid input"));
    });
    group.finish();

    let adaptive = DcOptions {
        inside_below: true,
        ..DcOptions::default()
    };
    let plain = DcOptions {
        feature_angle: 0.0,
        ..adaptive
    };
    describe(
        "dual contouring",
        &dual_contouring(&volume, 0.0, &adaptive).expect("valid input"),
    );
    let mut group = c.benchmark_group("dual_contouring");
    group.sample_size(10);
    group.throughput(Throughput::Elements((N * N * N) as u64));
    group.bench_function("sphere_f32_256_feature_30deg", |b| {
        b.iter(|| dual_contouring(black_box(&volume), 0.0, &adaptive).expect("valid input"));
    });
    group.bench_function("sphere_f32_256_qef_everywhere", |b| {
        b.iter(|| dual_contouring(black_box(&volume), 0.0, &plain).expect("valid input"));
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
