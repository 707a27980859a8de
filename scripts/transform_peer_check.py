#!/usr/bin/env python3
"""ITK transform files written by volmorph, applied by SimpleITK: the same points come out.

volmorph writes an affine map, a cubic B-spline lattice moved at random, their
composition (affine applied first, then the lattice; and the reverse) and interpolating
thin-plate splines of 16 landmarks (kernels `r` and `r² ln r`, ITK's
`ThinPlateSplineKernelTransform` and `ThinPlateR2LogRSplineKernelTransform`) as ITK `.tfm` files
(`volmorph map compose … -o C.tfm`, `volmorph lattice convert … -o L.tfm`). Each file is read
by SimpleITK (`ReadTransform`) and applied to points spread over the lattice box; volmorph
applies the same file (`volmorph map apply`) and its own JSON form of the map. The largest
distance between SimpleITK's and volmorph's mapped points must be at most 1e-9 of the box
diagonal (rounding of the 17-digit text) for every file, 1e-7 for the thin-plate splines
(ITK solves their landmark system again).

The thin-plate files need ITK's kernel transforms, which the readers of pip's SimpleITK
(2.5) and ITK (5.4) cannot create ("Could not create an instance of
ThinPlateSplineKernelTransform_double_3_3"). When SimpleITK cannot read such a file, the
check builds the file's transforms with the `itk` package instead: each kernel transform from
its Parameters (the source landmarks) and FixedParameters (the target landmarks), the others
by name, in an ITK `CompositeTransform` in the file's order, as ITK's reader would. Without
the `itk` package (pip install itk) those two checks are skipped with the reason; the others
run regardless.

Then the other transform files:

* Displacement fields: `volmorph map field M --reference V -o F` (`.nii.gz` and `.mha`, of the
  composite above, on an oblique reference grid SimpleITK wrote) read by SimpleITK as a
  `DisplacementFieldTransform`, applied to points inside the grid, near its border and outside
  it (where ITK's displacement is zero), against volmorph applying the same field file; and a
  field SimpleITK computed (`TransformToDisplacementField` of the B-spline transform) read by
  volmorph. Same tolerance (f64 values).
* ITK/ANTs MATLAB `.mat`: an affine with a centre written by SimpleITK (`WriteTransform`) read
  by volmorph, and the affine volmorph writes read by SimpleITK.

Usage:  python3 scripts/transform_peer_check.py [--volmorph target/release/volmorph]
The binary is --volmorph, else $VOLMORPH, else target/release/volmorph. Prints a PASS, FAIL
or SKIP line per check and "N passed, N failed, N skipped". Exits 0 with a SKIP message when
numpy or SimpleITK is not installed or the binary is missing; 1 when a check fails.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

try:
    import numpy as np
except ImportError:  # main() skips
    np = None

ROOT = Path(__file__).resolve().parent.parent
#: Largest allowed distance between the peers' mapped points, relative to the box diagonal.
REL_TOL = 1e-9
#: The same for thin-plate splines: ITK solves the landmark system again when it reads the file
#: (in the file's coordinates, volmorph in centred and scaled ones), so the two agree to the
#: rounding of that solve, amplified by its condition number (16 landmarks here).
TPS_REL_TOL = 1e-7
#: The same for grids read from NIfTI: the header holds the geometry in f32 (pixdim, quatern_*,
#: srow_*; NIfTI-1 standard), and its qform and sform round differently, so two readers that
#: prefer different ones agree only to f32 rounding (about 1.2e-7 relative, times the few
#: terms of an index-to-physical map).
NIFTI_REL_TOL = 1e-6


#: PASS (True), FAIL (False) or SKIP (None) of every check, in order.
RESULTS: list[bool | None] = []


def record(good: bool | None, line: str) -> bool:
    """Print a check's line and count it; `good` None is a skip (it does not fail the run)."""
    print({True: "PASS  ", False: "FAIL  ", None: "SKIP  "}[good] + line)
    RESULTS.append(good)
    return good is not False


def itk_transform_from_tfm(path: Path):
    """The transform of an ITK text `.tfm` file built with the `itk` package, for the types
    pip's readers cannot create (ITK's thin-plate kernel transforms): every `#Transform` of the
    file by its class name, FixedParameters then Parameters (a kernel transform's targets, then
    its sources), inside a CompositeTransform in the file's order (ITK applies its last
    transform first, as its reader would). Raises ImportError without the `itk` package."""
    import itk

    blocks: list[dict[str, str]] = []
    for line in path.read_text().splitlines():
        if line.startswith("#Transform"):
            blocks.append({})
        elif ":" in line and blocks:
            key, value = line.split(":", 1)
            blocks[-1][key.strip()] = value.strip()
    if blocks and blocks[0]["Transform"].startswith("CompositeTransform_"):
        blocks = blocks[1:]
    composite = itk.CompositeTransform[itk.D, 3].New()
    for b in blocks:
        name = b["Transform"]
        if not name.endswith("_double_3_3"):
            raise ValueError(f"{path}: {name} is not a 3-D double transform")
        tx = getattr(itk, name[: -len("_double_3_3")])[itk.D, 3].New()
        for setter, key in ((tx.SetFixedParameters, "FixedParameters"),
                            (tx.SetParameters, "Parameters")):
            values = [float(v) for v in b.get(key, "").split()]
            params = itk.OptimizerParameters[itk.D](len(values))
            for i, v in enumerate(values):
                params[i] = v
            setter(params)
        if hasattr(tx, "ComputeWMatrix"):
            # A kernel transform maps points only once its W matrix is solved for the
            # landmarks set (pip ITK 5.4.7 crashes in TransformPoint otherwise).
            tx.ComputeWMatrix()
        composite.AddTransform(tx)
    return composite


def run(vm: Path, *args) -> None:
    r = subprocess.run([str(vm), *map(str, args)], capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"volmorph {' '.join(map(str, args))}: {r.stderr.strip()}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--volmorph", default=os.environ.get("VOLMORPH")
                    or str(ROOT / "target/release/volmorph"))
    ap.add_argument("--points", type=int, default=500)
    a = ap.parse_args()
    if np is None:
        print("SKIP: numpy is not installed (pip install numpy SimpleITK)")
        return 0
    try:
        import SimpleITK as sitk
    except ImportError:
        print("SKIP: SimpleITK is not installed (pip install SimpleITK)")
        return 0
    vm = Path(a.volmorph)
    if not vm.is_file():
        print(f"SKIP: no volmorph binary at {vm} (cargo build --release -p volmorph-cli)")
        return 0
    rng = np.random.default_rng(7)
    ok = True
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        run(vm, "phantom", "sphere", "-o", t / "v.nii.gz", "--size", "24")
        run(vm, "lattice", "init", t / "v.nii.gz", "--counts", "7,6,5", "-o", t / "l0.json")
        lat = json.loads((t / "l0.json").read_text())
        pts = np.array(lat["control_points"], dtype=float)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        diag = float(np.linalg.norm(hi - lo))
        lat["control_points"] = (pts + rng.uniform(-0.04, 0.04, pts.shape) * diag).tolist()
        (t / "l.json").write_text(json.dumps(lat))
        angle = 0.3
        c, s = np.cos(angle), np.sin(angle)
        matrix = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ np.diag([1.1, 0.95, 1.02])
        matrix[0, 2] = 0.05  # a shear
        affine = {"version": 1, "kind": "affine", "matrix": matrix.tolist(),
                  "offset": (0.02 * diag * np.array([1.0, -0.5, 0.3])).tolist()}
        (t / "a.json").write_text(json.dumps(affine))
        run(vm, "lattice", "convert", t / "l.json", "-o", t / "l.tfm")
        run(vm, "map", "compose", t / "a.json", t / "a.json", "-o", t / "aa.tfm")
        run(vm, "map", "compose", t / "a.json", t / "l.json", "-o", t / "al.tfm")
        run(vm, "map", "compose", t / "a.json", t / "l.json", "-o", t / "al.json")
        run(vm, "map", "compose", t / "l.json", t / "a.json", "-o", t / "la.tfm")
        run(vm, "map", "compose", t / "l.json", t / "a.json", "-o", t / "la.json")
        # Interpolating thin-plate splines (both kernels) written as ITK kernel transforms,
        # inside a composite with the identity (`map compose` takes two maps or more).
        (t / "id.json").write_text(json.dumps({"version": 1, "kind": "affine",
                                               "matrix": np.eye(3).tolist(),
                                               "offset": [0.0, 0.0, 0.0]}))
        src = rng.uniform(lo, hi, (16, 3))
        dst = src + rng.uniform(-0.05, 0.05, src.shape) * diag
        for kernel in ("r", "r2logr"):
            tps = {"version": 1, "kind": "thin-plate", "smoothing": 0.0, "kernel": kernel,
                   "sources": src.tolist(), "targets": dst.tolist()}
            (t / f"tps_{kernel}.json").write_text(json.dumps(tps))
            run(vm, "map", "compose", t / f"tps_{kernel}.json", t / "id.json",
                "-o", t / f"tps_{kernel}.tfm")
        inner = lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo)
        p = rng.uniform(inner[0], inner[1], (a.points, 3))
        np.savetxt(t / "p.txt", p, fmt="%.17g")
        cases = [
            ("cubic B-spline lattice", "l.tfm", "l.json"),
            ("affine then affine", "aa.tfm", None),
            ("composite: affine then B-spline", "al.tfm", "al.json"),
            ("composite: B-spline then affine", "la.tfm", "la.json"),
            ("thin-plate spline, kernel r", "tps_r.tfm", "tps_r.json"),
            ("thin-plate spline, kernel r² ln r", "tps_r2logr.tfm", "tps_r2logr.json"),
        ]
        for name, tfm, own in cases:
            peer = "SimpleITK"
            try:
                tx = sitk.ReadTransform(str(t / tfm))
                kind = tx.GetName()
            except RuntimeError as e:
                if not tfm.startswith("tps"):
                    raise
                # pip's SimpleITK cannot create ITK's kernel transforms: build them with itk.
                lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
                reason = next((ln for ln in lines if "Could not create" in ln), lines[0])
                reason = reason.split("ITK ERROR: ")[-1][:160]
                try:
                    tx = itk_transform_from_tfm(t / tfm)
                except ImportError:
                    ok &= record(None, f"{name} ({tfm}): SimpleITK cannot read it ({reason}), "
                                       "and the itk package is not installed (pip install itk)")
                    continue
                peer = "ITK (itk package, kernel transform built from the file)"
                kind = " + ".join(tx.GetNthTransform(i).GetNameOfClass()
                                  for i in range(tx.GetNumberOfTransforms()))
            theirs = np.array([tuple(tx.TransformPoint([float(c) for c in q])) for q in p])
            run(vm, "map", "apply", t / tfm, t / "p.txt", "-o", t / "q.txt")
            ours = np.loadtxt(t / "q.txt", comments="#", delimiter=None, ndmin=2)[:, :3]
            err = float(np.max(np.linalg.norm(ours - theirs, axis=1)))
            moved = float(np.max(np.linalg.norm(theirs - p, axis=1)))
            line = f"{name} ({tfm}, {kind}): largest |volmorph − {peer}| = {err:.2e}"
            if own:
                run(vm, "map", "apply", t / own, t / "p.txt", "-o", t / "r.txt")
                mine = np.loadtxt(t / "r.txt", comments="#", ndmin=2)[:, :3]
                err_own = float(np.max(np.linalg.norm(mine - theirs, axis=1)))
                line += f", JSON form {err_own:.2e}"
                err = max(err, err_own)
            line += f" (points moved up to {moved:.3g}, box diagonal {diag:.3g})"
            tol = TPS_REL_TOL if tfm.startswith("tps") else REL_TOL
            ok &= record(err <= tol * diag and moved > 1e-3 * diag, line)
        ok &= check_fields_and_mat(sitk, vm, t, rng, diag, lo, hi)
    passed = sum(r is True for r in RESULTS)
    failed = sum(r is False for r in RESULTS)
    skipped = sum(r is None for r in RESULTS)
    print(f"transform peer check: {passed} passed, {failed} failed, {skipped} skipped")
    return 0 if ok else 1


def apply_file(vm: Path, t: Path, mapfile: Path, pts: np.ndarray) -> np.ndarray:
    np.savetxt(t / "fp.txt", pts, fmt="%.17g")
    run(vm, "map", "apply", mapfile, t / "fp.txt", "-o", t / "fq.txt")
    return np.loadtxt(t / "fq.txt", comments="#", ndmin=2)[:, :3]


def report(name: str, ours: np.ndarray, theirs: np.ndarray, pts: np.ndarray, tol: float) -> bool:
    err = float(np.max(np.linalg.norm(ours - theirs, axis=1)))
    moved = float(np.max(np.linalg.norm(theirs - pts, axis=1)))
    return record(err <= tol and moved > 0.0,
                  f"{name}: largest |volmorph − SimpleITK| = {err:.2e} (points moved up to "
                  f"{moved:.3g})")


def check_fields_and_mat(sitk, vm: Path, t: Path, rng, diag: float, lo, hi) -> bool:
    ok = True
    tol = REL_TOL * diag

    def tol_for(name: str) -> float:
        return (NIFTI_REL_TOL if name.endswith((".nii", ".nii.gz")) else REL_TOL) * diag

    # An oblique reference grid written by SimpleITK, covering the lattice box.
    ref = sitk.Image(20, 18, 16, sitk.sitkFloat32)
    ang = 0.2
    c, s = np.cos(ang), np.sin(ang)
    d = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    ref.SetDirection(tuple(d.flatten()))
    ref.SetSpacing(tuple(((hi - lo) / np.array([17.0, 15.0, 13.0])).tolist()))
    ref.SetOrigin(tuple(lo.tolist()))
    sitk.WriteImage(ref, str(t / "ref.nii.gz"))
    # The reference as volmorph reads it (NIfTI keeps geometry in f32).
    back = sitk.ReadImage(str(t / "ref.nii.gz"))
    size = np.array(back.GetSize(), dtype=float)
    for field in ["f.nii.gz", "f.mha"]:
        run(vm, "map", "field", t / "al.tfm", "--reference", t / "ref.nii.gz", "-o", t / field)
        img = sitk.ReadImage(str(t / field))
        if img.GetNumberOfComponentsPerPixel() != 3:
            ok &= record(False, f"{field}: SimpleITK reads {img.GetNumberOfComponentsPerPixel()} "
                                "components")
            continue
        dft = sitk.DisplacementFieldTransform(sitk.Cast(img, sitk.sitkVectorFloat64))
        # Continuous indices inside, within half a voxel outside, and beyond.
        ci = rng.uniform(-2.0, size + 1.0, (2000, 3))
        pts = np.array([img.TransformContinuousIndexToPhysicalPoint(tuple(q)) for q in ci])
        theirs = np.array([dft.TransformPoint(tuple(q)) for q in pts])
        ours = apply_file(vm, t, t / field, pts)
        ok &= report(f"displacement field {field} (volmorph map field) read as a map", ours,
                     theirs, pts, tol_for(field))
        # The field agrees with the composite at the grid nodes.
        nodes = np.array([img.TransformIndexToPhysicalPoint((int(i), int(j), int(k)))
                          for i, j, k in rng.integers(0, size, (300, 3))])
        comp = sitk.ReadTransform(str(t / "al.tfm"))
        exact = np.array([comp.TransformPoint(tuple(q)) for q in nodes])
        viafield = np.array([dft.TransformPoint(tuple(q)) for q in nodes])
        ok &= report(f"{field} at its nodes (SimpleITK) vs the composite .tfm", viafield, exact,
                     nodes, tol_for(field))
    # A field SimpleITK computed, read by volmorph.
    bs = sitk.ReadTransform(str(t / "l.tfm"))
    tdf = sitk.TransformToDisplacementFieldFilter()
    tdf.SetReferenceImage(ref)
    tdf.SetOutputPixelType(sitk.sitkVectorFloat64)
    sf = tdf.Execute(bs)
    sitk.WriteImage(sf, str(t / "sitk_field.nii.gz"))
    sitk.WriteImage(sf, str(t / "sitk_field.mha"))
    dft = sitk.DisplacementFieldTransform(sitk.Cast(sitk.ReadImage(str(t / "sitk_field.mha")),
                                                    sitk.sitkVectorFloat64))
    ci = rng.uniform(-1.0, size, (1000, 3))
    pts = np.array([ref.TransformContinuousIndexToPhysicalPoint(tuple(q)) for q in ci])
    theirs = np.array([dft.TransformPoint(tuple(q)) for q in pts])
    for name in ["sitk_field.nii.gz", "sitk_field.mha"]:
        ours = apply_file(vm, t, t / name, pts)
        ok &= report(f"SimpleITK's displacement field {name} read by volmorph", ours, theirs,
                     pts, tol_for(name))
    # MATLAB .mat: SimpleITK's affine with a centre read by volmorph, and back.
    aff = sitk.AffineTransform(3)
    aff.SetMatrix((1.05, 0.1, 0.0, -0.08, 0.97, 0.02, 0.01, 0.0, 1.1))
    aff.SetTranslation((1.5, -2.0, 0.7))
    aff.SetCenter(tuple(((lo + hi) / 2).tolist()))
    sitk.WriteTransform(aff, str(t / "sitk_affine.mat"))
    pts = rng.uniform(lo, hi, (500, 3))
    theirs = np.array([aff.TransformPoint(tuple(q)) for q in pts])
    ours = apply_file(vm, t, t / "sitk_affine.mat", pts)
    ok &= report("SimpleITK's affine .mat (with centre) read by volmorph", ours, theirs, pts, tol)
    (t / "id.json").write_text(json.dumps({"version": 1, "kind": "identity"}))
    run(vm, "map", "compose", t / "a.json", t / "id.json", "-o", t / "a.mat")
    mat = sitk.ReadTransform(str(t / "a.mat"))
    theirs = np.array([mat.TransformPoint(tuple(q)) for q in pts])
    ours = apply_file(vm, t, t / "a.json", pts)
    ok &= report(f"volmorph's affine .mat read by SimpleITK ({mat.GetName()})", ours, theirs,
                 pts, tol)
    return ok


if __name__ == "__main__":
    sys.exit(main())
