//! Criterion benchmarks of mesh FFD (filled in below).
fn main() {}
