"""Type stubs of the `volmorph` package."""

from typing import Any, Optional, Sequence, Tuple

from ._volmorph import (
    FileError as FileError,
    Frep as Frep,
    Geometry as Geometry,
    InputError as InputError,
    Map as Map,
    MapError as MapError,
    ModelError as ModelError,
    Nurbs as Nurbs,
    Scene as Scene,
    SceneError as SceneError,
    Volume as Volume,
    VolmorphError as VolmorphError,
    WarpError as WarpError,
    __version__ as __version__,
    ffd as ffd,
    isosurface as isosurface,
    jacobian_map as jacobian_map,
    read_mesh as read_mesh,
    warp as warp,
    write_mesh as write_mesh,
)

def from_sitk(image: Any) -> Volume: ...
def to_sitk(volume: Volume) -> Any: ...
def from_nibabel(image: Any) -> Volume: ...
def to_nibabel(volume: Volume) -> Any: ...
def drag(
    volume: Volume,
    grabbed: Sequence[Sequence[float]],
    targets: Sequence[Sequence[float]],
    lattice: Optional[Map] = None,
    counts: Tuple[int, int, int] = (9, 9, 9),
    radius: Optional[float] = None,
    freeze_boundary: bool = False,
    method: str = "pushforward-antialiased",
) -> Tuple[Volume, Map, dict]: ...
from . import dask as dask
