#!/usr/bin/env python3
"""Interoperability checks between volmorph and the Python tools people use.

Each check runs only when its peer package is installed and is reported as SKIP otherwise:

* nibabel   — NIfTI written by nibabel (oblique sform + qform) reads in volmorph with the same
              voxels and the same physical geometry; NIfTI written by volmorph reads the same in
              nibabel.
* SimpleITK — volumes with a non-identity direction written by SimpleITK as .nii.gz, .mha,
              .mhd, .nrrd read in volmorph with the same voxels and geometry; volmorph's writes
              of every format read the same in SimpleITK.
* pynrrd    — NRRD written by pynrrd (space directions, gzip) reads the same in volmorph, and
              volmorph's NRRD reads the same in pynrrd.
* trimesh   — meshes written by volmorph (OBJ, STL, PLY, OFF) load in trimesh with the same
              vertex and face counts.

Geometry is compared in ITK/LPS convention: nibabel's RAS affine is converted with
diag(-1, -1, 1). Usage:  python3 scripts/interop.py [--volmorph PATH] [--mesh FILE ...]
Exit status is 1 if any check that ran failed.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS: list[tuple[str, str, str]] = []


def record(name: str, status: str, detail: str = "") -> None:
    RESULTS.append((name, status, detail))
    print(f"{status:4}  {name}" + (f"  ({detail})" if detail else ""), flush=True)


def try_import(name: str):
    try:
        return __import__(name)
    except Exception:  # noqa: BLE001 - any import failure means the peer is absent
        return None


np = try_import("numpy")


def volmorph_binary(arg: str | None) -> Path:
    if arg:
        return Path(arg)
    exe = ROOT / "target" / "release" / "volmorph"
    subprocess.run(["cargo", "build", "--release", "-q", "-p", "volmorph-cli"], cwd=ROOT, check=True)
    return exe


class Volmorph:
    def __init__(self, exe: Path):
        self.exe = exe

    def run(self, *args: str) -> str:
        p = subprocess.run([str(self.exe), *map(str, args)], capture_output=True, text=True)
        if p.returncode != 0:
            raise RuntimeError(f"volmorph {' '.join(map(str, args))} failed: {p.stderr.strip()}")
        return p.stdout

    def info(self, path: Path) -> dict:
        return json.loads(self.run("info", "--json", "--no-stats", path))

    def voxels(self, path: Path, tmp: Path) -> "np.ndarray":
        """Voxels as an (nz, ny, nx) array, read through a volmorph .raw export."""
        info = self.info(path)
        raw = tmp / (path.name + ".export.raw")
        self.run("convert", path, raw)
        nx, ny, nz = info["dims"]
        dt = np.dtype(DTYPES[info["voxel_type"]]).newbyteorder("<")
        return np.fromfile(raw, dtype=dt).reshape(nz, ny, nx)


DTYPES = {"u8": "u1", "i8": "i1", "u16": "u2", "i16": "i2", "u32": "u4", "i32": "i4",
          "f32": "f4", "f64": "f8"}


def rotation(ax: float, ay: float, az: float) -> "np.ndarray":
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def test_volume(nx=13, ny=11, nz=7, dtype="i2") -> "np.ndarray":
    rng = np.random.default_rng(7)
    info = np.iinfo(dtype) if np.dtype(dtype).kind in "iu" else None
    if info is not None:
        return rng.integers(max(info.min, -30000), min(info.max, 30000), size=(nz, ny, nx)).astype(dtype)
    return rng.normal(size=(nz, ny, nx)).astype(dtype)


def close(a, b, tol) -> bool:
    return bool(np.allclose(np.asarray(a, float), np.asarray(b, float), atol=tol, rtol=0))


def check_geometry(name, info, spacing, origin, direction, tol=1e-5):
    ok = close(info["dims"], info["dims"], 0)
    bad = []
    if not close(info["spacing"], spacing, tol):
        bad.append(f"spacing {info['spacing']} != {list(spacing)}")
    if not close(info["origin"], origin, tol):
        bad.append(f"origin {info['origin']} != {list(origin)}")
    if not close(info["direction"], direction, tol):
        bad.append(f"direction {info['direction']} != {np.asarray(direction).tolist()}")
    ok = not bad
    return ok, "; ".join(bad)


# ---------------------------------------------------------------- nibabel
def check_nibabel(vm: Volmorph, tmp: Path) -> None:
    nib = try_import("nibabel")
    if nib is None or np is None:
        record("nibabel", "SKIP", "nibabel not installed")
        return
    data_zyx = test_volume(dtype="i2")
    data_xyz = np.ascontiguousarray(data_zyx.transpose(2, 1, 0))
    spacing = np.array([0.75, 1.25, 2.5])
    rot = rotation(0.3, -0.2, 0.5)
    affine = np.eye(4)
    affine[:3, :3] = rot @ np.diag(spacing)
    affine[:3, 3] = [12.5, -40.25, 7.0]
    for forms in ("sform+qform", "sform only"):
        img = nib.Nifti1Image(data_xyz, affine)
        if forms == "sform only":
            img.set_qform(None, code=0)
        else:
            img.set_qform(affine, code=1)
        img.set_sform(affine, code=1)
        for ext in (".nii", ".nii.gz"):
            p = tmp / f"nib{ext}"
            nib.save(img, p)
            info = vm.info(p)
            lps = np.diag([-1.0, -1.0, 1.0])
            ok, why = check_geometry("", info, spacing, lps @ affine[:3, 3], lps @ rot)
            same = np.array_equal(vm.voxels(p, tmp), data_zyx)
            record(f"nibabel writes {ext} ({forms}), volmorph reads", "PASS" if ok and same else "FAIL",
                   why if not ok else ("" if same else "voxels differ"))
            # volmorph writes, nibabel reads
            out = tmp / f"vm_from_nib{ext}"
            vm.run("convert", p, out)
            back = nib.load(out)
            ok2 = close(back.affine, affine, 1e-5) and np.array_equal(np.asanyarray(back.dataobj), data_xyz)
            record(f"volmorph writes {ext} ({forms} source), nibabel reads", "PASS" if ok2 else "FAIL",
                   "" if ok2 else f"affine {back.affine.tolist()}")


# ---------------------------------------------------------------- SimpleITK
def check_simpleitk(vm: Volmorph, tmp: Path) -> None:
    sitk = try_import("SimpleITK")
    if sitk is None or np is None:
        record("SimpleITK", "SKIP", "SimpleITK not installed")
        return
    for dtype in ("u1", "i2", "u2", "f4", "f8"):
        arr = test_volume(dtype=dtype)
        img = sitk.GetImageFromArray(arr)
        spacing = (0.5, 0.8, 1.7)
        origin = (-3.5, 14.0, 100.25)
        direction = rotation(0.4, 0.1, -0.6)
        img.SetSpacing(spacing)
        img.SetOrigin(origin)
        img.SetDirection(direction.flatten().tolist())
        for ext in (".nii.gz", ".nii", ".mha", ".mhd", ".nrrd"):
            p = tmp / f"sitk_{dtype}{ext}"
            sitk.WriteImage(img, str(p), useCompression=ext in (".mha", ".nrrd"))
            info = vm.info(p)
            ok, why = check_geometry("", info, spacing, origin, direction)
            same = np.array_equal(vm.voxels(p, tmp), arr)
            record(f"SimpleITK writes {ext} {dtype}, volmorph reads", "PASS" if ok and same else "FAIL",
                   why if not ok else ("" if same else "voxels differ"))
            for out_ext in (".nii.gz", ".mha", ".mhd", ".nrrd"):
                out = tmp / f"vm_{dtype}_{ext.strip('.').replace('.', '_')}{out_ext}"
                vm.run("convert", p, out, "--compress")
                back = sitk.ReadImage(str(out))
                ok2 = (close(back.GetSpacing(), spacing, 1e-5) and close(back.GetOrigin(), origin, 1e-5)
                       and close(back.GetDirection(), direction.flatten(), 1e-5)
                       and np.array_equal(sitk.GetArrayFromImage(back), arr))
                if not ok2 or ext == ".nii.gz":
                    record(f"volmorph writes {out_ext} {dtype}, SimpleITK reads", "PASS" if ok2 else "FAIL",
                           "" if ok2 else f"spacing {back.GetSpacing()} origin {back.GetOrigin()} "
                                          f"direction {back.GetDirection()}")
    # VTK legacy: SimpleITK writes no direction there; identity geometry only.
    arr = test_volume(dtype="f4")
    img = sitk.GetImageFromArray(arr)
    img.SetSpacing((0.5, 0.25, 2.0))
    img.SetOrigin((1.0, 2.0, -3.0))
    p = tmp / "sitk.vtk"
    sitk.WriteImage(img, str(p))
    info = vm.info(p)
    ok, why = check_geometry("", info, (0.5, 0.25, 2.0), (1.0, 2.0, -3.0), np.eye(3))
    same = np.array_equal(vm.voxels(p, tmp), arr)
    record("SimpleITK writes .vtk f4, volmorph reads", "PASS" if ok and same else "FAIL",
           why if not ok else ("" if same else "voxels differ"))
    out = tmp / "vm.vtk"
    vm.run("convert", p, out)
    back = sitk.ReadImage(str(out))
    ok2 = (close(back.GetSpacing(), (0.5, 0.25, 2.0), 1e-6) and close(back.GetOrigin(), (1.0, 2.0, -3.0), 1e-6)
           and np.array_equal(sitk.GetArrayFromImage(back), arr))
    record("volmorph writes .vtk f4, SimpleITK reads", "PASS" if ok2 else "FAIL")


# ---------------------------------------------------------------- pynrrd
def check_pynrrd(vm: Volmorph, tmp: Path) -> None:
    nrrd = try_import("nrrd")
    if nrrd is None or np is None:
        record("pynrrd", "SKIP", "pynrrd not installed")
        return
    data_xyz = np.ascontiguousarray(test_volume(dtype="i2").transpose(2, 1, 0))
    dirs = rotation(-0.3, 0.25, 0.9) @ np.diag([0.6, 0.9, 1.4])
    origin = np.array([5.0, -6.5, 30.0])
    for space, flip in (("left-posterior-superior", np.diag([1.0, 1, 1])),
                        ("right-anterior-superior", np.diag([-1.0, -1, 1]))):
        header = {"space": space, "space directions": dirs.T, "space origin": origin,
                  "kinds": ["domain"] * 3, "encoding": "gzip"}
        p = tmp / f"pynrrd_{space[:5]}.nrrd"
        nrrd.write(str(p), data_xyz, header, index_order="F")
        info = vm.info(p)
        spacing = np.linalg.norm(dirs, axis=0)
        ok, why = check_geometry("", info, spacing, flip @ origin, flip @ dirs / spacing)
        same = np.array_equal(vm.voxels(p, tmp), data_xyz.transpose(2, 1, 0))
        record(f"pynrrd writes NRRD ({space}), volmorph reads", "PASS" if ok and same else "FAIL",
               why if not ok else ("" if same else "voxels differ"))
    out = tmp / "vm_pynrrd.nrrd"
    vm.run("convert", tmp / "pynrrd_left-.nrrd", out, "--compress")
    back, hdr = nrrd.read(str(out), index_order="F")
    ok2 = (np.array_equal(back, data_xyz) and close(hdr["space directions"], dirs.T, 1e-9)
           and close(hdr["space origin"], origin, 1e-9))
    record("volmorph writes NRRD, pynrrd reads", "PASS" if ok2 else "FAIL")


# ---------------------------------------------------------------- trimesh
def check_trimesh(vm: Volmorph, tmp: Path, meshes: list[Path]) -> None:
    trimesh = try_import("trimesh")
    if trimesh is None:
        record("trimesh", "SKIP", "trimesh not installed")
        return
    src = tmp / "icosphere.ply"
    trimesh.creation.icosphere(subdivisions=3).export(src)
    sources = [src] + [m for m in meshes if m.exists()]
    for m in sources:
        for ext, extra in ((".obj", []), (".stl", []), (".stl", ["--ascii"]), (".ply", []),
                           (".ply", ["--ascii"]), (".off", [])):
            out = tmp / f"{m.name.split('.')[0]}{'_ascii' if extra else ''}{ext}"
            vm.run("mesh", "convert", m, out, *extra)
            ref = trimesh.load(m, process=False, force="mesh") if not m.name.endswith(".gz") else None
            back = trimesh.load(out, process=False, force="mesh")
            if ext == ".stl":
                # STL stores triangles only; trimesh merges vertices only when processing.
                back = trimesh.load(out, force="mesh")
            nv, nf = len(back.vertices), len(back.faces)
            want_v = len(ref.vertices) if ref is not None else nv
            want_f = len(ref.faces) if ref is not None else nf
            ok = nv == want_v and nf == want_f
            record(f"volmorph writes {out.name}, trimesh loads", "PASS" if ok else "FAIL",
                   f"{nv} vertices, {nf} faces" + ("" if ok else f"; expected {want_v}, {want_f}"))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--volmorph", help="path to the volmorph binary (default: build release)")
    ap.add_argument("--mesh", action="append", default=[], help="extra mesh files to convert")
    args = ap.parse_args()
    if np is None:
        print("SKIP  all checks: numpy not installed")
        return 0
    vm = Volmorph(volmorph_binary(args.volmorph))
    meshes = [Path(m) for m in args.mesh]
    bunny = ROOT.parent / "shared" / "data" / "meshes" / "bunny.obj"
    if not args.mesh and bunny.exists():
        meshes.append(bunny)
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for check in (check_nibabel, check_simpleitk, check_pynrrd):
            try:
                check(vm, tmp)
            except Exception as e:  # noqa: BLE001 - report and go on with the next peer
                record(check.__name__, "FAIL", str(e))
        try:
            check_trimesh(vm, tmp, meshes)
        except Exception as e:  # noqa: BLE001
            record("check_trimesh", "FAIL", str(e))
    passed = sum(1 for _, s, _ in RESULTS if s == "PASS")
    failed = sum(1 for _, s, _ in RESULTS if s == "FAIL")
    skipped = sum(1 for _, s, _ in RESULTS if s == "SKIP")
    print(f"interop: {passed} passed, {failed} failed, {skipped} skipped")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
