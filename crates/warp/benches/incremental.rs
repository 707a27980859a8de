//! Incremental push-forward (True 1992 §5.3 main loop): a 128³ volume under True's 9×9×9
//! uniform cubic lattice around the volume's bounds; one interior control point is moved
//! (alternately there and back, so the state stays bounded) and the push-forward updated.
//! A direct-manipulation drag of the point at an interior control point's place, with a tool
//! radius of half a region (so the least-norm solve moves that one control point): solve plus
//! incremental update, each run starting from the same lattice (restored untimed by undo).
//! For scale, the full antialiased push-forward of the same volume and the engine's set-up.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use std::time::{Duration, Instant};

use volmorph_lattice::BSplineLattice;
use volmorph_lattice::manipulate::{Drag, DragOptions, ManipulationSession};
use volmorph_volume::{Geometry, Volume};
use volmorph_warp::incremental::IncrementalPushForward;
use volmorph_warp::pushforward::{AntialiasOptions, push_forward_antialiased_f32};

/// Displace control points of the engine's lattice (`(index, delta)` pairs) through the
/// generic parameter interface.
fn move_cps(
    e: &mut IncrementalPushForward<BSplineLattice>,
    moves: &[([usize; 3], DVec3)],
) -> Result<volmorph_warp::incremental::UpdateReport, volmorph_warp::WarpError> {
    let changes = e
        .map()
        .changes_for_displacements(moves)
        .map_err(volmorph_warp::WarpError::Parameters)?;
    e.set_parameters(&changes)
}

fn bench(c: &mut Criterion) {
    let grid = Geometry::new([128, 128, 128]);
    let input = Volume::from_fn(grid, |i, j, k| ((i ^ j ^ k) & 0xff) as u8).expect("volume");
    let (lo, hi) = grid.physical_bounds();
    let mut lattice = BSplineLattice::uniform_cubic_around(lo, hi, [9, 9, 9]).expect("lattice");
    // A deformed starting state, so the moved point's region is not the identity.
    lattice
        .move_control_point([3, 5, 4], DVec3::new(4.0, -3.0, 2.0))
        .expect("move");
    let opts = AntialiasOptions::default();
    let mut g = c.benchmark_group("incremental_128^3_lattice_9x9x9");
    g.sample_size(20);
    let mut engine =
        IncrementalPushForward::new(&input, lattice.clone(), &grid, &opts).expect("engine");
    let mut sign = 1.0;
    g.bench_function("move_one_interior_point", |b| {
        b.iter(|| {
            sign = -sign;
            move_cps(
                &mut engine,
                &[([4, 4, 4], DVec3::new(3.0, -2.0, 1.5) * sign)],
            )
            .expect("update")
        });
    });
    engine.set_map(lattice.clone()).expect("reset");
    let centre = lattice.control_point([4, 4, 4]).expect("control point");
    let region = (lattice.control_point([5, 4, 4]).expect("control point") - centre).length();
    let mut session =
        ManipulationSession::new(lattice.clone(), DragOptions::with_radius(0.5 * region))
            .expect("session");
    let step = DVec3::new(0.3, -0.2, 0.25) * region;
    g.bench_function("drag_solve_and_update", |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                let start = Instant::now();
                session
                    .drag(&[Drag::new(centre, centre + step)])
                    .expect("drag");
                engine.set_map(session.lattice().clone()).expect("update");
                total += start.elapsed();
                session.undo();
                engine.set_map(session.lattice().clone()).expect("undo");
            }
            total
        });
    });
    g.sample_size(10);
    g.bench_function("full_push_forward_f32", |b| {
        b.iter(|| push_forward_antialiased_f32(&input, &lattice, &grid, &opts).expect("full"));
    });
    g.bench_function("engine_set_up", |b| {
        b.iter(|| IncrementalPushForward::new(&input, lattice.clone(), &grid, &opts).expect("new"));
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
