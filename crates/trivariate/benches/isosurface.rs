//! Isosurface and slice extraction (Martin & Cohen §5.1) on a 16³-control-point tricubic
//! volume with curved geometry and a smooth non-trivial attribute, to flatness 1e-3 of the
//! bounding-box diagonal. Target: isosurface ≤ 0.5 s on 2 cores.

use criterion::{Criterion, criterion_group, criterion_main};
use volmorph_trivariate::{AggregateVolume, PolygonizeOptions, isosurface, slice};

/// 16³ tricubic volume: a bent, twisted box with a wavy scalar attribute.
fn model() -> AggregateVolume {
    volmorph_trivariate::examples::twisted_box(16).unwrap()
}

fn bench(c: &mut Criterion) {
    let m = model();
    let opts = PolygonizeOptions::default();
    let z = isosurface(&m, "f", 0.1, &opts).unwrap();
    eprintln!(
        "isosurface: {} triangles, lattice {:?}, {} root cells",
        z.mesh.face_count(),
        z.lattice,
        z.root_cells
    );
    let s = slice(&m, [0.3, 0.2, 1.0, -0.5], Some("f"), &opts).unwrap();
    eprintln!(
        "slice: {} triangles, lattice {:?}, {} root cells",
        s.mesh.face_count(),
        s.lattice,
        s.root_cells
    );
    let mut g = c.benchmark_group("trivariate_extract");
    g.sample_size(10);
    g.bench_function("isosurface_16cubed_tricubic_1e-3", |b| {
        b.iter(|| isosurface(&m, "f", 0.1, &opts).unwrap());
    });
    g.bench_function("slice_16cubed_tricubic_1e-3", |b| {
        b.iter(|| slice(&m, [0.3, 0.2, 1.0, -0.5], Some("f"), &opts).unwrap());
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
