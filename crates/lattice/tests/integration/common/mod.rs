//! Helpers shared by the deform integration tests.
#![allow(dead_code)] // each test file uses its own subset

use std::path::PathBuf;

/// A path in the test's scratch folder.
pub fn tmp(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name)
}

/// Row-major direction of the ITK and plastimatch reference files: Rz(0.4)·Ry(−0.7)·Rx(1.1) with the third column
/// negated (a left-handed frame), as printed by Python's `repr`.
pub const REF_DIRECTION: [f64; 9] = [
    0.7044663052755917,
    -0.7054488206087492,
    -0.07790498208126101,
    0.2978435767000479,
    0.19421234020899739,
    0.9346500792965607,
    0.644217687237691,
    0.681632986593423,
    -0.34692944965489897,
];
