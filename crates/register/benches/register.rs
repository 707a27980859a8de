//! Benchmarks of the registration workbench:
//!
//! * `live/correct_343` — correcting one of 343 correspondences updates the 32³ preview grid
//!   over a 256×256×112 volume (thesis Table 5.2: 0.3–0.8 ms; target ≤ 0.5 ms), for affine and
//!   frame MLS;
//! * `match/ncc_64_handles` — NCC matching of 64 handles (window 11³, search ±4, 1 level, with
//!   sub-voxel refinement) on a 96×80×72 lung phantom pair;
//! * `dense/refine` — a dense refinement (MI, 2 levels, 15 iterations each) of the same pair.
//!
//! `cargo bench -p volmorph-register`

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use volmorph_maps::HandleMethod;
use volmorph_register::dense::{DenseOptions, refine};
use volmorph_register::live::{LivePreview, THESIS_GRID_NODES};
use volmorph_register::matching::{Correspondence, MatchOptions, MatchStatus, match_handles};
use volmorph_register::phantom::{LungPhantomOptions, lung_phantom};
use volmorph_register::select::{SelectOptions, select_handles};
use volmorph_register::solve::{SolveOptions, handle_map};
use volmorph_testkit::Rng;
use volmorph_volume::Geometry;

fn live(c: &mut Criterion) {
    let grid = Geometry::new([256, 256, 112]).with_spacing(DVec3::new(0.9, 0.9, 2.5));
    let (lo, hi) = grid.physical_bounds();
    let mut rng = Rng::new(11);
    let corr: Vec<Correspondence> = (0..343)
        .map(|_| {
            let p = rng.point_in(lo, hi);
            Correspondence {
                source: p,
                target: p + rng.point(3.0),
                ncc: 1.0,
                distinctness: 1.0,
                confidence: 1.0,
                residual: 0.0,
                axes: glam::DMat3::IDENTITY,
                status: MatchStatus::Accepted,
            }
        })
        .collect();
    for method in [
        HandleMethod::Affine,
        HandleMethod::Frames,
        HandleMethod::Tps,
    ] {
        let map = handle_map(
            &corr,
            &SolveOptions {
                method,
                ..SolveOptions::default()
            },
        )
        .unwrap();
        let mut preview = LivePreview::new(&map, &grid, [THESIS_GRID_NODES; 3]).unwrap();
        preview.select(100).unwrap();
        let base = corr[100].target;
        let mut t = 0.0f64;
        c.bench_function(&format!("live/correct_343_{}", method.name()), |b| {
            b.iter(|| {
                t += 0.01;
                preview
                    .correct(100, base + DVec3::new(t.sin(), t.cos(), 0.0))
                    .unwrap();
            });
        });
    }
}

fn matching_and_dense(c: &mut Criterion) {
    let p = lung_phantom(&LungPhantomOptions::default()).unwrap();
    let h = select_handles(
        &p.inhale,
        None,
        &SelectOptions {
            count: 64,
            radius: 12.0,
            ..SelectOptions::default()
        },
    )
    .unwrap();
    let src: Vec<DVec3> = h.iter().map(|h| h.position).collect();
    let o = MatchOptions {
        levels: 1,
        ..MatchOptions::default()
    };
    let mut g = c.benchmark_group("slow");
    g.sample_size(10);
    g.bench_function("match/ncc_64_handles", |b| {
        b.iter(|| match_handles(&p.inhale, &p.exhale, &src, None, &o).unwrap());
    });
    let d = DenseOptions {
        levels: 2,
        iterations: 15,
        ..DenseOptions::default()
    };
    g.bench_function("dense/refine", |b| {
        b.iter(|| {
            refine(
                &p.inhale,
                &p.exhale,
                &volmorph_deform::Identity,
                &[],
                None,
                &d,
            )
            .unwrap()
        });
    });
    g.finish();
}

criterion_group!(benches, live, matching_and_dense);
criterion_main!(benches);
