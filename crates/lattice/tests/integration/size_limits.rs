//! Lattice creation refuses nets larger than the readers accept, before allocating.

use volmorph_deform::DeformError;
use volmorph_lattice::BSplineLattice;
use volmorph_lattice::json::MAX_CONTROL_POINTS;
use volmorph_volume::DVec3;

/// Issue: `lattice init VOL --counts 1000,1000,1000`, `drag … --counts 700,700,700` and
/// `lattice init --mesh … --size 700,700,700` aborted with "memory allocation failed".
#[test]
fn lattice_init_huge_counts_abort() {
    let (lo, hi) = (DVec3::ZERO, DVec3::ONE);
    for counts in [[1000, 1000, 1000], [700, 700, 700], [usize::MAX, 4, 4]] {
        let e = BSplineLattice::uniform_cubic_around(lo, hi, counts).unwrap_err();
        assert!(
            matches!(e, DeformError::TooManyControlPoints { max, .. } if max == MAX_CONTROL_POINTS),
            "{counts:?}: {e}"
        );
        assert!(e.to_string().contains("control points"), "{e}");
        for degree in [1, 2, 3] {
            let d = [degree; 3];
            let e = BSplineLattice::feng_uniform_around(lo, hi, d, counts).unwrap_err();
            assert!(matches!(e, DeformError::TooManyControlPoints { .. }), "{e}");
            let e = BSplineLattice::feng_end_interpolating_around(lo, hi, d, counts).unwrap_err();
            assert!(matches!(e, DeformError::TooManyControlPoints { .. }), "{e}");
        }
    }
    // Just within the cap in count is still subject to the memory budget, and a normal
    // lattice is built as before.
    let at_cap = volmorph_lattice::lattice::check_net_size([1 << 9, 1 << 9, 1 << 10]);
    if volmorph_io::memory_limit() >= (MAX_CONTROL_POINTS as u64) * 24 {
        assert_eq!(at_cap.unwrap(), MAX_CONTROL_POINTS);
    } else {
        assert!(at_cap.unwrap_err().to_string().contains("memory budget"));
    }
    let l = BSplineLattice::uniform_cubic_around(lo, hi, [9, 9, 9]).unwrap();
    assert_eq!(l.counts(), [9, 9, 9]);
}
