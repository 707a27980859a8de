//! Sizes from options are checked against the memory budget before allocating.
//!
//! This test binary sets a small memory budget for its whole process.

use volmorph_volume::phantom::{self, Phantom};

/// `phantom sphere --kind sdf --size 2000` (32 GB of f32) aborted in the allocator ("memory
/// allocation failed"). The size is now refused with an error naming the budget.
#[test]
fn phantom_sdf_size_2000_aborts_in_allocator() {
    volmorph_io::set_memory_limit(64 << 20);
    let e = phantom::signed_distance(Phantom::Sphere, [2000; 3])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("2000×2000×2000") && e.contains("memory budget"),
        "{e}"
    );
    let e = phantom::density(Phantom::Sphere, [2000; 3])
        .unwrap_err()
        .to_string();
    assert!(e.contains("memory budget"), "{e}");
    // Within the budget the same call works.
    assert!(phantom::signed_distance(Phantom::Sphere, [16; 3]).is_ok());
}
