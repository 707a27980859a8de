//! Isosurface and slice extraction (Martin & Cohen §5.1) on a 16³-control-point tricubic
//! volume with curved geometry and a smooth non-trivial attribute, to flatness 1e-3 of the
//! bounding-box diagonal. Target: isosurface ≤ 0.5 s on 2 cores.

use criterion::{Criterion, criterion_group, criterion_main};
use volmorph_spline::{KnotVector, TensorBSpline};
use volmorph_trivariate::{Aggregate, AggregateVolume, PolygonizeOptions, isosurface, slice};

/// 16³ tricubic volume: a bent, twisted box with a wavy scalar attribute.
fn model() -> AggregateVolume {
    let n = 16;
    let kv = KnotVector::clamped_uniform(3, n, [0.0, 1.0]).unwrap();
    let g = kv.greville();
    let mut pts = Vec::with_capacity(n * n * n * 3);
    let mut vals = Vec::with_capacity(n * n * n);
    for &w in &g {
        for &v in &g {
            for &u in &g {
                let ang = 0.6 * w;
                let (x, y) = (u - 0.5, v - 0.5);
                pts.extend([
                    x * ang.cos() - y * ang.sin() + 0.15 * (3.0 * w).sin(),
                    x * ang.sin() + y * ang.cos(),
                    w + 0.1 * (4.0 * u).sin(),
                ]);
                vals.push(
                    (u - 0.5).powi(2)
                        + (v - 0.45).powi(2)
                        + (w - 0.5).powi(2)
                        + 0.02 * (9.0 * u).sin() * (7.0 * v).cos(),
                );
            }
        }
    }
    let k = [kv.clone(), kv.clone(), kv];
    let geo = TensorBSpline::new(k.clone(), 3, pts).unwrap();
    let attr = TensorBSpline::new(k, 1, vals).unwrap();
    Aggregate::new(geo)
        .unwrap()
        .with_attribute("f", attr)
        .unwrap()
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
