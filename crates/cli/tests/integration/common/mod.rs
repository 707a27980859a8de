//! Running the `volmorph` binary from the end-to-end tests.

#![allow(dead_code)] // each test file uses its own subset

use std::process::{Command, Output};

/// Run `volmorph` with `args`.
pub fn volmorph(args: &[&dyn AsRef<std::ffi::OsStr>]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_volmorph"))
        .args(args.iter().map(|a| a.as_ref()))
        .output()
        .expect("the volmorph binary runs")
}

/// Runs a command that must succeed; returns its standard output.
pub fn ok(args: &[&dyn AsRef<std::ffi::OsStr>]) -> String {
    let out = volmorph(args);
    assert!(
        out.status.success(),
        "volmorph failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("utf-8 output")
}

/// Runs a command that must succeed; returns its standard error (warnings).
pub fn ok_stderr(args: &[&dyn AsRef<std::ffi::OsStr>]) -> String {
    let out = volmorph(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "volmorph failed: {err}");
    err
}

/// Runs a command that must fail cleanly; returns its standard error.
pub fn fails(args: &[&dyn AsRef<std::ffi::OsStr>]) -> String {
    let out = volmorph(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "expected exit 1, stderr: {err}");
    assert!(!err.contains("panicked"), "panic: {err}");
    err
}

/// The voxels of a volume file as `f32`, with its geometry (any voxel type is converted).
pub fn read_f32(path: &std::path::Path) -> volmorph_volume::Volume<f32> {
    let any = volmorph_volume_io::read(path).expect("the volume reads back");
    match any.cast(volmorph_volume::VoxelType::F32, 1.0, 0.0) {
        volmorph_volume::AnyVolume::F32(v) => v,
        _ => unreachable!("cast to f32"),
    }
}

/// The value of the voxel nearest the physical point `p`, `None` outside the grid.
pub fn nearest(v: &volmorph_volume::Volume<f32>, p: glam::DVec3) -> Option<f32> {
    let u = v.geometry().physical_to_index(p).round();
    if u.min_element() < 0.0 {
        return None;
    }
    v.get(u.x as usize, u.y as usize, u.z as usize)
}

/// Fraction (0 to 1) of the pixels of a PNG that are not the white background.
pub fn covered_fraction(path: &std::path::Path) -> f64 {
    let img = volmorph_render::read_png(path).expect("a PNG");
    let fg = img
        .pixels()
        .iter()
        .filter(|p| **p != [255, 255, 255, 255])
        .count();
    fg as f64 / img.pixels().len() as f64
}
