"""Volume: numpy round trips, files, geometry against SimpleITK and nibabel, bad input."""

import numpy as np
import pytest
from conftest import ROTATION, blob

import volmorph as vm

DTYPES = [np.uint8, np.int8, np.uint16, np.int16, np.uint32, np.int32, np.float32, np.float64]


@pytest.mark.parametrize("dtype", DTYPES)
def test_numpy_round_trip_keeps_the_array_and_geometry(dtype):
    a = np.arange(4 * 5 * 6).reshape(4, 5, 6).astype(dtype)
    v = vm.Volume(a, spacing=(0.5, 2.0, 3.0), origin=(1, 2, 3), direction=ROTATION.tolist())
    assert v.array is a  # no copy in
    assert np.shares_memory(np.asarray(v), a)
    assert v.dtype == np.dtype(dtype).name
    assert v.shape == (4, 5, 6)
    assert v.geometry.shape == (4, 5, 6)
    assert v.spacing == (0.5, 2.0, 3.0)
    assert v.origin == (1.0, 2.0, 3.0)
    np.testing.assert_array_equal(np.asarray(v.direction), ROTATION)
    # Through Rust and back (identity warp): same voxels, a new array owned by numpy.
    w = vm.warp(v, vm.Map.identity(), "pullback-nearest")
    assert w.dtype == v.dtype
    np.testing.assert_array_equal(w.array, a)
    assert not np.shares_memory(w.array, a)


def test_index_to_physical_is_origin_plus_direction_times_spacing():
    v = blob()
    idx = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0], [8.0, 10.0, 12.0]])
    expected = np.asarray(v.origin) + (ROTATION @ (idx * np.asarray(v.spacing)).T).T
    got = v.geometry.index_to_physical(idx)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(v.geometry.physical_to_index(got), idx, atol=1e-12)


@pytest.mark.parametrize("ext", [".nii.gz", ".nii", ".mha", ".nrrd", ".vti", ".mgz"])
def test_file_round_trip(tmp_path, ext):
    v = blob(dtype=np.int16)
    path = tmp_path / f"v{ext}"
    v.write(path)
    r = vm.Volume.read(path)
    assert r.dtype == "int16"
    np.testing.assert_array_equal(r.array, v.array)
    np.testing.assert_allclose(r.spacing, v.spacing, rtol=1e-6)
    np.testing.assert_allclose(r.origin, v.origin, atol=1e-5)
    np.testing.assert_allclose(np.asarray(r.direction), ROTATION, atol=1e-5)


def test_geometry_agrees_with_simpleitk(tmp_path):
    sitk = pytest.importorskip("SimpleITK")
    v = blob()
    path = tmp_path / "v.mha"
    v.write(path)
    img = sitk.ReadImage(str(path))
    np.testing.assert_array_equal(sitk.GetArrayFromImage(img), v.array)
    np.testing.assert_allclose(img.GetSpacing(), v.spacing, rtol=1e-6)
    np.testing.assert_allclose(img.GetOrigin(), v.origin, atol=1e-6)
    np.testing.assert_allclose(np.reshape(img.GetDirection(), (3, 3)), ROTATION, atol=1e-6)
    idx = [(0, 0, 0), (3, 7, 2), (8, 10, 12)]
    ours = v.geometry.index_to_physical(np.array(idx, dtype=float))
    theirs = [img.TransformContinuousIndexToPhysicalPoint(i) for i in idx]
    np.testing.assert_allclose(ours, theirs, atol=1e-6)
    # from_sitk / to_sitk round trip.
    back = vm.from_sitk(img)
    np.testing.assert_array_equal(back.array, v.array)
    np.testing.assert_allclose(np.asarray(back.direction), ROTATION, atol=1e-6)
    img2 = vm.to_sitk(v)
    np.testing.assert_allclose(img2.GetOrigin(), v.origin)
    np.testing.assert_allclose(np.reshape(img2.GetDirection(), (3, 3)), ROTATION)
    # A NIfTI written by SimpleITK is read here with the same physical geometry.
    sitk.WriteImage(img2, str(tmp_path / "s.nii.gz"))
    r = vm.Volume.read(tmp_path / "s.nii.gz")
    np.testing.assert_allclose(r.origin, v.origin, atol=1e-4)
    np.testing.assert_allclose(np.asarray(r.direction), ROTATION, atol=1e-4)


def test_geometry_agrees_with_nibabel(tmp_path):
    nib = pytest.importorskip("nibabel")
    v = blob()
    path = tmp_path / "v.nii.gz"
    v.write(path)
    img = nib.load(str(path))
    np.testing.assert_array_equal(np.asanyarray(img.dataobj).transpose(2, 1, 0), v.array)
    # nibabel's affine (RAS) sends voxel (i, j, k) to our point (LPS) with x, y negated.
    ijk = np.array([[0, 0, 0], [3, 7, 2], [8, 10, 12]], dtype=float)
    ras = (img.affine[:3, :3] @ ijk.T).T + img.affine[:3, 3]
    lps = ras * [-1, -1, 1]
    np.testing.assert_allclose(lps, v.geometry.index_to_physical(ijk), atol=1e-4)
    back = vm.from_nibabel(img)
    np.testing.assert_array_equal(back.array, v.array)
    np.testing.assert_allclose(back.origin, v.origin, atol=1e-4)
    np.testing.assert_allclose(np.asarray(back.direction), ROTATION, atol=1e-4)
    out = vm.to_nibabel(v)
    np.testing.assert_allclose(out.affine, img.affine, atol=1e-4)


def test_wrong_dtype_is_an_input_error():
    with pytest.raises(vm.InputError, match="unsupported dtype complex128"):
        vm.Volume(np.zeros((2, 2, 2), np.complex128))
    with pytest.raises(vm.InputError, match="unsupported dtype bool"):
        vm.Volume(np.zeros((2, 2, 2), bool))


def test_non_contiguous_array_is_an_input_error():
    a = np.zeros((4, 5, 6), np.float32)
    with pytest.raises(vm.InputError, match="C-contiguous"):
        vm.Volume(a.transpose(2, 1, 0))
    with pytest.raises(vm.InputError, match="C-contiguous"):
        vm.Volume(a[:, ::2, :])
    vm.Volume(np.ascontiguousarray(a[:, ::2, :]))  # the fix the message names


def test_wrong_shapes_are_input_errors():
    with pytest.raises(vm.InputError, match="3-D array"):
        vm.Volume(np.zeros((4, 5), np.float32))
    with pytest.raises(vm.InputError, match="numpy array"):
        vm.Volume([[[1.0]]])
    with pytest.raises(vm.InputError, match="does not match"):
        vm.Volume(np.zeros((4, 5, 6), np.float32), geometry=vm.Geometry((4, 5, 7)))
    with pytest.raises(vm.InputError, match="spacing"):
        vm.Volume(np.zeros((2, 2, 2), np.float32), spacing=(1.0, 1.0))
    with pytest.raises(vm.InputError, match="finite"):
        vm.Volume(np.zeros((2, 2, 2), np.float32), origin=(0.0, np.nan, 0.0))
    with pytest.raises(vm.InputError, match="geometry"):
        vm.Volume(np.zeros((2, 2, 2), np.float32), spacing=(1.0, -1.0, 1.0))


def test_file_errors_name_the_file(tmp_path):
    missing = tmp_path / "missing.nii.gz"
    with pytest.raises(vm.FileError, match="missing.nii.gz"):
        vm.Volume.read(missing)
    bad = tmp_path / "bad.mha"
    bad.write_text("ObjectType = Image\nNDims = 3\nDimSize = 2 2\n")
    with pytest.raises(vm.FileError, match="bad.mha"):
        vm.Volume.read(bad)
    assert issubclass(vm.FileError, vm.VolmorphError)
    assert issubclass(vm.InputError, vm.VolmorphError)
