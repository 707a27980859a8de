//! Direct volume rendering of a synthetic head CT (256 × 256 × 160 voxels of 0.9 × 0.9 ×
//! 1.2 mm, Hounsfield units: air, skin and soft tissue, a skull shell with a cancellous
//! layer, brain) at 512 × 512 with the CT bone preset, shaded, from the anterior view:
//! undeformed, and deformed by a 200-handle affine MLS map sampled on a 33³ grid (target: at
//! most 1.5× the undeformed time), plus the map sampling itself. The comparison with VTK on
//! the real cranium CT is `scripts/dvr_vtk_bench.py`.
//!
//! `cargo bench -p volmorph-render --bench dvr`

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use volmorph_handles::{AffineMls, Weighting};
use volmorph_render::{
    Camera, DEFAULT_FOV_Y, DeformedView, DvrOptions, DvrRenderer, DvrVolume, Framing, Orbit,
    Projection, TransferPreset, UpAxis,
};
use volmorph_testkit::Rng;
use volmorph_volume::{Geometry, Volume};

/// The synthetic head: ellipsoidal shells about the centre, radii in millimetres.
fn head() -> Volume<i16> {
    let g = Geometry::new([256, 256, 160]).with_spacing(DVec3::new(0.9, 0.9, 1.2));
    let (lo, hi) = g.physical_bounds();
    let c = 0.5 * (lo + hi);
    Volume::from_fn(g, |i, j, k| {
        let p = g.index_to_physical(DVec3::new(i as f64, j as f64, k as f64)) - c;
        let r = (p / DVec3::new(95.0, 110.0, 85.0)).length();
        let hu = if r > 1.0 {
            -1000.0
        } else if r > 0.96 {
            40.0 // skin and soft tissue
        } else if r > 0.935 || r <= 0.91 && r > 0.885 {
            1200.0 // outer and inner tables of the skull
        } else if r > 0.885 {
            450.0 // cancellous bone between them
        } else {
            30.0 // brain
        };
        // Noise of ±10 HU, seeded per voxel (the fill may run in parallel).
        let noise = Rng::new((i + 256 * (j + 256 * k)) as u64).unit() - 0.5;
        (hu + 20.0 * noise).round() as i16
    })
    .expect("head volume")
}

fn camera(dv: &DvrVolume) -> Camera {
    Orbit::named("anterior", UpAxis::Z)
        .expect("named view")
        .camera(
            dv.geometry().physical_bounds(),
            Projection::Perspective {
                fov_y: DEFAULT_FOV_Y,
            },
            Framing::Sphere,
            512,
            512,
        )
        .expect("camera")
}

/// The pull-back of 200 handles spread through the box and moved by a smooth bend.
fn mls(dv: &DvrVolume) -> AffineMls {
    let (lo, hi) = dv.geometry().physical_bounds();
    let (c, e) = (0.5 * (lo + hi), hi - lo);
    let mut rng = Rng::new(20_241_201);
    let sources: Vec<DVec3> = (0..200).map(|_| rng.point_in(lo, hi)).collect();
    let targets: Vec<DVec3> = sources
        .iter()
        .map(|&s| {
            let q = (s - c) / e;
            s + DVec3::new(
                0.04 * e.x * (q.z * std::f64::consts::PI).sin(),
                0.03 * e.y * (q.x * std::f64::consts::PI).cos(),
                0.0,
            )
        })
        .collect();
    AffineMls::new(
        &targets,
        &sources,
        Weighting::InverseDistance { alpha: 1.0 },
    )
    .expect("mls")
}

fn bench(c: &mut Criterion) {
    let dv = DvrVolume::from_volume(&head()).expect("prepare");
    let tf = TransferPreset::CtBone.build((0.0, 1.0)).expect("preset");
    let r = DvrRenderer::new(&dv, DvrOptions::new(tf)).expect("renderer");
    let cam = camera(&dv);
    let map = mls(&dv);
    let view = DeformedView::from_map(&dv, &map, [33; 3]).expect("view");
    // The first shaded picture builds the gradient table; keep it out of the timings.
    r.render(&cam).expect("render");
    let mut g = c.benchmark_group("dvr_head_512");
    g.sample_size(10);
    g.bench_function("composite_ct_bone", |b| {
        b.iter(|| r.render(black_box(&cam)).expect("render"));
    });
    g.bench_function("composite_ct_bone_mls200_grid33", |b| {
        b.iter(|| r.render_deformed(&view, black_box(&cam)).expect("render"));
    });
    g.bench_function("sample_mls200_grid33", |b| {
        b.iter(|| DeformedView::from_map(&dv, black_box(&map), [33; 3]).expect("view"));
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
