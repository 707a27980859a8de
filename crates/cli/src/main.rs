//! The `volmorph` command-line tool.

fn main() {}
