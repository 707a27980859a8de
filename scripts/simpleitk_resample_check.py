#!/usr/bin/env python3
"""Peer check of volmorph's pull-back warp against SimpleITK's Resample with the same lattice.

A smooth test volume with non-unit spacing, a non-zero origin and an oblique direction is
written by SimpleITK. `volmorph lattice init` puts a uniform cubic lattice around it (in the
volume's own direction frame); the lattice's JSON is edited here (every control point off the
outer layer moved at random, fixed seed) and `volmorph lattice convert` writes it as an ITK
.tfm. Then:

* transform — the .tfm as read by SimpleITK is the lattice volmorph applies: volumes holding
  the physical x, y and z coordinate of each voxel centre (f64) are warped by volmorph
  (`--method pullback-linear`, which reproduces affine functions exactly), so each output
  voxel holds volmorph's lattice image of its centre; SimpleITK's displacement field of the
  transform read from the .tfm (`TransformToDisplacementField`) must give the same points.
  The output's border layer is left out: it lies on the faces of the lattice box, where ITK
  decides by rounding whether a point is inside its transform domain and leaves it unmoved
  if not (how many such voxels differ is printed).
  (scripts/itk_bspline_check.py compares random lattices point by point; this covers the
  CLI path, the volume's oblique frame and every voxel of a grid.)
* resample linear / cubic — `volmorph warp --method pullback-linear` and `pullback-cubic`
  against `sitk.Resample` with `sitkLinear` and `sitkBSpline` (both interpolating cubic
  B-splines on mirror-extended coefficients), default value 0. Compared on voxels at least
  MARGIN voxels from the output's border whose mapped point lies at least MARGIN voxels
  inside the input (boundary conventions differ within the last voxels); they must agree to
  TOL of the volume's value range.

Usage: scripts/simpleitk_resample_check.py [--volmorph PATH] [--seed S] [--tol T]
Prints PASS/FAIL/SKIP lines; exits 0 with SKIP when SimpleITK or numpy is not importable and
1 if any check failed.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

try:
    import numpy as np
    import SimpleITK as sitk
except ImportError:
    print("SKIP: SimpleITK and numpy are needed (pip install SimpleITK numpy)")
    sys.exit(0)

ROOT = Path(__file__).resolve().parent.parent

#: Voxels excluded at the output border and required between a mapped point and the input's.
MARGIN = 4
#: Control points per axis of the lattice.
COUNTS = (7, 6, 7)
#: Largest control-point displacement per component, in lattice regions.
AMPLITUDE = 0.3

FAILED = False


def record(name: str, ok: bool | None, detail: str) -> None:
    global FAILED
    ok = None if ok is None else bool(ok)
    status = "SKIP" if ok is None else ("PASS" if ok else "FAIL")
    FAILED |= ok is not None and not ok
    print(f"{status:4}  {name}  ({detail})", flush=True)


def volmorph_binary(arg: str | None) -> Path:
    if arg:
        return Path(arg)
    subprocess.run(
        ["cargo", "build", "--release", "-q", "-p", "volmorph-cli"], cwd=ROOT, check=True
    )
    return ROOT / "target" / "release" / "volmorph"


def run(exe: Path, *args) -> str:
    p = subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"volmorph {' '.join(map(str, args))} failed: {p.stderr.strip()}")
    return p.stdout


def test_geometry() -> dict:
    """Non-unit anisotropic spacing, non-zero origin, oblique (rotated) direction."""
    a, b = 0.35, -0.2
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    return {
        "size": (46, 40, 36),
        "spacing": (0.9, 1.3, 1.1),
        "origin": (-21.0, 12.5, 7.25),
        "direction": tuple((rz @ ry).ravel()),
    }


def image(values: "np.ndarray", g: dict) -> "sitk.Image":
    """An image from an (nz, ny, nx) array on geometry `g`."""
    img = sitk.GetImageFromArray(values)
    img.SetSpacing(g["spacing"])
    img.SetOrigin(g["origin"])
    img.SetDirection(g["direction"])
    return img


def voxel_centres(g: dict) -> "np.ndarray":
    """Physical centres, shape (nz, ny, nx, 3): origin + direction · (spacing ⊙ index)."""
    nx, ny, nz = g["size"]
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    idx = np.stack([i, j, k], axis=-1).astype(np.float64) * np.array(g["spacing"])
    d = np.array(g["direction"]).reshape(3, 3)
    return np.array(g["origin"]) + idx @ d.T


def smooth_volume(g: dict) -> "np.ndarray":
    """A smooth field with structure at several scales and no symmetry (f64)."""
    p = voxel_centres(g)
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    return (
        100.0 * np.sin(0.11 * x + 0.3) * np.cos(0.07 * y - 0.2)
        + 40.0 * np.cos(0.09 * z + 0.05 * x)
        + 0.5 * (y - 30.0)
    )


def moved_lattice(exe: Path, vol: Path, tmp: Path, seed: int) -> tuple[Path, Path]:
    """`volmorph lattice init`, control points moved in the JSON, converted to .tfm."""
    init = tmp / "identity.json"
    run(exe, "lattice", "init", vol, "--counts", ",".join(map(str, COUNTS)), "-o", init)
    lat = json.loads(init.read_text())
    cx, cy, cz = lat["counts"]
    axes = np.array(lat["frame"]["axes"])  # axes[a] is the direction of parameter axis a
    region = np.array(lat["frame"]["spacing"])  # physical length of one knot span per axis
    rng = np.random.default_rng(seed)
    pts = np.array(lat["control_points"], dtype=np.float64)
    for k in range(1, cz - 1):
        for j in range(1, cy - 1):
            for i in range(1, cx - 1):
                d = rng.uniform(-AMPLITUDE, AMPLITUDE, 3) * region
                pts[i + cx * (j + cy * k)] += d @ axes
    lat["control_points"] = pts.tolist()
    moved = tmp / "moved.json"
    moved.write_text(json.dumps(lat))
    tfm = tmp / "moved.tfm"
    run(exe, "lattice", "convert", moved, "-o", tfm)
    return moved, tfm


def mapped_points(tx: "sitk.Transform", g: dict) -> "np.ndarray":
    """SimpleITK's image of every voxel centre, shape (nz, ny, nx, 3)."""
    field = sitk.TransformToDisplacementField(
        tx,
        sitk.sitkVectorFloat64,
        g["size"],
        g["origin"],
        g["spacing"],
        g["direction"],
    )
    return voxel_centres(g) + sitk.GetArrayFromImage(field)


def continuous_index(p: "np.ndarray", g: dict) -> "np.ndarray":
    d = np.array(g["direction"]).reshape(3, 3)
    return ((p - np.array(g["origin"])) @ d) / np.array(g["spacing"])


def inner_mask(g: dict, mapped: "np.ndarray", border: int, inset: float) -> "np.ndarray":
    """Voxels at least `border` voxels from the output's border whose mapped point lies at
    least `inset` voxels inside the input's box of voxel centres."""
    nx, ny, nz = g["size"]
    mask = np.zeros((nz, ny, nx), dtype=bool)
    mask[border : nz - border, border : ny - border, border : nx - border] = True
    c = continuous_index(mapped, g)
    n = np.array([nx, ny, nz], dtype=np.float64)
    inside = np.all((c >= inset) & (c <= n - 1 - inset), axis=-1)
    return mask & inside


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--volmorph", help="volmorph executable (default: build the release one)")
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--tol", type=float, default=1e-3, help="relative to the value range")
    args = ap.parse_args()
    exe = volmorph_binary(args.volmorph)
    print(f"SimpleITK {sitk.Version.VersionString()} (ITK {sitk.Version.ITKVersionString()})")

    g = test_geometry()
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        values = smooth_volume(g)
        src = tmp / "smooth.mha"
        sitk.WriteImage(image(values, g), str(src))
        moved, tfm = moved_lattice(exe, src, tmp, args.seed)
        tx = sitk.ReadTransform(str(tfm))
        mapped = mapped_points(tx, g)
        moved_by = np.linalg.norm(mapped - voxel_centres(g), axis=-1)

        # The transform: volmorph's pull-back of the coordinate volumes vs SimpleITK's field.
        centres = voxel_centres(g)
        vm_mapped = np.empty_like(mapped)
        for a, name in enumerate("xyz"):
            coord = tmp / f"coord_{name}.mha"
            sitk.WriteImage(image(centres[..., a].copy(), g), str(coord))
            out = tmp / f"coord_{name}_warped.mha"
            run(exe, "warp", coord, "--lattice", moved, "-o", out, "--method", "pullback-linear")
            vm_mapped[..., a] = sitk.GetArrayFromImage(sitk.ReadImage(str(out)))
        # Trilinear interpolation reproduces the coordinates wherever all eight neighbours
        # exist: mapped points inside the box of voxel centres. The output's border layer
        # lies on the faces of the lattice box, where ITK decides by rounding whether a
        # point is inside its transform domain (and leaves it unmoved if not): left out.
        exact = inner_mask(g, mapped, 1, 0.0)
        diff = np.abs(vm_mapped - mapped).max(axis=-1)
        err = diff[exact].max()
        extent = np.abs(centres).max()
        faces = ~inner_mask(g, mapped, 1, -np.inf)
        off_faces = int((diff[faces] > 1e-9 * extent).sum())
        record(
            "transform: .tfm read by SimpleITK == volmorph's lattice",
            err <= 1e-9 * extent,
            f"{exact.sum()} voxels, max |volmorph - SimpleITK| = {err:.2e} "
            f"(coordinates up to {extent:.1f}, voxels moved by up to {moved_by.max():.2f}); "
            f"on the lattice box's faces {off_faces} of {faces.sum()} voxels differ",
        )

        img = sitk.ReadImage(str(src))
        value_range = float(values.max() - values.min())
        mask = inner_mask(g, mapped, MARGIN, MARGIN)
        for method, interp in (
            ("pullback-linear", sitk.sitkLinear),
            ("pullback-cubic", sitk.sitkBSpline),
        ):
            out = tmp / f"{method}.mha"
            run(exe, "warp", src, "--lattice", moved, "-o", out, "--method", method)
            ours = sitk.GetArrayFromImage(sitk.ReadImage(str(out)))
            peer = sitk.GetArrayFromImage(sitk.Resample(img, img, tx, interp, 0.0))
            diff = np.abs(ours - peer)
            worst = diff[mask].max() / value_range
            everywhere = diff.max() / value_range
            record(
                f"resample {method} vs sitk.Resample",
                worst <= args.tol,
                f"{mask.sum()} of {mask.size} voxels (margin {MARGIN}), max difference "
                f"{worst:.2e} of the value range {value_range:.1f} (tolerance {args.tol:.0e}); "
                f"{everywhere:.2e} including the border",
            )
    print("FAIL" if FAILED else "PASS")
    sys.exit(1 if FAILED else 0)


if __name__ == "__main__":
    main()
