//! Throughput of the shared picture layer: scalar-field colour mapping, PNG encoding, and
//! camera rays intersected with a box (the first step of every ray caster).

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::DVec3;
use volmorph_render::{
    Aabb, Camera, Colormap, Projection, ScalarStyle, Window, encode_png_rgba, render_scalar_with,
};

const W: u32 = 1024;
const H: u32 = 1024;

fn field() -> Vec<f32> {
    (0..W * H)
        .map(|i| {
            let (x, y) = ((i % W) as f32, (i / W) as f32);
            (x * 0.01).sin() * (y * 0.013).cos() * 100.0
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let values = field();
    let window = Window::from_percentiles(&values, 1.0, 99.0).expect("finite field");
    let mut group = c.benchmark_group("render");
    group.throughput(Throughput::Elements(u64::from(W * H)));
    for (name, style) in [
        (
            "scalar_viridis_1024",
            ScalarStyle::new(window, Colormap::Viridis),
        ),
        (
            "scalar_coolwarm_diverging_1024",
            ScalarStyle::new(window, Colormap::CoolWarm)
                .with_diverging_center(0.0)
                .expect("finite centre"),
        ),
    ] {
        group.bench_function(name, |b| {
            b.iter(|| render_scalar_with(black_box(&values), W, H, &style).expect("sizes match"));
        });
    }
    group.bench_function("percentile_window_1024", |b| {
        b.iter(|| Window::from_percentiles(black_box(&values), 1.0, 99.0).expect("finite"));
    });
    let img = render_scalar_with(&values, W, H, &ScalarStyle::new(window, Colormap::Turbo))
        .expect("sizes match");
    group.bench_function("png_encode_rgba_1024", |b| {
        b.iter(|| encode_png_rgba(black_box(&img)).expect("encodes"));
    });
    let cam = Camera::look_at(
        DVec3::new(3.0, -4.0, 2.0),
        DVec3::ZERO,
        DVec3::Z,
        Projection::Perspective { fov_y: 0.7 },
        W,
        H,
    )
    .expect("valid camera");
    let bbox = Aabb::new(DVec3::splat(-1.0), DVec3::splat(1.0)).expect("valid box");
    group.bench_function("camera_rays_aabb_1024", |b| {
        b.iter(|| {
            let mut hits = 0u32;
            for y in 0..H {
                for x in 0..W {
                    hits += u32::from(bbox.intersect(&cam.ray(x, y)).is_some());
                }
            }
            black_box(hits)
        });
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
