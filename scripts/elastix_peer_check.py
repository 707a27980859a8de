#!/usr/bin/env python3
"""elastix transform parameter chains read by volmorph, against transformix.

itk-elastix registers two small synthetic volumes (an oblique fixed grid, a moving volume
deformed by an affine map and a smooth sine warp) with an affine parameter map, then a cubic
B-spline one, run from a folder with the output folder `out` as elastix is usually run: the
B-spline's `out/TransformParameters.1.txt` names the affine's file as its initial transform
(elastix 5.2 and later write the entry `InitialTransformParameterFileName`, earlier versions
`InitialTransformParametersFileName`). Then, against transformix reading the same file:

* the deformation field: `volmorph map field out/TransformParameters.1.txt --reference
  fixed.nii.gz -o field.nii.gz` against transformix's deformation field on the fixed grid;
* points (inside the fixed image, beyond it, and beyond the B-spline's control grid, where
  only the affine moves them): `volmorph map apply` against transformix's outputpoints.txt;
* the same file with the entry spelled as elastix up to 5.1 writes it: the same points;
* the B-spline file without its initial transform (how volmorph read elastix 5.2's files
  before it knew the new name) must be far from transformix: the check can see that fault.

Tolerances follow transformix's output: its deformation field holds f32 vectors (rounded to
2^-24 of the largest component), and volmorph's grid is the fixed image read back from NIfTI,
whose header keeps the geometry in f32 (voxel positions rounded to 2^-24 of their distance
from 0, which moves a displacement by at most twice that here); outputpoints.txt prints 6
decimals (std::fixed), so 5e-7 per coordinate.

Usage:  python3 scripts/elastix_peer_check.py [--volmorph target/release/volmorph]
                                              [--write-fixture DIR]
The binary is --volmorph, else $VOLMORPH, else target/release/volmorph. --write-fixture copies
the two parameter files and transformix's outputpoints.txt to DIR (the test corpus of
crates/maps/tests/corpus/elastix5 was made so). Prints a PASS or FAIL line per check and
"N passed, N failed"; exits 0 with a SKIP line when numpy or itk-elastix is not installed or
the binary is missing, 1 when a check fails.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: Points mapped by transformix and volmorph (physical LPS mm): inside the fixed image, near
#: and beyond its border, and far outside the B-spline's control grid (the affine alone).
POINTS = [
    (-12.0, -6.0, 20.0),
    (0.5, 3.25, 27.0),
    (10.0, 12.0, 40.0),
    (-3.0, -10.0, 33.5),
    (6.0, 0.0, 14.0),
    (-60.0, 30.0, 90.0),
]
#: outputpoints.txt prints each coordinate with 6 decimals (`std::fixed`, elastix's
#: TransformBase::TransformPointsSomePoints): half a unit of the last decimal, and a little
#: for the decimal reading of volmorph's 17-digit output.
POINT_TOL = 5e-7 + 1e-9
#: Unit roundoff of f32 (half an ulp relative to the value): transformix's deformation field
#: holds f32 vectors, and a NIfTI header keeps the grid's geometry in f32 (pixdim, quatern_*,
#: srow_*).
F32_UNIT_ROUNDOFF = 2.0**-24
#: Bound on |∇T − I| of the chain (its affine part is within 10 % of a rotation, its B-spline
#: part moves points by a few mm over control points 25 mm apart): how much a shift of a grid
#: point changes the displacement there.
DISPLACEMENT_GRADIENT = 2.0
#: The B-spline alone must miss transformix by more than this (mm) for the negative control.
MISREAD_MIN = 1.0


def anatomy(np, q):
    """A few Gaussian blobs, the same content for both images."""
    v = np.zeros(len(q))
    for c, s, a in [((-5, 0, 25), 6, 1.0), ((8, 6, 30), 4, 0.8), ((0, -8, 20), 5, 0.6),
                    ((6, -4, 34), 3, 0.9), ((-8, 8, 30), 4, 0.7)]:
        v += a * np.exp(-np.sum((q - np.array(c, dtype=float)) ** 2, 1) / (2.0 * s * s))
    return v


def make_image(np, itk, shape, spacing, origin, direction, warp):
    idx = np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), -1)
    pts = (idx.reshape(-1, 3) * spacing) @ direction.T + origin
    v = anatomy(np, warp(pts)).reshape(shape)
    im = itk.image_from_array(np.ascontiguousarray(v.transpose(2, 1, 0)).astype(np.float32))
    im.SetSpacing(spacing.tolist())
    im.SetOrigin(origin.tolist())
    im.SetDirection(itk.matrix_from_array(np.ascontiguousarray(direction)))
    return im


def register(np, itk, work: Path):
    """Write fixed.nii.gz and moving.nii.gz in `work`, register them affine then B-spline
    with the output folder `out` (run from `work`); return the moving image."""
    a = 0.15
    d = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    fixed = make_image(np, itk, (20, 18, 16), np.array([2.0, 2.0, 2.5]),
                       np.array([-20.0, -16.0, 10.0]), d, lambda p: p)
    m = np.array([[1.04, 0.05, 0.0], [-0.03, 0.97, 0.02], [0.0, 0.01, 1.02]])

    def warp(p):
        return p @ m.T + np.array([1.5, -1.0, 0.8]) + 1.5 * np.sin(p[:, [1, 2, 0]] / 9.0)

    moving = make_image(np, itk, (22, 20, 18), np.array([2.0, 2.0, 2.0]),
                        np.array([-22.0, -18.0, 8.0]), np.eye(3), warp)
    itk.imwrite(fixed, str(work / "fixed.nii.gz"))
    itk.imwrite(moving, str(work / "moving.nii.gz"))
    po = itk.ParameterObject.New()
    am = po.GetDefaultParameterMap("affine", 2)
    am["MaximumNumberOfIterations"] = ["150"]
    po.AddParameterMap(am)
    # A coarse control grid (5 points per axis here) keeps the parameter file small.
    bm = po.GetDefaultParameterMap("bspline", 1, 24.0)
    bm["MaximumNumberOfIterations"] = ["150"]
    po.AddParameterMap(bm)
    (work / "out").mkdir()
    itk.elastix_registration_method(fixed, moving, parameter_object=po, output_directory="out",
                                    log_to_console=False)
    return moving


def transformix(itk, moving, parameter_file: str, points: str | None = None, out: str = ""):
    """transformix reading `parameter_file` (and the chain it names), as its command line does:
    the deformation field on the fixed grid, or (one or the other per run) `points` mapped into
    outputpoints.txt in the folder `out`."""
    t = itk.TransformixFilter[type(moving)].New()
    t.SetMovingImage(moving)
    t.SetTransformParameterFileName(parameter_file)
    if points:
        t.SetFixedPointSetFileName(points)
        t.SetOutputDirectory(out)
    else:
        t.SetComputeDeformationField(True)
    t.SetLogToConsole(False)
    t.Update()
    return None if points else t.GetOutputDeformationField()


def package_version(name: str) -> str:
    try:
        return version(name)
    except PackageNotFoundError:
        return "(version unknown)"


def read_outputpoints(np, path: Path):
    rows = []
    for line in path.read_text().splitlines():
        part = line.split("OutputPoint = [")[1].split("]")[0]
        rows.append([float(v) for v in part.split()])
    return np.array(rows)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--volmorph", default=None)
    ap.add_argument("--write-fixture", type=Path, default=None)
    a = ap.parse_args()
    try:
        import numpy as np
    except ImportError:
        print("SKIP: numpy is not installed (pip install numpy itk-elastix)")
        return 0
    try:
        import itk

        itk.ElastixRegistrationMethod  # noqa: B018 (itk without elastix has no such name)
    except (ImportError, AttributeError):
        print("SKIP: itk-elastix is not installed (pip install itk-elastix)")
        return 0
    vm = Path(a.volmorph or os.environ.get("VOLMORPH") or ROOT / "target/release/volmorph")
    if not vm.is_file():
        print(f"SKIP: no volmorph binary at {vm} (cargo build --release -p volmorph-cli)")
        return 0
    vm = vm.resolve()
    results: list[bool] = []

    def check(good: bool, line: str) -> None:
        print(("PASS  " if good else "FAIL  ") + line)
        results.append(good)

    def volmorph(*args) -> str:
        r = subprocess.run([str(vm), *map(str, args)], capture_output=True, text=True, cwd=work)
        if r.returncode != 0:
            raise RuntimeError(f"volmorph {' '.join(map(str, args))}: {r.stderr.strip()}")
        return r.stdout

    def apply(mapfile: str):
        volmorph("map", "apply", mapfile, "p.txt", "-o", "q.txt")
        return np.loadtxt(work / "q.txt", comments="#", ndmin=2)[:, :3]

    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        cwd = os.getcwd()
        os.chdir(work)  # elastix names the initial file relative to where it ran
        try:
            moving = register(np, itk, work)
            with open("points.txt", "w") as f:
                f.write(f"point\n{len(POINTS)}\n")
                f.writelines(f"{x!r} {y!r} {z!r}\n" for x, y, z in POINTS)
            (work / "tx").mkdir()
            field = transformix(itk, moving, "out/TransformParameters.1.txt")
            transformix(itk, moving, "out/TransformParameters.1.txt", "points.txt", "tx")
        finally:
            os.chdir(cwd)
        p1 = (work / "out/TransformParameters.1.txt").read_text()
        key = next((k for k in ("InitialTransformParameterFileName",
                                "InitialTransformParametersFileName")
                    if f"({k} " in p1), None)
        entry = next((ln for ln in p1.splitlines() if key and ln.startswith(f"({key} ")), "none")
        print(f"itk-elastix {package_version('itk-elastix')}: the chain entry is {entry}")
        if a.write_fixture:
            a.write_fixture.mkdir(parents=True, exist_ok=True)
            for name in ("out/TransformParameters.0.txt", "out/TransformParameters.1.txt",
                         "tx/outputpoints.txt"):
                shutil.copy(work / name, a.write_fixture / Path(name).name)
            print(f"wrote the fixture to {a.write_fixture}")

        # The deformation field on the fixed grid.
        volmorph("map", "field", "out/TransformParameters.1.txt", "--reference", "fixed.nii.gz",
                 "-o", "field.nii.gz")
        reader = itk.ImageFileReader[itk.VectorImage[itk.D, 3]].New(
            FileName=str(work / "field.nii.gz"))
        reader.Update()
        ours = itk.array_from_image(reader.GetOutput()).reshape(-1, 3)
        theirs = itk.array_from_image(field).reshape(-1, 3).astype(np.float64)
        fixed = itk.imread(str(work / "fixed.nii.gz"))
        size = np.array(fixed.GetLargestPossibleRegion().GetSize(), dtype=float)
        d = itk.array_from_matrix(fixed.GetDirection())
        corners = np.array([np.array(fixed.GetOrigin())
                            + d @ (np.array(fixed.GetSpacing()) * (size - 1) * np.array(k))
                            for k in np.ndindex(2, 2, 2)])
        farthest = float(np.max(np.linalg.norm(corners, axis=1)))
        biggest = float(np.max(np.linalg.norm(theirs, axis=1)))
        tol = F32_UNIT_ROUNDOFF * (float(np.max(np.abs(theirs)))
                                   + DISPLACEMENT_GRADIENT * farthest)
        err = float(np.max(np.abs(ours - theirs))) if ours.shape == theirs.shape else np.inf
        check(err <= tol and biggest > 1.0,
              f"deformation field of the affine → B-spline chain ({ours.shape[0]} voxels): "
              f"largest |volmorph − transformix| = {err:.2e} mm (tolerance {tol:.1e}; "
              f"displacements up to {biggest:.3g} mm)")

        # Points, against outputpoints.txt.
        want = read_outputpoints(np, work / "tx/outputpoints.txt")
        np.savetxt(work / "p.txt", np.array(POINTS), fmt="%.17g")
        got = apply("out/TransformParameters.1.txt")
        err = float(np.max(np.abs(got - want)))
        moved = float(np.max(np.linalg.norm(want - np.array(POINTS), axis=1)))
        check(err <= POINT_TOL and moved > 1.0,
              f"{len(POINTS)} points through the chain: largest |volmorph − transformix| = "
              f"{err:.2e} mm per coordinate (outputpoints.txt has 6 decimals; points moved up "
              f"to {moved:.3g} mm)")

        # The entry's old spelling (elastix up to 5.1).
        new, old = "(InitialTransformParameterFileName ", "(InitialTransformParametersFileName "
        renamed = p1.replace(new, old) if key == new.strip("( ") else p1.replace(old, new)
        (work / "out/renamed.txt").write_text(renamed)
        got = apply("out/renamed.txt")
        err = float(np.max(np.abs(got - want)))
        other = old if key == new.strip("( ") else new
        check(err <= POINT_TOL, f"the chain entry spelled {other.strip('( ')}: largest "
                                f"|volmorph − transformix| = {err:.2e} mm")

        # Negative control: the B-spline alone.
        alone = "\n".join(ln for ln in p1.splitlines() if not ln.startswith(f"({key} "))
        (work / "out/alone.txt").write_text(alone + "\n")
        got = apply("out/alone.txt")
        err = float(np.max(np.linalg.norm(got - want, axis=1)))
        check(err > MISREAD_MIN, f"the B-spline without its initial transform is off by up to "
                                 f"{err:.3g} mm (more than {MISREAD_MIN} mm: the check sees a "
                                 f"chain read as its last transform)")

    passed = sum(results)
    print(f"elastix peer check: {passed} passed, {len(results) - passed} failed")
    return 0 if all(results) else 1


if __name__ == "__main__":
    sys.exit(main())
