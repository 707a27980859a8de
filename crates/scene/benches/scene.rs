//! Scene benchmarks (filled in below).
fn main() {}
