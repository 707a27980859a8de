//! Handle-driven deformations against the targets of McPhail's thesis (Table 4.1, §5.5.4)
//! and the thin-plate targets: 2D rigid MLS on a 100×100 grid (11 points; 7 segments), 3D
//! affine MLS on a 32³ grid with 200 handles (set-up, update after one handle moves), and
//! a 1000-landmark thin-plate spline (factorisation, re-solve, 32³ grid evaluation).

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use glam::{DVec2, DVec3};
use volmorph_deform::{LiveGrid, SpaceMap};
use volmorph_handles::mls2d::{Mls2dHandles, Mls2dKind, image_grid};
use volmorph_handles::volume_spline::VolumeSplineSystem;
use volmorph_handles::{
    AffineMls, Frame, FrameMls, RigidMls, SimilarityMls, ThinPlateMap, Weighting,
};
use volmorph_volume::Geometry;

/// Deterministic pseudo-random numbers in [0, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((self.0 >> 11) as f64) / ((1u64 << 53) as f64)
    }
}

fn bench_2d(c: &mut Criterion) {
    let mut r = Lcg(7);
    let points: Vec<DVec2> = (0..11)
        .map(|_| DVec2::new(50.0 + 400.0 * r.next(), 50.0 + 400.0 * r.next()))
        .collect();
    let targets: Vec<DVec2> = points
        .iter()
        .map(|p| *p + DVec2::new(40.0 * r.next() - 20.0, 40.0 * r.next() - 20.0))
        .collect();
    let verts = image_grid(500, 500, 100, 100).expect("grid");
    let h = Mls2dHandles::new(&points, &[], 1.0).expect("handles");
    let plan = h.plan(&verts, Mls2dKind::Rigid).expect("plan");
    let mut out = vec![DVec2::ZERO; verts.len()];
    let mut g = c.benchmark_group("mls2d_100x100");
    g.bench_function("rigid_11_points_deform", |b| {
        b.iter(|| plan.deform(&targets, &mut out).expect("deform"));
    });
    let segs: Vec<[DVec2; 2]> = (0..7)
        .map(|_| {
            let a = DVec2::new(50.0 + 400.0 * r.next(), 50.0 + 400.0 * r.next());
            [
                a,
                a + DVec2::new(60.0 * r.next() + 10.0, 60.0 * r.next() - 30.0),
            ]
        })
        .collect();
    let hs = Mls2dHandles::new(&[], &segs, 2.0).expect("segments");
    let seg_targets: Vec<DVec2> = segs
        .iter()
        .flat_map(|s| [s[0] + DVec2::new(5.0, 3.0), s[1] - DVec2::new(2.0, 4.0)])
        .collect();
    let splan = hs.plan(&verts, Mls2dKind::Rigid).expect("plan");
    g.bench_function("rigid_7_segments_deform", |b| {
        b.iter(|| splan.deform(&seg_targets, &mut out).expect("deform"));
    });
    g.bench_function("rigid_7_segments_plan", |b| {
        b.iter(|| hs.plan(&verts, Mls2dKind::Rigid).expect("plan"));
    });
    g.finish();
}

fn bench_3d(c: &mut Criterion) {
    let mut r = Lcg(11);
    // A 256×256×112 CT-like volume with 1 mm voxels; 200 handles inside it.
    let vol = Geometry::new([256, 256, 112]);
    let src: Vec<DVec3> = (0..200)
        .map(|_| DVec3::new(255.0 * r.next(), 255.0 * r.next(), 111.0 * r.next()))
        .collect();
    let dst: Vec<DVec3> = src
        .iter()
        .map(|p| {
            *p + DVec3::new(
                8.0 * r.next() - 4.0,
                8.0 * r.next() - 4.0,
                4.0 * r.next() - 2.0,
            )
        })
        .collect();
    let grid = vol.resampled([32, 32, 32]);
    let map = AffineMls::new(&src, &dst, Weighting::default()).expect("mls");
    let mut g = c.benchmark_group("mls3d_affine_200_handles_32cubed");
    g.sample_size(10);
    g.bench_function("setup", |b| {
        b.iter(|| LiveGrid::new(map.clone(), grid).expect("grid"));
    });
    let mut hg = LiveGrid::new(map.clone(), grid).expect("grid");
    let mut step = 0.0;
    g.bench_function("move_one_handle", |b| {
        b.iter(|| {
            step += 0.01;
            hg.move_parameter(17, dst[17] + DVec3::new(step, 0.0, 0.0))
                .expect("move");
        });
    });
    hg.select(17).expect("select");
    g.bench_function("drag_selected_handle", |b| {
        b.iter(|| {
            step += 0.01;
            hg.drag_selected(dst[17] + DVec3::new(0.0, step, 0.0))
                .expect("drag");
        });
    });
    g.finish();

    // Analytic Jacobians (and `apply` for comparison) of the 3D MLS maps, 200 handles, at
    // 1000 points of the volume.
    let probes: Vec<DVec3> = (0..1000)
        .map(|_| DVec3::new(255.0 * r.next(), 255.0 * r.next(), 111.0 * r.next()))
        .collect();
    let fs: Vec<Frame> = src.iter().map(|&o| Frame::at(o)).collect();
    let ft: Vec<Frame> = dst.iter().map(|&o| Frame::at(o)).collect();
    let maps: Vec<(&str, Box<dyn SpaceMap>)> = vec![
        ("affine", Box::new(map.clone())),
        (
            "similarity",
            Box::new(SimilarityMls::new(&src, &dst, Weighting::default()).expect("mls")),
        ),
        (
            "rigid",
            Box::new(RigidMls::new(&src, &dst, Weighting::default()).expect("mls")),
        ),
        (
            "frame",
            Box::new(FrameMls::new(&fs, &ft, 1.0, Weighting::default()).expect("mls")),
        ),
    ];
    let mut g = c.benchmark_group("mls3d_200_handles_1000_points");
    g.sample_size(10);
    for (name, m) in &maps {
        g.bench_function(format!("{name}_apply"), |b| {
            b.iter(|| probes.iter().map(|&p| m.apply(p)).sum::<DVec3>());
        });
        g.bench_function(format!("{name}_jacobian"), |b| {
            b.iter(|| probes.iter().map(|&p| m.jacobian(p).x_axis).sum::<DVec3>());
        });
    }
    g.finish();

    // Thin-plate spline through 1000 landmarks.
    let src: Vec<DVec3> = (0..1000)
        .map(|_| DVec3::new(255.0 * r.next(), 255.0 * r.next(), 111.0 * r.next()))
        .collect();
    let dst: Vec<DVec3> = src
        .iter()
        .map(|p| {
            *p + DVec3::new(
                6.0 * r.next() - 3.0,
                6.0 * r.next() - 3.0,
                6.0 * r.next() - 3.0,
            )
        })
        .collect();
    let centres: Vec<[f64; 3]> = src.iter().map(|p| p.to_array()).collect();
    let mut g = c.benchmark_group("tps_1000_landmarks");
    g.sample_size(10);
    g.bench_function("factorise", |b| {
        b.iter(|| VolumeSplineSystem::<3>::new(&centres, 0.0).expect("system"));
    });
    let mut tps = ThinPlateMap::new(&src, &dst, 0.0).expect("tps");
    g.bench_function("resolve_after_drag", |b| {
        b.iter(|| {
            step += 0.01;
            tps.move_target(3, dst[3] + DVec3::new(step, 0.0, 0.0))
                .expect("move");
        });
    });
    let mut out = vec![DVec3::ZERO; grid.len()];
    g.bench_function("evaluate_32cubed", |b| {
        b.iter(|| tps.apply_grid(&grid, &mut out).expect("grid"));
    });
    g.bench_function("evaluate_32cubed_batch", |b| {
        b.iter_batched_ref(
            || {
                let mut pts = Vec::with_capacity(grid.len());
                for k in 0..32 {
                    for j in 0..32 {
                        for i in 0..32 {
                            pts.push(grid.index_to_physical(DVec3::new(
                                f64::from(i),
                                f64::from(j),
                                f64::from(k),
                            )));
                        }
                    }
                }
                pts
            },
            |pts| tps.apply_batch(pts, &mut out).expect("batch"),
            BatchSize::LargeInput,
        );
    });
    g.finish();
}

criterion_group!(benches, bench_2d, bench_3d);
criterion_main!(benches);
