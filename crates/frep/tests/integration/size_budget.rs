//! Grid sizes from options are checked against the memory budget before allocating.
//!
//! This test binary sets a small memory budget for its whole process.

use volmorph_frep::grid::sample;
use volmorph_frep::{CompileOptions, Tape, compile_source};
use volmorph_volume::Geometry;

/// `frep eval s1_sphere.hf --grid 2000` (32 GB) aborted in the allocator. The grid is now
/// refused with an error naming the grid and the budget.
#[test]
fn frep_eval_grid_2000_aborts_in_allocator() {
    volmorph_io::set_memory_limit(64 << 20);
    let model = compile_source(
        "my_model(x[3], a[1]) { my_model = 1 - x[1]^2 - x[2]^2 - x[3]^2; }",
        &CompileOptions::default(),
    )
    .unwrap();
    let tape = Tape::new(&model);
    let e = sample(&tape, &Geometry::new([2000; 3]))
        .unwrap_err()
        .to_string();
    assert!(e.contains("2000") && e.contains("memory budget"), "{e}");
    let small = sample(&tape, &Geometry::new([8; 3])).unwrap();
    assert_eq!(small.data().len(), 512);
}
