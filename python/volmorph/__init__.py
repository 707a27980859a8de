"""volmorph: modeling with volumes by deforming space.

Volumes are numpy arrays of shape ``(nz, ny, nx)`` (x fastest, as SimpleITK's
``GetArrayFromImage``) with an ITK-style geometry: ``spacing`` and ``origin`` in ``(x, y, z)``
and a direction matrix whose column ``c`` is the physical direction of index axis ``c``.
Physical space is LPS as in ITK and DICOM (NIfTI's RAS is converted on read and write).

Every computation runs in Rust with the GIL released. Errors are subclasses of
:class:`VolmorphError` carrying the messages of the ``volmorph`` command line.

Copies: a :class:`Volume` keeps the numpy array it was made from; each computation copies
its input voxels once into Rust; results are handed to numpy without a copy. Points (N×3
float64) are read in place.

>>> import numpy as np, volmorph as vm
>>> v = vm.Volume(np.zeros((16, 16, 16), np.float32), spacing=(1.0, 1.0, 2.0))
>>> m = vm.Map.affine(np.eye(3), (0.5, 0.0, 0.0))
>>> w = vm.warp(v, m, "pullback-linear")
>>> w.shape, w.spacing
((16, 16, 16), (1.0, 1.0, 2.0))
"""

from __future__ import annotations

from typing import Any, Optional, Sequence, Tuple

import numpy as np

from ._volmorph import (
    FileError,
    Frep,
    Geometry,
    InputError,
    Map,
    MapError,
    ModelError,
    Nurbs,
    Scene,
    SceneError,
    Volume,
    VolmorphError,
    WarpError,
    __version__,
    ffd,
    isosurface,
    jacobian_map,
    read_mesh,
    warp,
    write_mesh,
)

__all__ = [
    "FileError",
    "Frep",
    "Geometry",
    "InputError",
    "Map",
    "MapError",
    "ModelError",
    "Nurbs",
    "Scene",
    "SceneError",
    "Volume",
    "VolmorphError",
    "WarpError",
    "__version__",
    "drag",
    "ffd",
    "from_nibabel",
    "from_sitk",
    "isosurface",
    "jacobian_map",
    "read_mesh",
    "to_nibabel",
    "to_sitk",
    "warp",
    "write_mesh",
]

# RAS (NIfTI, nibabel) ↔ LPS (ITK, volmorph): negate x and y.
_RAS_TO_LPS = np.diag([-1.0, -1.0, 1.0])


def from_sitk(image: Any) -> Volume:
    """A Volume from a 3-D ``SimpleITK.Image`` (same voxels, spacing, origin, direction).

    SimpleITK is not a dependency; pass an image made with it. The voxels are copied once
    (``GetArrayFromImage``).
    """
    import SimpleITK as sitk  # noqa: PLC0415 (optional peer)

    if image.GetDimension() != 3 or image.GetNumberOfComponentsPerPixel() != 1:
        raise InputError(
            f"from_sitk: expected a 3-D scalar image, got {image.GetDimension()}-D with "
            f"{image.GetNumberOfComponentsPerPixel()} components"
        )
    array = np.ascontiguousarray(sitk.GetArrayFromImage(image))
    direction = np.asarray(image.GetDirection(), dtype=float).reshape(3, 3)
    return Volume(
        array,
        spacing=tuple(image.GetSpacing()),
        origin=tuple(image.GetOrigin()),
        direction=direction.tolist(),
    )


def to_sitk(volume: Volume) -> Any:
    """The Volume as a ``SimpleITK.Image`` (voxels copied by ``GetImageFromArray``)."""
    import SimpleITK as sitk  # noqa: PLC0415 (optional peer)

    image = sitk.GetImageFromArray(volume.array)
    image.SetSpacing(volume.spacing)
    image.SetOrigin(volume.origin)
    image.SetDirection(tuple(np.asarray(volume.direction, dtype=float).ravel()))
    return image


def from_nibabel(image: Any) -> Volume:
    """A Volume from a 3-D nibabel image (its affine, RAS, becomes volmorph's LPS geometry).

    The voxels are copied once (nibabel's ``(i, j, k)`` order is transposed to
    ``(k, j, i)``); scaled data (``scl_slope``) arrive as nibabel's ``dataobj`` gives them.
    """
    data = np.asanyarray(image.dataobj)
    if data.ndim != 3:
        raise InputError(f"from_nibabel: expected a 3-D image, got shape {data.shape}")
    affine = _RAS_TO_LPS @ np.asarray(image.affine, dtype=float)[:3, :]
    columns = affine[:, :3]
    spacing = np.linalg.norm(columns, axis=0)
    if np.any(spacing <= 0) or not np.all(np.isfinite(affine)):
        raise InputError(f"from_nibabel: the affine is degenerate: {image.affine.tolist()}")
    return Volume(
        np.ascontiguousarray(data.transpose(2, 1, 0)),
        spacing=tuple(spacing),
        origin=tuple(affine[:, 3]),
        direction=(columns / spacing).tolist(),
    )


def to_nibabel(volume: Volume) -> Any:
    """The Volume as a ``nibabel.Nifti1Image`` (RAS affine; the data is a transposed view)."""
    import nibabel as nib  # noqa: PLC0415 (optional peer)

    affine = np.eye(4)
    affine[:3, :3] = np.asarray(volume.direction) * np.asarray(volume.spacing)
    affine[:3, 3] = volume.origin
    affine[:3, :] = _RAS_TO_LPS @ affine[:3, :]
    return nib.Nifti1Image(volume.array.transpose(2, 1, 0), affine)


def drag(
    volume: Volume,
    grabbed: Sequence[Sequence[float]],
    targets: Sequence[Sequence[float]],
    lattice: Optional[Map] = None,
    counts: Tuple[int, int, int] = (9, 9, 9),
    radius: Optional[float] = None,
    freeze_boundary: bool = False,
    method: str = "pushforward-antialiased",
) -> Tuple[Volume, Map, dict]:
    """Direct manipulation (True 1992 §6), as ``volmorph drag``: the points ``grabbed`` of the
    model as deformed by ``lattice`` (default: the identity lattice of ``counts`` control
    points over the volume) go exactly to ``targets``. Returns the deformed volume, the new
    lattice and the scene's change report (``report["drag"]`` says how the drag was solved).

    It runs as scene commands (add, derived warp, drag), exactly like the CLI.
    """
    scene = Scene()
    v = scene.add_volume("input", volume)
    if lattice is None:
        lattice = Map.lattice(volume.geometry, counts)
    m = scene.add_map("lattice", lattice)
    added = scene.add_derived(
        "output",
        {
            "recipe": "warp",
            "source": v,
            "map": m,
            "method": method,
            "background": 0.0,
            "sampled_nodes": None,
            "swap_handles": False,
        },
    )
    if added["errors"]:
        raise WarpError(added["errors"][0][1])
    w = added["added"][0]
    report = scene.drag_points(
        m,
        np.asarray(grabbed, dtype=float).reshape(-1, 3),
        np.asarray(targets, dtype=float).reshape(-1, 3),
        radius=radius,
        freeze_boundary=freeze_boundary,
    )
    if report["errors"]:
        raise WarpError(report["errors"][0][1])
    return scene.volume(w), scene.map(m), report


def __getattr__(name: str):
    """``volmorph.dask`` is imported on first use (it needs dask only then)."""
    if name == "dask":
        import importlib

        return importlib.import_module(".dask", __name__)
    raise AttributeError(f"module 'volmorph' has no attribute {name!r}")
