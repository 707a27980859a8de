//! Helpers shared by the deform integration tests.
#![allow(dead_code)] // each test file uses its own subset

use std::path::PathBuf;

use glam::DVec3;

/// A small deterministic generator (64-bit LCG, top 53 bits as a fraction).
pub struct Lcg(pub u64);

impl Lcg {
    /// Next value in `[0, 1)`.
    pub fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    /// A point of `[0, 1)³`.
    pub fn vec(&mut self) -> DVec3 {
        DVec3::new(self.next(), self.next(), self.next())
    }
    /// A point of `[-1, 1)³`.
    pub fn signed(&mut self) -> DVec3 {
        self.vec() * 2.0 - 1.0
    }
}

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
