//! Marching cubes on a 256³ `f32` sphere distance field (radius 100 voxels, about 300 000
//! triangles), the size the extractor is tuned for.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::DVec3;
use volmorph_contour::{McOptions, marching_cubes};
use volmorph_volume::{Geometry, Volume};

const N: usize = 256;

fn sphere() -> Volume<f32> {
    let c = DVec3::splat((N - 1) as f64 / 2.0);
    Volume::from_fn(Geometry::new([N, N, N]), |i, j, k| {
        ((DVec3::new(i as f64, j as f64, k as f64) - c).length() - 100.0) as f32
    })
    .expect("256³ f32 volume fits")
}

fn bench(c: &mut Criterion) {
    let volume = sphere();
    let options = McOptions { inside_below: true };
    let surface = marching_cubes(&volume, 0.0, &options).expect("valid input");
    eprintln!(
        "sphere 256³: {} vertices, {} triangles",
        surface.mesh.positions().len(),
        surface.mesh.face_count()
    );
    let mut group = c.benchmark_group("marching_cubes");
    group.sample_size(20);
    group.throughput(Throughput::Elements((N * N * N) as u64));
    group.bench_function("sphere_f32_256", |b| {
        b.iter(|| marching_cubes(black_box(&volume), 0.0, &options).expect("valid input"));
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
