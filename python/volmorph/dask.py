"""Chunked warps on Dask: one task per output chunk, each reading only the input it needs.

``warp(source, map, output_geometry, chunks=...)`` warps ``source`` through ``map`` onto
``output_geometry``, chunk by chunk, with a pull-back (output voxel x takes the input at
``map(x)``, ITK's convention) or a push-forward (input voxel p goes to ``map(p)``, True 1992
§5.3–5.4). The source is a dask array (with its ``input_geometry``) or the path of an OME-Zarr
image; the result is a dask array, or an OME-Zarr store when ``output=`` is given. Whichever
method, the result is **bit for bit** ``volmorph.warp(volume, map, method, output_geometry)``,
whatever the chunk shapes and however many workers run it.

Pull-backs (``pullback-linear``, ``pullback-nearest``; in Rust ``volmorph_warp::chunked``):
the map is evaluated at the chunk's voxel centres exactly as the single-process warp
evaluates it, the bounding box of the sampled input indices is widened by the interpolation
kernel's support and a one-voxel margin, only that box of the input is read, and it is
sampled.

Push-forwards (``pushforward-antialiased``, ``pushforward-nearest``; in Rust
``volmorph_warp::chunked::push``, design and costs in ``docs/chunked-pushforward.md``): the
graph is *planned* where it is built, one evaluation of the map over the input's voxels (in
parallel threads, GIL released) that finds, for every output chunk, the input slabs whose
footprints reach it and the box of their voxels that does. Each chunk's task reads that box
once and recomputes those voxels' tallies restricted to the chunk, slab by slab in the order
the in-memory push-forward adds them, then normalises: no task depends on another.

* OME-Zarr source: each task opens the store and reads only its box (only the store chunks
  overlapping it are decoded); the graph has exactly one task per output chunk and no
  dependencies.
* Dask-array source: the box of every output chunk is computed when the graph is built (the
  pull-back's preimages, one evaluation of the map over the output grid; the push-forward's
  plan, over the input grid), and each warp task depends on the slice ``source[box]`` only,
  so dask moves just those input chunks to the worker.

The cubic pull-back (its B-spline prefilter spans the whole volume) and the inverse methods
do not run chunk by chunk; which methods do is the library's one policy
(``volmorph_warp::chunked::ChunkedMethod``).

Nothing here schedules work: the graph runs on whatever Dask scheduler is active, a
``distributed.LocalCluster`` or a multi-node cluster (dask-jobqueue, dask-kubernetes)::

    from dask.distributed import Client, LocalCluster
    client = Client(LocalCluster(n_workers=2, threads_per_worker=1))
    vm.dask.warp("ct.ome.zarr", m, chunks=(64, 64, 64), output="warped.ome.zarr")
"""

from __future__ import annotations

import functools
import itertools
import os
from concurrent.futures import ThreadPoolExecutor
from typing import Any, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _volmorph
from ._volmorph import Geometry, Map, Volume

__all__ = ["warp", "to_ome_zarr", "from_ome_zarr", "chunk_preimage", "push_plan"]

Zyx = Tuple[int, int, int]


def _require_dask():
    try:
        import dask.array as da  # noqa: F401
    except ImportError as e:  # pragma: no cover - exercised only without dask
        raise ImportError(
            "volmorph.dask needs dask: pip install 'dask[array]' (and distributed for a cluster)"
        ) from e
    return da


def _geometry_tuple(g: Geometry):
    """A picklable description of a geometry (Geometry objects stay in one process)."""
    return (tuple(g.shape), tuple(g.spacing), tuple(g.origin), [list(r) for r in g.direction])


@functools.lru_cache(maxsize=8)
def _geometry(t) -> Geometry:
    shape, spacing, origin, direction = t
    return Geometry(shape, spacing, origin, [list(r) for r in direction])


@functools.lru_cache(maxsize=8)
def _map(text: str) -> Map:
    """The map of a JSON text, parsed once per worker process."""
    return Map.from_json(text)


def _freeze(t):
    shape, spacing, origin, direction = t
    return (shape, spacing, origin, tuple(tuple(r) for r in direction))


def _normalize_chunks(chunks, shape, dtype):
    da = _require_dask()
    return da.core.normalize_chunks(chunks, shape=shape, dtype=dtype)


def _starts(chunks):
    return [np.cumsum((0,) + tuple(c))[:-1].tolist() for c in chunks]


def _blocks(chunks):
    """Every output chunk as (block index, start, stop), numpy order."""
    starts = _starts(chunks)
    for idx in itertools.product(*[range(len(c)) for c in chunks]):
        start = tuple(int(starts[a][idx[a]]) for a in range(3))
        stop = tuple(start[a] + int(chunks[a][idx[a]]) for a in range(3))
        yield idx, start, stop


def chunk_preimage(
    map: Map,
    input_geometry: Geometry,
    output_geometry: Geometry,
    start: Zyx,
    stop: Zyx,
    method: str = "pullback-linear",
) -> Optional[Tuple[Zyx, Zyx]]:
    """The box ``(start, stop)`` (``(z, y, x)``, half-open) of input voxels that the output
    chunk ``start..stop`` reads, or ``None`` if it reads none. Exact (see the module docs)."""
    return _volmorph.chunk_preimage(
        map, input_geometry, output_geometry, tuple(start), tuple(stop), method
    )


def push_plan(
    map: Map,
    input_geometry: Geometry,
    output_geometry: Geometry,
    chunks,
    method: str = "pushforward-antialiased",
    background: float = 0.0,
) -> List[Tuple[Zyx, Optional[Tuple[Zyx, Zyx]], List[Tuple[int, Tuple[Zyx, Zyx], Tuple[Zyx, Zyx]]]]]:
    """The plan of a chunked push-forward of an input on ``input_geometry`` through ``map``
    onto ``output_geometry`` cut into ``chunks`` (dask's normalised chunks, ``(z, y, x)``).

    One entry per output chunk, z slowest and x fastest: ``(block index, input box or None,
    sources)``. The input box ``(start, stop)`` (``(z, y, x)``, half-open) is what the chunk's
    task reads (``None``: nothing reaches the chunk, it is the background); the sources are
    ``(slab, input box, output box)``, the in-memory push-forward's input slabs reaching the
    chunk in the order their tallies add (see ``docs/chunked-pushforward.md``). One
    evaluation of the map over the input's voxels, in parallel threads, GIL released."""
    return _volmorph.push_plan(
        map, input_geometry, output_geometry, tuple(tuple(int(n) for n in c) for c in chunks),
        method, background,
    )


def _zarr_task(path, map_json, out_geom, start, stop, method, background, level):
    v = _volmorph.warp_zarr_chunk(
        path, _map(map_json), _geometry(out_geom), start, stop, method, background, level
    )
    return v.array


def _array_task(region, region_start, map_json, in_geom, out_geom, start, stop, method, background):
    region = np.ascontiguousarray(region)
    v = _volmorph.warp_chunk(
        Volume(region),
        tuple(region_start),
        _map(map_json),
        _geometry(in_geom),
        _geometry(out_geom),
        start,
        stop,
        method,
        background,
    )
    return v.array


def _push_zarr_task(path, sources, map_json, out_geom, start, stop, method, background, level):
    v = _volmorph.push_zarr_chunk(
        path, sources, _map(map_json), _geometry(out_geom), start, stop, method, background, level
    )
    return v.array


def _push_array_task(
    region, region_start, sources, map_json, in_geom, out_geom, start, stop, method, background
):
    region = np.ascontiguousarray(region)
    v = _volmorph.push_chunk(
        Volume(region),
        tuple(region_start),
        sources,
        _map(map_json),
        _geometry(in_geom),
        _geometry(out_geom),
        start,
        stop,
        method,
        background,
    )
    return v.array


def _is_path(source) -> bool:
    return isinstance(source, (str, os.PathLike))


def warp(
    source: Union[str, os.PathLike, Any],
    map: Map,
    output_geometry: Optional[Geometry] = None,
    chunks: Union[None, int, Sequence[int], str] = None,
    *,
    input_geometry: Optional[Geometry] = None,
    method: str = "pullback-linear",
    background: float = 0.0,
    level: int = 0,
    output: Union[None, str, os.PathLike] = None,
    zarr_version: int = 2,
    levels: Optional[int] = None,
):
    """Warp ``source`` through ``map`` onto ``output_geometry``, one task per output chunk.

    ``source``: an OME-Zarr path (its ``level`` is read; geometry from its metadata) or a
    3-D dask array of shape ``(nz, ny, nx)`` with ``input_geometry``. ``output_geometry``
    defaults to the input's grid. ``chunks`` is the output chunk shape ``(z, y, x)`` (any
    form dask accepts; default: the source's chunks). ``method`` is ``pullback-linear``,
    ``pullback-nearest``, ``pushforward-antialiased`` (True's box filter, averaged face
    centres) or ``pushforward-nearest``; ``background`` fills voxels whose source lies outside
    the input (pull-backs) or that nothing covers (antialiased push-forward: uncovered
    fractions are blended with it; ``pushforward-nearest`` takes 0 only). The map runs in the
    direction of the method: output to input for a pull-back, input to output for a
    push-forward.

    Returns a dask array (dtype of the source), or, with ``output=`` a ``.ome.zarr`` path,
    computes it into that store (OME-NGFF v0.4 on Zarr v2 or v0.5 on Zarr v3 with
    ``zarr_version=3``, with a pyramid) and returns the path. A push-forward evaluates the
    map over the input's voxels here, before returning (the plan, see the module docs).

    Raises ``InputError`` for a method that does not run chunk by chunk (cubic pull-back,
    inverse methods) or a non-finite background, and ``WarpError`` when the map cannot be
    evaluated or a task's working memory exceeds the budget.

    >>> import numpy as np, dask.array as da, volmorph as vm
    >>> a = np.arange(6 * 7 * 8, dtype=np.float32).reshape(6, 7, 8)
    >>> g = vm.Geometry(a.shape)
    >>> w = vm.dask.warp(da.from_array(a, chunks=3), vm.Map.identity(), g, input_geometry=g)
    >>> bool((w.compute() == a).all())
    True
    """
    da = _require_dask()
    from dask.base import tokenize
    from dask.highlevelgraph import HighLevelGraph

    map_json = map.to_json()
    kind = _volmorph.chunked_kind(method, background)
    if _is_path(source):
        path = os.fspath(source)
        in_geom, dtype, store_chunks = _volmorph.zarr_info(path, level)
        if input_geometry is not None:
            raise _volmorph.InputError(
                "input_geometry is read from the OME-Zarr metadata; do not pass it with a path"
            )
        default_chunks = store_chunks
    else:
        if input_geometry is None:
            raise _volmorph.InputError("a dask-array source needs input_geometry=")
        in_geom = input_geometry
        if tuple(source.shape) != tuple(in_geom.shape):
            raise _volmorph.InputError(
                f"source shape {tuple(source.shape)} does not match input_geometry's "
                f"{tuple(in_geom.shape)}"
            )
        dtype = str(source.dtype)
        default_chunks = source.chunksize
    out_geom = in_geom if output_geometry is None else output_geometry
    out_t = _freeze(_geometry_tuple(out_geom))
    in_t = _freeze(_geometry_tuple(in_geom))
    norm = _normalize_chunks(default_chunks if chunks is None else chunks, out_geom.shape, dtype)
    name = "volmorph-warp-" + tokenize(
        os.fspath(source) if _is_path(source) else source.name,
        map_json,
        in_t,
        out_t,
        norm,
        method,
        background,
        level,
    )
    blocks = list(_blocks(norm))
    if kind == "push":
        plan = {
            idx: (b, src) for idx, b, src in push_plan(map, in_geom, out_geom, norm, method, background)
        }
        boxes = [plan[idx][0] for idx, _, _ in blocks]
        sources = [plan[idx][1] for idx, _, _ in blocks]
    elif not _is_path(source):

        def box(b):
            _, start, stop = b
            return chunk_preimage(map, in_geom, out_geom, start, stop, method)

        with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
            boxes = list(pool.map(box, blocks))
    if _is_path(source):
        if kind == "push":
            dsk = {
                (name,) + idx: (
                    _push_zarr_task, path, src, map_json, out_t, start, stop, method,
                    background, level,
                )
                for (idx, start, stop), src in zip(blocks, sources)
            }
        else:
            dsk = {
                (name,) + idx: (
                    _zarr_task, path, map_json, out_t, start, stop, method, background, level
                )
                for idx, start, stop in blocks
            }
        graph = HighLevelGraph.from_collections(name, dsk, dependencies=[])
        result = da.Array(graph, name, norm, dtype=np.dtype(dtype))
    else:
        from dask import delayed

        task = delayed(_push_array_task if kind == "push" else _array_task, pure=True)
        pieces = np.empty(tuple(len(c) for c in norm), dtype=object)
        for i, ((idx, start, stop), b) in enumerate(zip(blocks, boxes)):
            if b is None:  # nothing is read: one voxel gives the voxel type (and background)
                b = ((0, 0, 0), (1, 1, 1))
            (z0, y0, x0), (z1, y1, x1) = b
            region = source[z0:z1, y0:y1, x0:x1]
            shape = tuple(stop[a] - start[a] for a in range(3))
            if kind == "push":
                d = task(
                    region, b[0], sources[i], map_json, in_t, out_t, start, stop, method,
                    background,
                )
            else:
                d = task(region, b[0], map_json, in_t, out_t, start, stop, method, background)
            pieces[idx] = da.from_delayed(d, shape=shape, dtype=np.dtype(dtype))
        result = da.block(pieces.tolist())
    if output is None:
        return result
    return to_ome_zarr(result, out_geom, output, zarr_version=zarr_version, levels=levels)


def _store_task(block, staging, block_info=None):
    loc = block_info[0]["array-location"]
    start = tuple(int(s) for s, _ in loc)
    _volmorph.zarr_store_chunk(staging, start, Volume(np.ascontiguousarray(block)))
    return np.zeros((1, 1, 1), dtype=bool)


def to_ome_zarr(
    array,
    geometry: Geometry,
    path: Union[str, os.PathLike],
    *,
    zarr_version: int = 2,
    levels: Optional[int] = None,
    chunks: Optional[Zyx] = None,
):
    """Compute the dask ``array`` (shape ``geometry.shape``) into an OME-Zarr store at ``path``.

    Each dask task writes its own store chunks (the array is rechunked to the store's regular
    chunks, ``chunks`` or the array's first chunk shape); the pyramid is built and the store
    moved into place when every chunk is written, so a failed computation leaves nothing at
    ``path``. NGFF has no direction matrix: a geometry with a non-identity direction is
    refused. Returns ``path``.
    """
    _require_dask()
    if tuple(array.shape) != tuple(geometry.shape):
        raise _volmorph.InputError(
            f"array shape {tuple(array.shape)} does not match the geometry's {tuple(geometry.shape)}"
        )
    want = tuple(int(c) for c in (chunks or array.chunksize))
    writer = _volmorph.OmeZarrWriter(
        os.fspath(path), geometry, str(array.dtype), want, zarr_version, levels
    )
    store_chunks = writer.chunks
    if tuple(array.chunks) != tuple(
        _normalize_chunks(store_chunks, array.shape, array.dtype)
    ):
        array = array.rechunk(store_chunks)
    staging = os.fspath(writer.staging)
    array.map_blocks(
        _store_task, staging, dtype=bool, chunks=(1, 1, 1), meta=np.zeros((0, 0, 0), bool)
    ).compute()
    writer.finish()
    return path


def from_ome_zarr(path: Union[str, os.PathLike], level: int = 0, chunks=None):
    """A dask array over resolution ``level`` of the OME-Zarr image at ``path`` (one task per
    chunk, each reading only its box) and the level's geometry: ``(array, geometry)``."""
    da = _require_dask()
    from dask.base import tokenize
    from dask.highlevelgraph import HighLevelGraph

    p = os.fspath(path)
    geometry, dtype, store_chunks = _volmorph.zarr_info(p, level)
    norm = _normalize_chunks(store_chunks if chunks is None else chunks, geometry.shape, dtype)
    name = "volmorph-read-" + tokenize(p, level, norm, os.path.getmtime(p))
    dsk = {
        (name,) + idx: (_read_task, p, start, stop, level) for idx, start, stop in _blocks(norm)
    }
    graph = HighLevelGraph.from_collections(name, dsk, dependencies=[])
    return da.Array(graph, name, norm, dtype=np.dtype(dtype)), geometry


def _read_task(path, start, stop, level):
    return _volmorph.zarr_read_box(path, start, stop, level).array
