//! elastix transform parameter files as elastix writes them (`tests/corpus/elastix5`: an
//! affine → B-spline chain by itk-elastix 0.25.4), read as the maps transformix applies.

use std::path::{Path, PathBuf};

use glam::DVec3;
use volmorph_deform::SpaceMap;
use volmorph_maps::{AnyMap, elastix, read_map};

fn corpus() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus/elastix5")
}

/// Largest difference per coordinate between volmorph and transformix's `outputpoints.txt`:
/// transformix prints every coordinate with 6 decimals (`std::fixed` at the default
/// precision, elastix's `TransformBase::TransformPointsSomePoints`), half a unit of the last
/// decimal; its B-spline and affine arithmetic is f64, as volmorph's.
const TRANSFORMIX_OUTPUTPOINTS_ROUNDING: f64 = 5e-7;

/// Points of the fixed image and beyond it (the last outside the B-spline's control grid,
/// where only the affine moves it), and transformix's `OutputPoint`s for them, copied from
/// its `outputpoints.txt` (transformix reading `TransformParameters.1.txt`, see the corpus
/// README).
const TRANSFORMIX: [([f64; 3], [f64; 3]); 6] = [
    ([-12.0, -6.0, 20.0], [-11.177439, -6.213548, 20.942042]),
    ([0.5, 3.25, 27.0], [-2.022026, 3.114613, 25.902631]),
    ([10.0, 12.0, 40.0], [5.617359, 12.942997, 36.323217]),
    ([-3.0, -10.0, 33.5], [-2.584036, -8.615874, 31.546530]),
    ([6.0, 0.0, 14.0], [3.466214, -0.982865, 13.837774]),
    ([-60.0, 30.0, 90.0], [-60.528862, 34.637879, 89.344257]),
];

/// The largest difference per coordinate between `map` and transformix.
fn off_transformix(map: &AnyMap) -> f64 {
    TRANSFORMIX
        .iter()
        .map(|(x, want)| {
            let got = map.apply(DVec3::from_array(*x));
            (got - DVec3::from_array(*want)).abs().max_element()
        })
        .fold(0.0, f64::max)
}

/// elastix 5.2 renamed the chain entry `InitialTransformParametersFileName` to
/// `InitialTransformParameterFileName`; a reader that knew only the old name skipped the new
/// one and read an affine → B-spline chain as its B-spline alone (millimetres off), without
/// an error.
#[test]
fn elastix5_initial_transform_key_is_ignored() {
    let path = corpus().join("TransformParameters.1.txt");
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("(InitialTransformParameterFileName \"out/TransformParameters.0.txt\")"));
    let map = read_map(&path).unwrap();
    let AnyMap::Compose(parts) = &map else {
        panic!("read as a {} map, not the chain", map.kind())
    };
    assert_eq!(
        parts.iter().map(AnyMap::kind).collect::<Vec<_>>(),
        ["affine", "bspline-lattice"]
    );
    let off = off_transformix(&map);
    assert!(off <= TRANSFORMIX_OUTPUTPOINTS_ROUNDING, "{off}");
    // The points move by millimetres, and the B-spline alone (the old misreading) misses
    // transformix by millimetres: the comparison sees the fault.
    let moved = TRANSFORMIX
        .iter()
        .map(|(x, y)| (DVec3::from_array(*y) - DVec3::from_array(*x)).length())
        .fold(0.0, f64::max);
    assert!(moved > 4.0, "{moved}");
    let (alone, initial) = elastix::parse_elastix(&text).unwrap();
    assert_eq!(initial.as_deref(), Some("out/TransformParameters.0.txt"));
    assert!(off_transformix(&alone) > 1.0);

    // The entry spelled as elastix up to 5.1 writes it reads the same chain.
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(
        corpus().join("TransformParameters.0.txt"),
        dir.path().join("TransformParameters.0.txt"),
    )
    .unwrap();
    let old = dir.path().join("TransformParameters.1.txt");
    std::fs::write(
        &old,
        text.replace(
            "(InitialTransformParameterFileName ",
            "(InitialTransformParametersFileName ",
        ),
    )
    .unwrap();
    let off = off_transformix(&read_map(&old).unwrap());
    assert!(off <= TRANSFORMIX_OUTPUTPOINTS_ROUNDING, "{off}");
}

/// An entry elastix reads that volmorph does not know is refused with the file, line and
/// entry named, in any file of the chain.
#[test]
fn unknown_entries_of_an_elastix_chain_are_refused_naming_file_and_entry() {
    let dir = tempfile::tempdir().unwrap();
    let t0 = dir.path().join("TransformParameters.0.txt");
    let t1 = dir.path().join("TransformParameters.1.txt");
    let affine = std::fs::read_to_string(corpus().join("TransformParameters.0.txt")).unwrap();
    std::fs::copy(corpus().join("TransformParameters.1.txt"), &t1).unwrap();
    let cases = [
        ("(SomeFutureEntry 1)", "(SomeFutureEntry …)"),
        (
            "(ITKTransformParameters 1 0 0 0 1 0 0 0 1 0 0 0)",
            "ITKTransformParameters",
        ),
        ("(UseDirectionCosines \"false\")", "UseDirectionCosines"),
        ("(HowToCombineTransforms \"Add\")", "HowToCombineTransforms"),
    ];
    for (entry, named) in cases {
        let key = entry[1..].split_whitespace().next().unwrap();
        let text: String = affine
            .lines()
            .filter(|l| !l.starts_with(&format!("({key} ")))
            .chain([entry])
            .map(|l| format!("{l}\n"))
            .collect();
        std::fs::write(&t0, text).unwrap();
        let e = read_map(&t1).unwrap_err().to_string();
        assert!(e.starts_with(&t0.display().to_string()), "{e}");
        assert!(e.contains(named), "{e}");
        assert!(e.contains("line "), "{e}");
    }
}
