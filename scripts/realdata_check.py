#!/usr/bin/env python3
"""volmorph on real files that PyPI packages ship, compared with the packages' own readers.

For every file found, volmorph reads it (`volmorph info --json`, `volmorph convert` to
NIfTI) and the result is compared with the peer's reading:

* nibabel's test data (nibabel/tests/data): NIfTI-1 and NIfTI-2 (3-D and 4-D, every frame),
  FreeSurfer .mgz — voxels exactly, geometry (nibabel's RAS affine turned to ITK/LPS) to 1e-5;
  and SimpleITK's geometry for the NIfTI files it reads.
* pydicom's test files (pydicom.data, with pydicom-data where installed): every greyscale
  single-frame and multi-frame image — voxels against pydicom's pixel_array with the rescale,
  geometry against ImagePositionPatient / ImageOrientationPatient / PixelSpacing (and the
  functional groups of enhanced files). Files volmorph refuses (colour, no patient geometry,
  a codec pydicom cannot decode either, or one of UNDECODED_SYNTAXES) must be refused with a
  clear message, not a crash; refusing any other image pydicom decodes is a failure.
* dipy's and nilearn's bundled NIfTI data, when those packages are installed.

Every check is SKIP when its package is absent. Usage:

    python3 scripts/realdata_check.py [--volmorph target/release/volmorph] [--max-files N]

Exit status 1 if any check that ran failed.
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
except ImportError:  # main() skips: every peer reader below needs it
    np = None

ROOT = Path(__file__).resolve().parent.parent
RESULTS: list[tuple[str, str, str]] = []
#: RAS ↔ LPS (flip x and y), as a 4 × 4 matrix (None without numpy: main() skips).
LPS = None if np is None else np.diag([-1.0, -1.0, 1.0, 1.0])


def record(name: str, status: str, detail: str = "") -> None:
    RESULTS.append((name, status, detail))
    print(f"{status:4}  {name}" + (f"  ({detail})" if detail else ""), flush=True)


def find_volmorph(arg: str | None) -> Path | None:
    for c in [arg, ROOT / "target/release/volmorph", ROOT / "target/debug/volmorph"]:
        if c and Path(c).is_file():
            return Path(c)
    return None


class Volmorph:
    def __init__(self, exe: Path, tmp: Path):
        self.exe, self.tmp, self.n = exe, tmp, 0

    def run(self, *args: str) -> subprocess.CompletedProcess:
        return subprocess.run([str(self.exe), *map(str, args)], capture_output=True, text=True)

    def info(self, path: Path, frame: int | None = None) -> dict:
        extra = ["--frame", str(frame)] if frame is not None else []
        r = self.run("info", "--json", path, *extra)
        if r.returncode != 0:
            raise RuntimeError(r.stderr.strip())
        return json.loads(r.stdout)

    def voxels(self, path: Path, frame: int | None = None) -> np.ndarray:
        """The volume as read by volmorph, indexed [i, j, k] (via a NIfTI written by it)."""
        import nibabel as nib

        self.n += 1
        out = self.tmp / f"v{self.n}.nii"
        extra = ["--frame", str(frame)] if frame is not None else []
        r = self.run("convert", path, out, *extra)
        if r.returncode != 0:
            raise RuntimeError(r.stderr.strip())
        return np.asarray(nib.load(out).dataobj)


def geometry_close(info: dict, spacing, origin, direction, tol: float = 1e-5) -> str | None:
    s, o = np.array(info["spacing"]), np.array(info["origin"])
    d = np.array(info["direction"])
    for name, a, b in [("spacing", s, spacing), ("origin", o, origin), ("direction", d, direction)]:
        b = np.asarray(b, dtype=float)
        if a.shape != b.shape or not np.allclose(a, b, atol=tol, rtol=tol):
            return f"{name} {a.tolist()} vs {b.tolist()}"
    return None


def lps_from_affine(affine, zooms):
    m = LPS @ np.asarray(affine, dtype=float)
    cols = m[:3, :3]
    return list(zooms[:3]), m[:3, 3], cols / np.linalg.norm(cols, axis=0)


def check_nibabel(vm: Volmorph) -> None:
    try:
        import nibabel as nib
    except ImportError:
        record("nibabel test data", "SKIP", "nibabel is not installed")
        return
    try:
        import SimpleITK as sitk
    except ImportError:
        sitk = None
    files = sorted(
        p
        for p in (Path(nib.__file__).parent / "tests" / "data").iterdir()
        if p.name.endswith((".nii", ".nii.gz", ".mgz", ".mgh"))
    )
    for p in files:
        name = f"nibabel {p.name}"
        try:
            img = nib.load(p)
            data = np.asarray(img.dataobj)
            hdr_ok = img.header.get("sform_code", 1) or img.header.get("qform_code", 1)
        except Exception as e:  # noqa: BLE001 - a peer that cannot read it: not our check
            record(name, "SKIP", f"nibabel cannot read it: {e}")
            continue
        if data.ndim not in (3, 4) or data.dtype.kind not in "iuf" or data.ndim == 4 and 1 in data.shape[:3]:
            record(name, "SKIP", f"{data.ndim}-D {data.dtype} (not a 3-D/4-D scalar volume)")
            continue
        frames = data.shape[3] if data.ndim == 4 else 1
        try:
            fails = []
            for t in range(frames):
                frame = t if frames > 1 else None
                info = vm.info(p, frame)
                if info["frames"] != frames:
                    fails.append(f"frames {info['frames']} vs {frames}")
                ours = vm.voxels(p, frame)
                want = data[..., t] if frames > 1 else data
                if ours.shape != want.shape or not np.allclose(ours, want, rtol=1e-6, atol=1e-6, equal_nan=True):
                    fails.append(f"frame {t}: voxels differ")
                if hdr_ok:
                    g = geometry_close(info, *lps_from_affine(img.affine, img.header.get_zooms()))
                    if g:
                        fails.append(f"frame {t}: {g}")
            if sitk is not None and p.name.endswith((".nii", ".nii.gz")) and frames == 1:
                try:
                    s = sitk.ReadImage(str(p))
                    g = geometry_close(
                        vm.info(p), s.GetSpacing(), s.GetOrigin(),
                        np.array(s.GetDirection()).reshape(3, 3), 1e-6,
                    )
                    if g:
                        fails.append(f"vs SimpleITK: {g}")
                except RuntimeError:
                    pass  # SimpleITK refuses it; nibabel's reading was compared
            record(name, "FAIL" if fails else "PASS", "; ".join(fails) or f"{frames} frame(s)")
        except RuntimeError as e:
            record(name, "FAIL", str(e)[:200])


def dose_scaling(ds) -> float:
    """RT Dose's DoseGridScaling (PS3.3 C.8.8.3: stored value x scaling = dose in Gy), else 1.
    pydicom's pixel_array and apply_rescale leave it to the caller."""
    return float(getattr(ds, "DoseGridScaling", 1) or 1)


def group_items(ds, f: int, seq: str) -> list:
    """The `seq` macros that apply to frame `f` of an enhanced file, most specific first: the
    per-frame functional group's, then the shared one's (PS3.3 C.7.6.16)."""
    per = ds.get("PerFrameFunctionalGroupsSequence")
    groups = [per[f] if per is not None and f < len(per) else None]
    if "SharedFunctionalGroupsSequence" in ds:
        groups.append(ds.SharedFunctionalGroupsSequence[0])
    return [g[seq][0] for g in groups if g is not None and seq in g]


def frame_rescales(ds) -> list[tuple[float, float]]:
    """(slope, intercept) of each frame: the per-frame or shared functional groups'
    PixelValueTransformationSequence of an enhanced file (PS3.3 C.7.6.16.2.9), else the
    top-level RescaleSlope / RescaleIntercept. (pydicom's apply_rescale reads only the
    top level and per-frame groups of some files, so the script reads them itself.)"""
    frames = int(getattr(ds, "NumberOfFrames", 1) or 1)
    top = (float(getattr(ds, "RescaleSlope", 1) or 1), float(getattr(ds, "RescaleIntercept", 0) or 0))
    out = []
    for f in range(frames):
        items = group_items(ds, f, "PixelValueTransformationSequence")
        out.append((float(items[0].RescaleSlope), float(items[0].RescaleIntercept)) if items else top)
    return out


def frame_geometry(ds, f: int = 0):
    """(ImagePositionPatient, ImageOrientationPatient, PixelSpacing) of frame `f`: the
    per-frame functional group, then the shared one (PS3.3 C.7.6.16), then the top level."""

    def find(seq, tag):
        for it in group_items(ds, f, seq):
            if tag in it:
                return [float(v) for v in it[tag].value]
        return [float(v) for v in ds[tag].value] if tag in ds else None

    return (
        find("PlanePositionSequence", "ImagePositionPatient"),
        find("PlaneOrientationSequence", "ImageOrientationPatient"),
        find("PixelMeasuresSequence", "PixelSpacing"),
    )


# Transfer syntaxes whose decoders volmorph does not build in (README, File formats: DICOM):
# JPEG 2000, JPEG-LS and HTJ2K need C/C++ codec libraries. A refusal of any other image that
# pydicom decodes is a failure.
UNDECODED_SYNTAXES = {
    "1.2.840.10008.1.2.4.80",  # JPEG-LS lossless
    "1.2.840.10008.1.2.4.81",  # JPEG-LS near-lossless
    "1.2.840.10008.1.2.4.90",  # JPEG 2000 lossless
    "1.2.840.10008.1.2.4.91",  # JPEG 2000
    "1.2.840.10008.1.2.4.201",  # HTJ2K lossless
    "1.2.840.10008.1.2.4.202",  # HTJ2K lossless RPCL
    "1.2.840.10008.1.2.4.203",  # HTJ2K
}


def check_pydicom(vm: Volmorph, max_files: int) -> None:
    try:
        import pydicom
        from pydicom.data import get_testdata_files
    except ImportError:
        record("pydicom test files", "SKIP", "pydicom is not installed")
        return
    files = sorted(set(get_testdata_files("*.dcm")))[:max_files]
    for f in files:
        p = Path(f)
        name = f"pydicom {p.name}"
        try:
            ds = pydicom.dcmread(p)
        except Exception as e:  # noqa: BLE001
            record(name, "SKIP", f"pydicom cannot read it: {e}")
            continue
        if "PixelData" not in ds or "Rows" not in ds:
            continue
        # pydicom's test folder holds unrelated files that share series UIDs (one slice in
        # several transfer syntaxes): read each file on its own, as a one-file series.
        alone = vm.tmp / f"dcm{len(RESULTS)}"
        alone.mkdir()
        (alone / p.name).write_bytes(p.read_bytes())
        p = alone / p.name
        r = vm.run("info", "--json", p)
        greyscale = int(getattr(ds, "SamplesPerPixel", 1)) == 1
        try:
            arr = ds.pixel_array
        except Exception as e:  # noqa: BLE001 - pydicom lacks a decoder: compare refusal only
            arr = None
            why = str(e).splitlines()[0][:80]
        has_geometry = "ImagePositionPatient" in ds or "PerFrameFunctionalGroupsSequence" in ds
        if r.returncode != 0:
            msg = r.stderr.strip().splitlines()[-1] if r.stderr.strip() else ""
            msg = msg.replace(str(p.parent) + "/", "")[-200:]
            if "panicked" in r.stderr or r.returncode != 1:
                record(name, "FAIL", f"crash: {msg}")
            elif not greyscale or not has_geometry or arr is None:
                record(name, "PASS", f"refused clearly: {msg}")
            elif str(ds.file_meta.get("TransferSyntaxUID", "")) in UNDECODED_SYNTAXES:
                record(name, "PASS", f"refused clearly (a codec the README lists as not built in): {msg}")
            else:
                record(name, "FAIL", f"refused an image pydicom decodes: {msg}")
            continue
        if arr is None:
            record(name, "PASS", f"read (pydicom has no decoder to compare: {why})")
            continue
        info = json.loads(r.stdout)
        frames = int(getattr(ds, "NumberOfFrames", 1) or 1)
        try:
            ours = vm.voxels(p)
        except RuntimeError as e:
            record(name, "FAIL", str(e)[:200])
            continue
        fails = []
        if frames == 1:
            (m, b), = frame_rescales(ds)
            want = ((arr.astype(np.float64) * m + b) * dose_scaling(ds)).T[:, :, None]  # [i, j, 1]
            if ours.shape != want.shape or not np.allclose(ours, want, atol=1e-3):
                fails.append(f"voxels differ (shape {ours.shape} vs {want.shape})")
            ipp, iop, ps = frame_geometry(ds)
            iop = np.array(iop, dtype=float)
            rdir, cdir = iop[:3] / np.linalg.norm(iop[:3]), iop[3:] / np.linalg.norm(iop[3:])
            direction = np.column_stack([rdir, cdir, np.cross(rdir, cdir)])
            g = geometry_close(
                info, [ps[1], ps[0], info["spacing"][2]],
                np.array(ipp, dtype=float), direction, 1e-4,
            )
            if g:
                fails.append(g)
        else:
            # Multi-frame: every frame's values appear as one slice of ours, rescaled (per
            # frame for enhanced files, by DoseGridScaling for RT Dose); slices are in position
            # order, which is the file's order or its reverse for these files.
            stack = np.stack(
                [arr[f].astype(np.float64) * m + b for f, (m, b) in enumerate(frame_rescales(ds))]
            ) * dose_scaling(ds)
            same = ours.shape[2] == frames and ours.shape[:2] == stack.shape[:0:-1]
            if same:
                slices = [ours[:, :, k].T for k in range(frames)]
                fwd = all(np.allclose(slices[k], stack[k], atol=1e-3) for k in range(frames))
                rev = all(
                    np.allclose(slices[k], stack[frames - 1 - k], atol=1e-3)
                    for k in range(frames)
                )
                same = fwd or rev
            if not same:
                fails.append(f"frames differ ({ours.shape} vs {stack.shape})")
        record(name, "FAIL" if fails else "PASS", "; ".join(fails) or f"{info['dims']} {info['voxel_type']}")


def check_bundled_nifti(vm: Volmorph, package: str, paths_of) -> None:
    try:
        import nibabel as nib

        paths = paths_of()
    except ImportError:
        record(f"{package} data", "SKIP", f"{package} is not installed")
        return
    for p in paths:
        p = Path(p)
        img = nib.load(p)
        data = np.asarray(img.dataobj)
        frames = data.shape[3] if data.ndim == 4 else 1
        fails = []
        for t in sorted({0, frames - 1}):
            frame = t if frames > 1 else None
            try:
                info = vm.info(p, frame)
                ours = vm.voxels(p, frame)
            except RuntimeError as e:
                fails.append(str(e)[:160])
                break
            want = data[..., t] if frames > 1 else data
            if not np.allclose(ours, want, rtol=1e-6, atol=1e-6, equal_nan=True):
                fails.append(f"frame {t}: voxels differ")
            g = geometry_close(info, *lps_from_affine(img.affine, img.header.get_zooms()))
            if g:
                fails.append(g)
        record(f"{package} {p.name}", "FAIL" if fails else "PASS", "; ".join(fails) or f"{frames} frame(s)")


def dipy_files():
    from dipy.data import get_fnames

    return [get_fnames(name="small_64D")[0]]


def nilearn_files():
    import nilearn

    base = Path(nilearn.__file__).parent / "datasets" / "data"
    return sorted(base.glob("*.nii.gz"))[:3]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--volmorph", help="path of the volmorph binary")
    ap.add_argument("--max-files", type=int, default=200, help="most pydicom files to check")
    a = ap.parse_args()
    if np is None:
        print("SKIP: numpy is not installed (pip install numpy nibabel pydicom)")
        return 0
    exe = find_volmorph(a.volmorph)
    if exe is None:
        print("SKIP: no volmorph binary (cargo build --release -p volmorph-cli)")
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        vm = Volmorph(exe, Path(tmp))
        check_nibabel(vm)
        check_pydicom(vm, a.max_files)
        check_bundled_nifti(vm, "dipy", dipy_files)
        check_bundled_nifti(vm, "nilearn", nilearn_files)
    counts = {s: sum(1 for r in RESULTS if r[1] == s) for s in ("PASS", "FAIL", "SKIP")}
    print(f"{counts['PASS']} passed, {counts['FAIL']} failed, {counts['SKIP']} skipped")
    return 1 if counts["FAIL"] else 0


if __name__ == "__main__":
    sys.exit(main())
