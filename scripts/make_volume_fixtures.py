#!/usr/bin/env python3
"""Write the small peer-made volume fixtures of crates/volume-io/tests/corpus/peers/.

The Rust tests (crates/volume-io/tests/integration/peer_fixtures.rs) read every file and compare with
`expected.json`, which holds what the peer itself reads back (geometry in ITK/LPS convention,
direction row-major, and every voxel value in x-fastest order):

* nibabel 5  — an oblique NIfTI-1 (single-precision sform + qform, as scanners write them),
               a NIfTI-2 with a double-precision affine, a 4-D NIfTI-1 with 3 frames and a
               FreeSurfer .mgz (oblique, uint8 and float32).
* SimpleITK 2 — an oblique .nii.gz, and a DICOM CT series (oblique orientation, rescale
               intercept −1024) written slice by slice with the geometry tags, read back by
               SimpleITK's series reader for the expected values.
* VTK 9      — .vti image data with a direction matrix in every layout vtkXMLImageDataWriter
               writes: ascii, binary (base64), appended raw and base64, each zlib-compressed
               or not, and a big-endian file.
* pydicom 3  — an enhanced multi-frame CT (per-frame plane positions, shared orientation,
               pixel measures and rescale in the functional groups).

Run once with the peers installed (pip install nibabel SimpleITK pydicom numpy):

    python3 scripts/make_volume_fixtures.py [--out crates/volume-io/tests/corpus/peers]

The files are committed; the tests need no Python.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
LPS = np.diag([-1.0, -1.0, 1.0, 1.0])


def rotation(a: float, b: float, c: float) -> np.ndarray:
    """Rz(a) · Ry(b) · Rx(c)."""
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    rz = np.array([[ca, -sa, 0], [sa, ca, 0], [0, 0, 1]])
    ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    rx = np.array([[1, 0, 0], [0, cc, -sc], [0, sc, cc]])
    return rz @ ry @ rx


def ramp(shape_xyz: tuple[int, ...], dtype, scale: float = 1.0) -> np.ndarray:
    """Values i + 10 j + 100 k (+ 1000 t) in an array indexed [i, j, k(, t)]."""
    idx = np.indices(shape_xyz).astype(np.float64)
    w = [1.0, 10.0, 100.0, 1000.0]
    v = sum(w[a] * idx[a] for a in range(len(shape_xyz)))
    return (v * scale).astype(dtype)


def entry_from_affine(affine: np.ndarray, zooms, data_xyz: np.ndarray) -> dict:
    """Expected ITK/LPS geometry of a RAS voxel-to-world affine with ITK's reading rules."""
    m = LPS @ np.asarray(affine, dtype=np.float64)
    cols = m[:3, :3]
    direction = cols / np.linalg.norm(cols, axis=0)
    return {
        "dims": list(data_xyz.shape[:3]),
        "spacing": [float(z) for z in zooms[:3]],
        "origin": [float(v) for v in m[:3, 3]],
        "direction": [float(v) for v in direction.reshape(-1)],
        "values": [float(v) for v in data_xyz.reshape(-1, order="F")],
    }


def entry_from_sitk(img) -> dict:
    import SimpleITK as sitk

    arr = sitk.GetArrayFromImage(img)  # z, y, x
    return {
        "dims": list(img.GetSize()),
        "spacing": list(img.GetSpacing()),
        "origin": list(img.GetOrigin()),
        "direction": list(img.GetDirection()),
        "values": [float(v) for v in arr.reshape(-1)],
    }


def nibabel_fixtures(out: Path, expected: dict) -> None:
    import nibabel as nib

    r = rotation(0.35, -0.2, 0.5)
    spacing = np.array([0.9, 1.1, 2.5])
    aff = np.eye(4)
    aff[:3, :3] = r @ np.diag(spacing)
    aff[:3, 3] = [-40.25, 12.5, 7.75]
    data = ramp((6, 5, 4), np.int16)
    img = nib.Nifti1Image(data, aff)
    img.set_qform(aff, code=1)
    img.set_sform(aff, code=1)
    nib.save(img, out / "nibabel_oblique.nii.gz")
    back = nib.load(out / "nibabel_oblique.nii.gz")
    expected["nibabel_oblique.nii.gz"] = entry_from_affine(
        back.affine, back.header.get_zooms(), np.asarray(back.dataobj)
    )

    # NIfTI-2: the affine is stored in double precision.
    img2 = nib.Nifti2Image(ramp((5, 4, 3), np.float32, 0.5), aff)
    img2.set_qform(aff, code=1)
    img2.set_sform(aff, code=1)
    nib.save(img2, out / "nibabel_nifti2.nii")
    back = nib.load(out / "nibabel_nifti2.nii")
    expected["nibabel_nifti2.nii"] = entry_from_affine(
        back.affine, back.header.get_zooms(), np.asarray(back.dataobj)
    )

    # 4-D: three frames, each its own ramp (+1000 t).
    data4 = ramp((4, 3, 2, 3), np.int16)
    img4 = nib.Nifti1Image(data4, aff)
    img4.set_qform(aff, code=1)
    img4.set_sform(aff, code=1)
    img4.header.set_xyzt_units("mm", "sec")
    img4.header["pixdim"][4] = 2.0
    nib.save(img4, out / "nibabel_4d.nii.gz")
    back = nib.load(out / "nibabel_4d.nii.gz")
    full = np.asarray(back.dataobj)
    for t in range(full.shape[3]):
        e = entry_from_affine(back.affine, back.header.get_zooms(), full[..., t])
        e["frame"] = t
        e["frames"] = int(full.shape[3])
        expected[f"nibabel_4d.nii.gz#{t}"] = e
    # Frame 1 alone, with the series' header (same sform/qform bytes): what every command
    # must read from the series with --frame 1 (crates/cli/tests/integration/realdata.rs).
    frame1 = nib.Nifti1Image(full[..., 1], back.affine, header=back.header.copy())
    nib.save(frame1, out / "nibabel_4d_frame1.nii.gz")

    # FreeSurfer MGZ: oblique, uint8 and float32.
    for name, dtype in [("nibabel_oblique_u8.mgz", np.uint8), ("nibabel_f32.mgz", np.float32)]:
        d = ramp((5, 4, 3), dtype) if dtype == np.float32 else (ramp((5, 4, 3), np.int32) % 251).astype(np.uint8)
        mgh = nib.MGHImage(d, aff)
        nib.save(mgh, out / name)
        back = nib.load(out / name)
        expected[name] = entry_from_affine(
            back.affine, back.header.get_zooms(), np.asarray(back.dataobj)
        )


def sitk_fixtures(out: Path, expected: dict) -> None:
    import SimpleITK as sitk

    d = rotation(-0.4, 0.25, 0.15)  # an LPS direction
    arr = ramp((6, 5, 4), np.int16).transpose(2, 1, 0).copy()  # z, y, x
    img = sitk.GetImageFromArray(arr)
    img.SetSpacing((0.8, 1.2, 2.0))
    img.SetOrigin((10.5, -20.25, 30.0))
    img.SetDirection(tuple(d.reshape(-1)))
    sitk.WriteImage(img, str(out / "sitk_oblique.nii.gz"))
    expected["sitk_oblique.nii.gz"] = entry_from_sitk(sitk.ReadImage(str(out / "sitk_oblique.nii.gz")))

    # DICOM CT series, slice by slice (the SimpleITK "DICOM series from array" recipe).
    series_dir = out / "sitk_ct_series"
    series_dir.mkdir(exist_ok=True)
    for f in series_dir.glob("*.dcm"):
        f.unlink()
    hu = (ramp((8, 6, 5), np.int32) - 1024).astype(np.int16).transpose(2, 1, 0).copy()
    ct = sitk.GetImageFromArray(hu)
    ct.SetSpacing((0.7, 0.75, 1.25))
    ct.SetOrigin((-60.0, 35.5, -110.25))
    ct.SetDirection(tuple(d.reshape(-1)))
    writer = sitk.ImageFileWriter()
    writer.KeepOriginalImageUIDOn()
    study = "1.2.826.0.1.3680043.2.1125.1.1"
    series = "1.2.826.0.1.3680043.2.1125.1.2"
    orient = "\\".join(f"{v:.10f}" for v in (d[0, 0], d[1, 0], d[2, 0], d[0, 1], d[1, 1], d[2, 1]))
    # Written in a shuffled order so the reader must sort by position.
    for n, k in enumerate([3, 0, 4, 1, 2]):
        sl = ct[:, :, k]
        p = ct.TransformIndexToPhysicalPoint((0, 0, k))
        tags = {
            "0008|0060": "CT",
            "0008|0016": "1.2.840.10008.5.1.4.1.1.2",
            "0008|0018": f"{series}.{k + 1}",
            "0020|000d": study,
            "0020|000e": series,
            "0020|0037": orient,
            "0020|0032": "\\".join(f"{v:.6f}" for v in p),
            "0020|0013": str(k + 1),
            "0028|1052": "-1024",
            "0028|1053": "1",
            "0018|0050": "1.25",
        }
        for key, val in tags.items():
            sl.SetMetaData(key, val)
        writer.SetFileName(str(series_dir / f"slice{n}.dcm"))
        writer.Execute(sl)
    reader = sitk.ImageSeriesReader()
    names = reader.GetGDCMSeriesFileNames(str(series_dir))
    reader.SetFileNames(names)
    back = reader.Execute()
    expected["sitk_ct_series"] = entry_from_sitk(back)


def vtk_fixtures(out: Path, expected: dict) -> None:
    try:
        import vtk
        from vtk.util import numpy_support
    except ImportError:
        print("SKIP vtk fixtures: the vtk package is not installed")
        return
    d = rotation(0.2, -0.5, 0.3)
    arr = ramp((5, 4, 3), np.float32, 0.25) - 3.0  # [i, j, k]
    img = vtk.vtkImageData()
    img.SetExtent(2, 6, -1, 2, 0, 2)  # the extent does not start at 0
    img.SetOrigin(3.5, -7.25, 11.0)
    img.SetSpacing(0.5, 0.75, 1.5)
    img.SetDirectionMatrix(*[float(v) for v in d.reshape(-1)])
    flat = numpy_support.numpy_to_vtk(arr.reshape(-1, order="F").copy(), deep=True)
    flat.SetName("density")
    img.GetPointData().SetScalars(flat)
    origin0 = np.array(img.GetOrigin()) + d @ (np.array(img.GetSpacing()) * np.array([2, -1, 0]))
    entry = {
        "dims": [5, 4, 3],
        "spacing": [0.5, 0.75, 1.5],
        "origin": [float(v) for v in origin0],
        "direction": [float(v) for v in d.reshape(-1)],
        "values": [float(v) for v in arr.reshape(-1, order="F")],
    }
    layouts = [
        ("ascii", lambda w: w.SetDataModeToAscii(), False),
        ("binary", lambda w: w.SetDataModeToBinary(), False),
        ("binary_zlib", lambda w: w.SetDataModeToBinary(), True),
        ("appended_raw", lambda w: (w.SetDataModeToAppended(), w.EncodeAppendedDataOff()), False),
        ("appended_raw_zlib", lambda w: (w.SetDataModeToAppended(), w.EncodeAppendedDataOff()), True),
        ("appended_b64", lambda w: (w.SetDataModeToAppended(), w.EncodeAppendedDataOn()), False),
        ("appended_b64_zlib", lambda w: (w.SetDataModeToAppended(), w.EncodeAppendedDataOn()), True),
    ]
    for name, mode, zlib in layouts:
        w = vtk.vtkXMLImageDataWriter()
        w.SetInputData(img)
        mode(w)
        if zlib:
            w.SetCompressorTypeToZLib()
            w.SetBlockSize(64)  # several blocks
        else:
            w.SetCompressorTypeToNone()
        fname = f"vtk_{name}.vti"
        w.SetFileName(str(out / fname))
        assert w.Write() == 1, fname
        expected[fname] = entry
    w = vtk.vtkXMLImageDataWriter()
    w.SetInputData(img)
    w.SetByteOrderToBigEndian()
    w.SetHeaderTypeToUInt32()
    w.SetDataModeToAppended()
    w.EncodeAppendedDataOff()
    w.SetCompressorTypeToNone()
    w.SetFileName(str(out / "vtk_bigendian_u32.vti"))
    assert w.Write() == 1
    expected["vtk_bigendian_u32.vti"] = entry


def enhanced_fixture(out: Path, expected: dict) -> None:
    """An Enhanced CT Image Storage file with 4 frames, written by pydicom."""
    import pydicom
    from pydicom.dataset import Dataset, FileMetaDataset
    from pydicom.sequence import Sequence
    from pydicom.uid import ExplicitVRLittleEndian

    r = rotation(0.3, 0.1, -0.25)  # LPS direction
    spacing = [0.6, 0.8, 1.5]  # column spacing (x), row spacing (y), slice step
    origin = np.array([-12.0, 40.5, 101.0])
    nx, ny, nz = 5, 4, 4
    stored = (ramp((nx, ny, nz), np.int32) + 24).astype(np.uint16)  # [i, j, k]
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = "1.2.840.10008.5.1.4.1.1.2.1"
    meta.MediaStorageSOPInstanceUID = "1.2.826.0.1.3680043.2.1125.2.1"
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = Dataset()
    ds.file_meta = meta
    ds.SOPClassUID = meta.MediaStorageSOPClassUID
    ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
    ds.StudyInstanceUID = "1.2.826.0.1.3680043.2.1125.2.2"
    ds.SeriesInstanceUID = "1.2.826.0.1.3680043.2.1125.2.3"
    ds.Modality = "CT"
    ds.Rows, ds.Columns = ny, nx
    ds.NumberOfFrames = nz
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 16, 16, 15, 0
    shared = Dataset()
    po = Dataset()
    po.ImageOrientationPatient = [float(v) for v in (*r[:, 0], *r[:, 1])]
    shared.PlaneOrientationSequence = Sequence([po])
    pm = Dataset()
    pm.PixelSpacing = [spacing[1], spacing[0]]  # row spacing, column spacing
    pm.SliceThickness = spacing[2]
    shared.PixelMeasuresSequence = Sequence([pm])
    tr = Dataset()
    tr.RescaleIntercept = -1000
    tr.RescaleSlope = 2
    tr.RescaleType = "HU"
    shared.PixelValueTransformationSequence = Sequence([tr])
    ds.SharedFunctionalGroupsSequence = Sequence([shared])
    per = []
    # Frames stored in reverse slice order: the reader must sort them along the normal.
    order = list(reversed(range(nz)))
    for k in order:
        f = Dataset()
        pp = Dataset()
        pp.ImagePositionPatient = [float(v) for v in origin + r[:, 2] * spacing[2] * k]
        f.PlanePositionSequence = Sequence([pp])
        per.append(f)
    ds.PerFrameFunctionalGroupsSequence = Sequence(per)
    frames = np.stack([stored[:, :, k].T for k in order])  # frame, row (j), column (i)
    ds.PixelData = frames.astype("<u2").tobytes()
    ds.save_as(out / "pydicom_enhanced_ct.dcm", enforce_file_format=True)
    values = stored.astype(np.float64) * 2 - 1000
    expected["pydicom_enhanced_ct.dcm"] = {
        "dims": [nx, ny, nz],
        "spacing": spacing,
        "origin": [float(v) for v in origin],
        "direction": [float(v) for v in r.reshape(-1)],
        "values": [float(v) for v in values.reshape(-1, order="F")],
    }


def _image_dataset(sop_class: str, uid: str, syntax):
    from pydicom.dataset import Dataset, FileMetaDataset

    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = sop_class
    meta.MediaStorageSOPInstanceUID = uid + ".1"
    meta.TransferSyntaxUID = syntax
    ds = Dataset()
    ds.file_meta = meta
    ds.SOPClassUID = sop_class
    ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
    ds.StudyInstanceUID = uid + ".2"
    ds.SeriesInstanceUID = uid + ".3"
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    return ds


def rtdose_fixture(out: Path, expected: dict) -> None:
    """RT Dose files as treatment-planning systems write them, by pydicom: 32-bit unsigned
    frames placed by an absolute GridFrameOffsetVector (its first element is the z of
    ImagePositionPatient, uneven steps), DoseGridScaling to Gy; the same dose in explicit VR big
    endian (one frame)."""
    from pydicom.uid import ExplicitVRBigEndian, ExplicitVRLittleEndian

    nx, ny, nz = 4, 3, 3
    origin = np.array([-20.0, 7.5, -31.0])
    offsets = [-31.0, -28.5, -26.0]  # absolute: z of each frame
    spacing = [2.0, 2.5, 2.5]
    stored = (ramp((nx, ny, nz), np.int64) * 1000 + 123456).astype(np.uint32)
    scaling = 1.5e-5

    def dose(syntax, frames, uid):
        ds = _image_dataset("1.2.840.10008.5.1.4.1.1.481.2", uid, syntax)
        ds.Modality = "RTDOSE"
        ds.Rows, ds.Columns = ny, nx
        ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 32, 32, 31, 0
        ds.ImagePositionPatient = [float(v) for v in origin]
        ds.ImageOrientationPatient = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        ds.PixelSpacing = [spacing[1], spacing[0]]
        ds.DoseUnits, ds.DoseType, ds.DoseSummationType = "GY", "PHYSICAL", "PLAN"
        ds.DoseGridScaling = scaling
        ds.GridFrameOffsetVector = offsets[:frames] if frames > 1 else offsets
        if frames > 1:
            ds.NumberOfFrames = frames
            ds.FrameIncrementPointer = 0x3004000C
        arr = np.stack([stored[:, :, k].T for k in range(frames)])
        dt = ">u4" if syntax == ExplicitVRBigEndian else "<u4"
        ds.PixelData = arr.astype(dt).tobytes()
        return ds

    uid = "1.2.826.0.1.3680043.2.1125.3"
    dose(ExplicitVRLittleEndian, nz, uid).save_as(out / "pydicom_rtdose.dcm", enforce_file_format=True)
    # Another series: the files share a folder.
    be = dose(ExplicitVRBigEndian, 1, uid + ".5")
    be.save_as(out / "pydicom_rtdose_be_1frame.dcm", enforce_file_format=True)
    values = stored.astype(np.float64) * scaling
    expected["pydicom_rtdose.dcm"] = {
        "dims": [nx, ny, nz],
        "spacing": spacing,
        "origin": [float(v) for v in origin],
        "direction": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        "values": [float(v) for v in values.reshape(-1, order="F")],
    }
    expected["pydicom_rtdose_be_1frame.dcm"] = {
        "dims": [nx, ny, 1],
        "spacing": [spacing[0], spacing[1], 1.0],
        "origin": [float(v) for v in origin],
        "direction": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        "values": [float(v) for v in values[:, :, :1].reshape(-1, order="F")],
    }


def un_vr_fixture(out: Path, expected: dict) -> None:
    """A CT slice whose geometry and pixel-description attributes are stored with VR UN (what a
    converter that drops the dictionary VRs writes, as in pydicom's explicit_VR-UN.dcm)."""
    import pydicom
    from pydicom.dataelem import RawDataElement
    from pydicom.tag import Tag
    from pydicom.uid import ExplicitVRLittleEndian

    ds = _image_dataset("1.2.840.10008.5.1.4.1.1.2", "1.2.826.0.1.3680043.2.1125.4", ExplicitVRLittleEndian)
    ds.Modality = "CT"
    nx, ny = 5, 3
    stored = (ramp((nx, ny, 1), np.int32) * 3 - 20).astype(np.int16)

    def un(tag, raw: bytes):
        # A raw element keeps VR UN when it is written (with the dictionary VR kept off).
        ds[tag] = RawDataElement(Tag(tag), "UN", len(raw), raw, 0, False, True)

    def text(values):
        t = "\\".join(values).encode()
        return t + b" " * (len(t) % 2)

    un(0x00280010, np.uint16(ny).tobytes())  # Rows
    un(0x00280011, np.uint16(nx).tobytes())  # Columns
    ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 16, 16, 15, 1
    un(0x00200032, text(["-4.5", "10", "2.25"]))  # ImagePositionPatient
    un(0x00200037, text(["0", "1", "0", "0", "0", "-1"]))  # ImageOrientationPatient (sagittal)
    un(0x00280030, text(["0.75", "1.25"]))  # PixelSpacing: row, column spacing
    un(0x00180050, text(["3"]))  # SliceThickness
    un(0x00281053, text(["2"]))  # RescaleSlope
    un(0x00281052, text(["-1024"]))  # RescaleIntercept
    ds.PixelData = stored[:, :, 0].T.astype("<i2").tobytes()
    keep = pydicom.config.replace_un_with_known_vr
    pydicom.config.replace_un_with_known_vr = False
    try:
        ds.save_as(out / "pydicom_un_vr.dcm", enforce_file_format=True)
    finally:
        pydicom.config.replace_un_with_known_vr = keep
    expected["pydicom_un_vr.dcm"] = {
        "dims": [nx, ny, 1],
        "spacing": [1.25, 0.75, 3.0],
        "origin": [-4.5, 10.0, 2.25],
        # columns: row direction (0, 1, 0), column direction (0, 0, -1), normal their cross
        "direction": [0.0, 0.0, -1.0, 1.0, 0.0, 0.0, 0.0, -1.0, 0.0],
        "values": [float(v) for v in (stored.astype(np.float64) * 2 - 1024).reshape(-1, order="F")],
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "crates/volume-io/tests/corpus/peers")
    a = ap.parse_args()
    try:
        import nibabel  # noqa: F401
        import pydicom  # noqa: F401
        import SimpleITK  # noqa: F401
    except ImportError as e:
        print(f"SKIP: {e.name} is not installed (pip install nibabel SimpleITK pydicom)")
        return 0
    a.out.mkdir(parents=True, exist_ok=True)
    expected: dict = {}
    nibabel_fixtures(a.out, expected)
    sitk_fixtures(a.out, expected)
    vtk_fixtures(a.out, expected)
    enhanced_fixture(a.out, expected)
    rtdose_fixture(a.out, expected)
    un_vr_fixture(a.out, expected)
    (a.out / "expected.json").write_text(json.dumps(expected, indent=1) + "\n")
    print(f"wrote {len(expected)} fixtures to {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
