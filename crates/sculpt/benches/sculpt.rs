//! Sculpting benchmarks (filled in below).
fn main() {}
