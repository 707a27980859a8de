//! Ray–boundary intersection rate on the GRIN lens and on a rational tricubic volume, and a
//! 256×256 volume rendering of the GRIN lens's index attribute.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::DVec3;
use volmorph_render::{Colormap, DEFAULT_FOV_Y, Framing, Projection, view_camera};
use volmorph_spline::{KnotVector, TensorBSpline};
use volmorph_testkit::Rng;
use volmorph_trivariate::{
    GRIN_ATTRIBUTE, GrinLensSpec, RayTracer, RenderOptions, TraceOptions, TransferFunction,
    VolumeRenderer, grin_lens,
};

fn curved() -> TensorBSpline<3> {
    let kv = KnotVector::clamped_uniform(3, 5, [0.0, 1.0]).expect("knots");
    let mut pts = Vec::new();
    let mut ws = Vec::new();
    for k in 0..5 {
        for j in 0..5 {
            for i in 0..5 {
                let (x, y, z) = (f64::from(i), f64::from(j), f64::from(k));
                pts.extend([
                    x + 0.2 * (y * z).sin(),
                    y + 0.15 * (x * 1.3).cos(),
                    z + 0.1 * x * y / 4.0,
                ]);
                ws.push(1.0 + 0.1 * ((i + 2 * j + k) % 3) as f64);
            }
        }
    }
    TensorBSpline::new_rational([kv.clone(), kv.clone(), kv], 3, pts, ws).expect("volume")
}

/// `n` rays from `eye` towards points uniform in the box `[lo, hi]` (seeded).
fn rays(eye: [f64; 3], lo: [f64; 3], hi: [f64; 3], n: usize) -> Vec<([f64; 3], [f64; 3])> {
    let mut rng = Rng::new(0x5eed);
    (0..n)
        .map(|_| {
            let target: [f64; 3] = std::array::from_fn(|c| rng.range(lo[c], hi[c]));
            (eye, std::array::from_fn(|c| target[c] - eye[c]))
        })
        .collect()
}

fn intersect(c: &mut Criterion) {
    let lens = grin_lens(&GrinLensSpec::default()).expect("lens");
    let lens_tracer = RayTracer::new(&lens, TraceOptions::default()).expect("tracer");
    let curved_tracer =
        RayTracer::from_geometry(&curved(), TraceOptions::default()).expect("tracer");
    let n = 1000;
    let mut g = c.benchmark_group("intersect");
    g.throughput(Throughput::Elements(n as u64));
    for (name, tracer) in [
        ("grin_lens", &lens_tracer),
        ("rational_tricubic", &curved_tracer),
    ] {
        let (lo, hi) = tracer.bounds();
        let eye = [hi[0] + 2.0 * tracer.diagonal(), hi[1] + 0.7, hi[2] + 1.3];
        let rs = rays(eye, lo, hi, n);
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut hits = 0;
                for (o, d) in &rs {
                    hits += tracer.intersect(*o, *d).expect("intersect").len();
                }
                black_box(hits)
            });
        });
    }
    g.finish();
}

fn render(c: &mut Criterion) {
    let lens = grin_lens(&GrinLensSpec::default()).expect("lens");
    let tracer = RayTracer::new(&lens, TraceOptions::default()).expect("tracer");
    let tf = TransferFunction::ramp(1.125, 1.5, Colormap::Viridis, 0.9).expect("transfer");
    let opts = RenderOptions::for_diagonal(tracer.diagonal());
    let r = VolumeRenderer::new(&lens, &tracer, GRIN_ATTRIBUTE, tf, opts).expect("renderer");
    let (lo, hi) = tracer.bounds();
    let (lo, hi) = (DVec3::from_array(lo), DVec3::from_array(hi));
    let cam = view_camera(
        DVec3::new(1.0, 0.6, 0.5),
        DVec3::Z,
        (lo, hi),
        Projection::Perspective {
            fov_y: DEFAULT_FOV_Y,
        },
        Framing::Sphere,
        (256, 256),
    )
    .expect("camera");
    let mut g = c.benchmark_group("render");
    g.sample_size(10);
    g.bench_function("grin_lens_256x256", |b| {
        b.iter(|| black_box(r.render_image(&cam).expect("render")));
    });
    g.finish();
}

criterion_group!(benches, intersect, render);
criterion_main!(benches);
