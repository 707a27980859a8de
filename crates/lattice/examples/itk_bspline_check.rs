//! Writes a random cubic B-spline lattice as an ITK transform file and the lattice's images of
//! random points, for comparison with ITK's `TransformPoint` (`scripts/itk_bspline_check.py`).
//!
//! Usage: `itk_bspline_check OUT.tfm POINTS.txt [SEED] [NPOINTS]`. A plastimatch file is also
//! written next to `OUT.tfm` (extension `.bxf`): the same control grid and displacements in an
//! axis-aligned frame (plastimatch 1.10's `xf-convert` evaluates rotated grids inconsistently,
//! see `volmorph_lattice::formats::bxf`). `POINTS.txt` gets one line
//! `x y z  X Y Z` per point (`X = apply(x)`), points drawn from the lattice box grown by 10 %
//! of its size on each side, so that some fall outside (and are not moved).
//!
//! `itk_bspline_check --read IN POINTS.txt` reads a transform file (an ITK `.tfm` / `.txt`, or
//! a plastimatch `.bxf`) and prints `X Y Z = apply(x)` for each line `x y z …` of
//! `POINTS.txt`.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use glam::{DMat3, DQuat, DVec3};
use volmorph_deform::SpaceMap;
use volmorph_lattice::BSplineLattice;
use volmorph_lattice::formats::itk_tfm::write_itk_tfm;

/// xorshift64* generator: reproducible uniform numbers in `[0, 1)` without dependencies.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }

    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() == 4 && args[1] == "--read" {
        return read_and_apply(&args[2], &args[3]);
    }
    if args.len() < 3 {
        bail!("usage: itk_bspline_check OUT.tfm POINTS.txt [SEED] [NPOINTS]");
    }
    let tfm = PathBuf::from(&args[1]);
    let points = PathBuf::from(&args[2]);
    let seed: u64 = args.get(3).map_or(Ok(1), |s| s.parse()).context("SEED")?;
    let npoints: usize = args
        .get(4)
        .map_or(Ok(200), |s| s.parse())
        .context("NPOINTS")?;
    let mut rng = Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1);

    let rot = DQuat::from_euler(
        glam::EulerRot::ZYX,
        rng.range(-1.0, 1.0),
        rng.range(-1.0, 1.0),
        rng.range(-1.0, 1.0),
    );
    let mut axes = DMat3::from_quat(rot);
    if rng.next() < 0.5 {
        // Left-handed frames occur too (flipped image axes).
        axes.z_axis = -axes.z_axis;
    }
    let corner = DVec3::new(
        rng.range(-50.0, 50.0),
        rng.range(-50.0, 50.0),
        rng.range(-50.0, 50.0),
    );
    let extent = DVec3::new(
        rng.range(10.0, 80.0),
        rng.range(10.0, 80.0),
        rng.range(10.0, 80.0),
    );
    let counts = [
        4 + (rng.next() * 5.0) as usize,
        4 + (rng.next() * 5.0) as usize,
        4 + (rng.next() * 5.0) as usize,
    ];
    let mut lat = BSplineLattice::uniform_cubic_in_box(corner, axes, extent, counts)?;
    let cell = lat.frame().spacing().min_element();
    for k in 0..counts[2] {
        for j in 0..counts[1] {
            for i in 0..counts[0] {
                let d = DVec3::new(
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                );
                lat.move_control_point([i, j, k], 0.3 * cell * d)?;
            }
        }
    }
    write_itk_tfm(&tfm, &lat)?;
    let mut aligned =
        BSplineLattice::uniform_cubic_in_box(corner, DMat3::IDENTITY, extent, counts)?;
    for k in 0..counts[2] {
        for j in 0..counts[1] {
            for i in 0..counts[0] {
                aligned.move_control_point([i, j, k], lat.displacement([i, j, k])?)?;
            }
        }
    }
    volmorph_lattice::formats::bxf::write_bxf(&tfm.with_extension("bxf"), &aligned)?;

    let mut out = String::new();
    for _ in 0..npoints {
        let u = DVec3::new(
            rng.range(-0.1, 1.1) * extent.x,
            rng.range(-0.1, 1.1) * extent.y,
            rng.range(-0.1, 1.1) * extent.z,
        );
        let p = corner + axes * u;
        let q = lat.apply(p);
        writeln!(
            out,
            "{:?} {:?} {:?} {:?} {:?} {:?}",
            p.x, p.y, p.z, q.x, q.y, q.z
        )?;
    }
    std::fs::write(&points, out).with_context(|| points.display().to_string())?;
    println!(
        "lattice {counts:?} control points, box corner {corner}, extent {extent}, {} handed",
        if axes.determinant() > 0.0 {
            "right"
        } else {
            "left"
        }
    );
    Ok(())
}

fn read_and_apply(tfm: &str, points: &str) -> Result<()> {
    let path = std::path::Path::new(tfm);
    let lat = if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("bxf"))
    {
        volmorph_lattice::formats::bxf::read_bxf(path)?
    } else {
        volmorph_lattice::formats::itk_tfm::read_itk_tfm(path)?
    };
    let text = std::fs::read_to_string(points).with_context(|| points.to_owned())?;
    let mut out = String::new();
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let v: Vec<f64> = line
            .split_whitespace()
            .take(3)
            .map(str::parse)
            .collect::<Result<_, _>>()
            .with_context(|| format!("point line '{line}'"))?;
        if v.len() != 3 {
            bail!("point line '{line}' has fewer than 3 numbers");
        }
        let q = lat.apply(DVec3::new(v[0], v[1], v[2]));
        writeln!(out, "{:?} {:?} {:?}", q.x, q.y, q.z)?;
    }
    print!("{out}");
    Ok(())
}
