//! Sculpting speed, against the targets (2 cores):
//!
//! * `convex_dab_256` — one dab of a convex brush (a 1 280-triangle sphere of radius 8 cells)
//!   subtracted from a sphere mesh on a 256³ grid, with local re-contour and stitch: target
//!   ≤ 33 ms (30 dabs per second; the thesis reports 20–30 fps for convex tools);
//! * `mesh_tool_dab_256` — the same with a non-convex tool mesh of 5 000 triangles (a torus):
//!   target ≤ 66 ms (the thesis reports 6–15 fps);
//! * `dab_vs_mesh_size/N` — the convex dab on base meshes from 5 120 to 1.3 million
//!   triangles: the time follows the edit's size, not the mesh's.
//!
//! Each iteration applies the dab and then undoes it outside the timed part, so every
//! iteration starts from the same document.
//!
//! Run: `cargo bench -p volmorph-sculpt`

use std::hint::black_box;
use std::sync::Arc;
use std::time::{Duration, Instant};

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use glam::DVec3;
use volmorph_mesh::shapes::{icosphere, torus};
use volmorph_sculpt::{Edit, Op, Pose, SculptDocument, SculptOptions, Tool};

const GRID: usize = 256;

fn document(level: u32) -> SculptDocument {
    let base = icosphere(level, 1.0, DVec3::ZERO).expect("sphere");
    SculptDocument::around(&base, GRID, 2.0, SculptOptions::default()).expect("document")
}

/// A dab on the sphere's surface, half in.
fn dab(tool: &Arc<Tool>) -> Edit {
    Edit::Tool {
        tool: tool.clone(),
        op: Op::Subtract,
        poses: vec![Pose::at(DVec3::new(0.6, 0.48, 0.64).normalize())],
        step: None,
    }
}

/// Time `edit` on `doc`, undoing it after each run.
fn time_dab(c: &mut Criterion, group: &str, id: &str, doc: &mut SculptDocument, edit: &Edit) {
    let first = doc.apply(edit).expect("dab");
    let s = first.stats();
    eprintln!(
        "{group}/{id}: {} triangles, {} rays changed, kept {}, removed {}, added {}; peel {:?}, paint {:?}, contour {:?}, stitch {:?}",
        doc.triangle_count(),
        s.rays_changed,
        s.triangles_kept,
        s.triangles_removed,
        s.triangles_added,
        s.timings.peel,
        s.timings.merge,
        s.timings.contour,
        s.timings.stitch
    );
    doc.undo(&first).expect("undo");
    let mut g = c.benchmark_group(group);
    g.sample_size(20).measurement_time(Duration::from_secs(8));
    g.bench_function(BenchmarkId::from_parameter(id), |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                let t = Instant::now();
                let rec = doc.apply(black_box(edit)).expect("dab");
                total += t.elapsed();
                doc.undo(&rec).expect("undo");
            }
            total
        });
    });
    g.finish();
}

fn bench(c: &mut Criterion) {
    let mut doc = document(6);
    let h = doc.grid().spacing();
    let brush =
        Arc::new(Tool::new(&icosphere(3, 8.0 * h, DVec3::ZERO).expect("brush")).expect("tool"));
    assert!(brush.is_convex());
    time_dab(
        c,
        "convex_dab_256",
        "sphere_brush_r8",
        &mut doc,
        &dab(&brush),
    );

    let ring = torus(6.0 * h, 2.5 * h, 50, 50, DVec3::ZERO).expect("torus");
    let mesh_tool = Arc::new(Tool::new(&ring).expect("tool"));
    assert!(!mesh_tool.is_convex() && mesh_tool.soup().triangles.len() == 5000);
    time_dab(
        c,
        "mesh_tool_dab_256",
        "torus_5k",
        &mut doc,
        &dab(&mesh_tool),
    );

    for level in [4, 6, 8] {
        let mut doc = document(level);
        let n = doc.triangle_count();
        time_dab(
            c,
            "dab_vs_mesh_size",
            &n.to_string(),
            &mut doc,
            &dab(&brush),
        );
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
