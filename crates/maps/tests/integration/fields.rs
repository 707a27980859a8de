//! Displacement fields and the transform files of ITK, ANTs and elastix, through the map
//! files every command reads: written fields read back as the same displacements, a field
//! sampled from a B-spline lattice (and from a composite `.tfm`) agrees with the map to
//! interpolation error, and `.mat` and elastix files read as the maps they name.

use glam::{DMat3, DVec3};
use volmorph_deform::{Affine, SpaceMap};
use volmorph_lattice::BSplineLattice;
use volmorph_maps::{AnyMap, DisplacementField, read_map, write_field, write_map};
use volmorph_volume::Geometry;
use volmorph_volume_io::vector::VectorPrecision;

fn lattice() -> BSplineLattice {
    let mut l =
        BSplineLattice::uniform_cubic_around(DVec3::splat(-10.0), DVec3::splat(10.0), [7, 6, 5])
            .unwrap();
    let mut r = volmorph_testkit::Rng::new(11);
    let [cx, cy, cz] = l.counts();
    for k in 0..cz {
        for j in 0..cy {
            for i in 0..cx {
                let d = DVec3::new(r.range(-0.8, 0.8), r.range(-0.8, 0.8), r.range(-0.8, 0.8));
                l.move_control_point([i, j, k], d).unwrap();
            }
        }
    }
    l
}

/// An oblique, anisotropic grid over most of the lattice box.
fn grid(n: [usize; 3]) -> Geometry {
    let (s, c) = 0.25f64.sin_cos();
    let mut g = Geometry::new(n);
    g.direction = DMat3::from_cols(DVec3::new(c, s, 0.0), DVec3::new(-s, c, 0.0), DVec3::Z);
    g.spacing = DVec3::new(14.0, 13.0, 12.0)
        / DVec3::new(n[0] as f64 - 1.0, n[1] as f64 - 1.0, n[2] as f64 - 1.0);
    g.origin = DVec3::new(-6.0, -8.0, -6.0);
    g
}

fn affine() -> Affine {
    Affine {
        matrix: DMat3::from_cols_array(&[1.05, 0.1, 0.0, -0.08, 0.97, 0.02, 0.01, 0.0, 1.1]),
        offset: DVec3::new(0.4, -0.3, 0.2),
    }
}

#[test]
fn written_fields_read_back_with_the_same_displacement_at_every_node() {
    let dir = tempfile::tempdir().unwrap();
    let map = AnyMap::Lattice(lattice());
    let g = grid([9, 8, 7]);
    for name in ["f.nii.gz", "f.nii", "f.mha", "f.mhd"] {
        let path = dir.path().join(name);
        let written = write_field(&path, &map, g, VectorPrecision::F64).unwrap();
        let AnyMap::DisplacementField(back) = read_map(&path).unwrap() else {
            panic!("{name} is not read as a displacement field")
        };
        // NIfTI keeps the geometry in f32: compare at the nodes of the grid read back.
        let bg = *back.grid();
        assert_eq!(bg.dims, g.dims);
        assert_eq!(back.displacements(), written.displacements(), "{name}");
        for (n, d) in back.displacements().iter().enumerate().step_by(17) {
            let [nx, ny, _] = bg.dims;
            let idx = DVec3::new(
                (n % nx) as f64,
                (n / nx % ny) as f64,
                (n / (nx * ny)) as f64,
            );
            let x = bg.index_to_physical(idx);
            assert!(
                (back.apply(x) - (x + *d)).length() < 1e-12,
                "{name} node {n}"
            );
            // The map itself at the node (the f32 geometry moves the node by ~1e-6).
            let tol = if name.contains(".nii") { 1e-4 } else { 1e-12 };
            assert!(
                (back.apply(x) - map.apply(x)).length() < tol,
                "{name} node {n}"
            );
        }
        // Trilinear in between: the mean of two neighbours at their midpoint.
        let a = bg.index_to_physical(DVec3::new(3.0, 4.0, 2.0));
        let b = bg.index_to_physical(DVec3::new(4.0, 4.0, 2.0));
        let mid = back.apply((a + b) * 0.5) - (a + b) * 0.5;
        let want = ((back.apply(a) - a) + (back.apply(b) - b)) * 0.5;
        assert!((mid - want).length() < 1e-12, "{name}");
        // And the field written as it is (write_map) reads back identically.
        let again = dir.path().join(format!("again-{name}"));
        write_map(&again, &AnyMap::DisplacementField(back.clone())).unwrap();
        let AnyMap::DisplacementField(twice) = read_map(&again).unwrap() else {
            panic!()
        };
        assert_eq!(twice.displacements(), back.displacements());
    }
    // A map without a grid cannot be written as a field without one.
    let e = write_map(&dir.path().join("x.nii.gz"), &map)
        .unwrap_err()
        .to_string();
    assert!(e.contains("reference grid"), "{e}");
}

/// Largest distance between `a` and `b` over points spread through the grid's interior.
fn worst(a: &dyn SpaceMap, b: &dyn SpaceMap, g: &Geometry) -> f64 {
    let mut r = volmorph_testkit::Rng::new(5);
    let hi = DVec3::new(
        g.dims[0] as f64 - 1.0,
        g.dims[1] as f64 - 1.0,
        g.dims[2] as f64 - 1.0,
    );
    (0..2000)
        .map(|_| {
            let c = r.point_in(DVec3::ZERO, hi);
            let x = g.index_to_physical(c);
            (a.apply(x) - b.apply(x)).length()
        })
        .fold(0.0, f64::max)
}

#[test]
fn field_of_a_bspline_lattice_agrees_with_it_to_interpolation_error() {
    let l = lattice();
    // Trilinear interpolation error ≤ h²/8 · max|∂²d|: halving the spacing quarters it.
    let coarse = grid([15, 14, 13]);
    let fine = grid([29, 27, 25]);
    let fc = DisplacementField::from_map(&l, coarse).unwrap();
    let ff = DisplacementField::from_map(&l, fine).unwrap();
    let (ec, ef) = (worst(&fc, &l, &coarse), worst(&ff, &l, &fine));
    assert!(
        ec > 1e-4,
        "the lattice should bend between coarse nodes ({ec})"
    );
    assert!(ef < ec / 2.5 && ef > ec / 6.0, "coarse {ec}, fine {ef}");
    // A composite (affine, then the lattice) through a .tfm file: same behaviour.
    let dir = tempfile::tempdir().unwrap();
    let comp = AnyMap::Affine(affine()).then(AnyMap::Lattice(l.clone()));
    let tfm = dir.path().join("c.tfm");
    write_map(&tfm, &comp).unwrap();
    let read = read_map(&tfm).unwrap();
    let fpath = dir.path().join("c.nii.gz");
    write_field(&fpath, &read, fine, VectorPrecision::F64).unwrap();
    let field = read_map(&fpath).unwrap();
    let e = worst(&field, &comp, &fine);
    assert!(
        e < 2.0 * ef + 1e-3,
        "composite through its field: {e} (lattice alone {ef})"
    );
    // An affine map is trilinear: its field is exact between the nodes.
    let a = AnyMap::Affine(affine());
    let fa = DisplacementField::from_map(&a, coarse).unwrap();
    assert!(worst(&fa, &a, &coarse) < 1e-12);
}

#[test]
fn mat_and_elastix_files_are_map_files() {
    let dir = tempfile::tempdir().unwrap();
    let a = AnyMap::Affine(affine());
    let mat = dir.path().join("a.mat");
    write_map(&mat, &a).unwrap();
    let AnyMap::Affine(b) = read_map(&mat).unwrap() else {
        panic!()
    };
    assert_eq!(b, affine());
    // elastix: the B-spline of the lattice (ITK's control grid) after an affine, as a chain.
    let l = lattice();
    let tfm = volmorph_lattice::formats::itk_tfm::itk_tfm_to_string(&l).unwrap();
    let field = |key: &str| -> Vec<String> {
        let line = tfm.lines().find(|x| x.starts_with(key)).unwrap();
        line[key.len()..]
            .split_whitespace()
            .map(str::to_owned)
            .collect()
    };
    let params = field("Parameters:");
    let fixed = field("FixedParameters:");
    // ITK's fixed parameters: size, origin, spacing, direction row-major; elastix lists the
    // direction column by column.
    let d: Vec<f64> = fixed[9..].iter().map(|v| v.parse().unwrap()).collect();
    let dcols: Vec<String> = (0..9).map(|i| d[(i % 3) * 3 + i / 3].to_string()).collect();
    let m = affine().matrix.transpose().to_cols_array();
    let t = affine().offset;
    let aff = format!(
        "(Transform \"AffineTransform\")\n(NumberOfParameters 12)\n(TransformParameters {} {} {} {})\n\
         (CenterOfRotationPoint 0 0 0)\n(InitialTransformParametersFileName \"NoInitialTransform\")\n",
        m.iter().map(f64::to_string).collect::<Vec<_>>().join(" "),
        t.x,
        t.y,
        t.z
    );
    std::fs::write(dir.path().join("TransformParameters.0.txt"), aff).unwrap();
    let bs = format!(
        "// elastix B-spline\n(Transform \"BSplineTransform\")\n(NumberOfParameters {})\n\
         (TransformParameters {})\n(GridSize {})\n(GridIndex 0 0 0)\n(GridSpacing {})\n\
         (GridOrigin {})\n(GridDirection {})\n(BSplineTransformSplineOrder 3)\n\
         (InitialTransformParametersFileName \"TransformParameters.0.txt\")\n\
         (HowToCombineTransforms \"Compose\")\n",
        params.len(),
        params.join(" "),
        fixed[..3].join(" "),
        fixed[6..9].join(" "),
        fixed[3..6].join(" "),
        dcols.join(" ")
    );
    let p1 = dir.path().join("TransformParameters.1.txt");
    std::fs::write(&p1, bs).unwrap();
    let chain = read_map(&p1).unwrap();
    let want = AnyMap::Affine(affine()).then(AnyMap::Lattice(l));
    let g = grid([9, 8, 7]);
    assert!(
        worst(&chain, &want, &g) < 1e-12,
        "{}",
        worst(&chain, &want, &g)
    );
}

/// A field written to an extension that holds no vector image is refused, naming the file
/// once, the extension found and the ones written (the message said "unsupported:
/// unsupported:"; since issue 15 it is the one extension error of every writer).
#[test]
fn field_to_an_unsupported_extension_says_unsupported_once() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("field.nrrd");
    let e = write_field(
        &path,
        &AnyMap::Affine(affine()),
        grid([4, 4, 4]),
        VectorPrecision::F64,
    )
    .unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "{}: the extension .nrrd is not written here; use .nii, .nii.gz, .mha or .mhd",
            path.display()
        )
    );
    assert!(!path.exists());
}
