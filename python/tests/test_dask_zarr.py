"""OME-Zarr read/write and chunked warps on Dask.

Dask results must equal the single-process warp bit for bit (odd chunks, rotated grids);
OME-Zarr stores written here must read in zarr / ome-zarr with the same values and scales,
and stores written by those must read here. Each test skips when its peer is absent.
"""

import json
import subprocess

import numpy as np
import pytest

import volmorph as vm
from conftest import ROTATION, bent_lattice, blob


def same_bits(a, b):
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape and a.dtype == b.dtype
    return a.tobytes() == b.tobytes()


def axis_aligned(shape=(20, 17, 15), dtype=np.uint16):
    return blob(shape, dtype, direction=np.eye(3))


# ---- OME-Zarr in volmorph alone ----------------------------------------------------------


@pytest.mark.parametrize("name", ["v.ome.zarr"])
def test_ome_zarr_round_trip_through_volume_read_write(tmp_path, name):
    v = axis_aligned()
    p = tmp_path / name
    v.write(str(p))
    back = vm.Volume.read(str(p))
    assert same_bits(back.array, v.array)
    assert back.spacing == v.spacing and back.origin == v.origin


def test_ome_zarr_refuses_rotated_volumes(tmp_path):
    v = blob((6, 5, 4))  # rotated direction
    with pytest.raises(vm.FileError, match="no direction matrix"):
        v.write(str(tmp_path / "r.ome.zarr"))
    assert not (tmp_path / "r.ome.zarr").exists()


def test_cli_info_and_convert_handle_ome_zarr(tmp_path, cli):
    v = axis_aligned()
    nii = tmp_path / "v.mha"
    v.write(str(nii))
    z = tmp_path / "v.ome.zarr"
    subprocess.run(
        [cli, "convert", str(nii), str(z), "--zarr-version", "3", "--chunk", "8,7,6"], check=True
    )
    info = json.loads(
        subprocess.run([cli, "info", str(z), "--json"], check=True, capture_output=True).stdout
    )
    assert info["format"] == "OME-Zarr"
    assert info["dims"] == [15, 17, 20]
    assert info["header"]["zarr_format"] == "3"
    assert info["header"]["chunk_xyz"] == "[8, 7, 6]"
    back = vm.Volume.read(str(z))
    assert same_bits(back.array, vm.Volume.read(str(nii)).array)


def test_cli_out_of_core_warp_equals_in_memory_warp(tmp_path, cli):
    v = axis_aligned((26, 23, 21))
    m = bent_lattice(v, amount=2.5)
    src = tmp_path / "in.ome.zarr"
    mha = tmp_path / "in.mha"  # MetaImage keeps the geometry exactly
    v.write(str(mha))
    subprocess.run([cli, "convert", str(mha), str(src), "--chunk", "9,7,5"], check=True)
    lat = tmp_path / "m.json"
    m.save(str(lat))
    out = tmp_path / "out.ome.zarr"
    subprocess.run(
        [cli, "warp", str(src), "--lattice", str(lat), "-o", str(out), "--chunk", "5,11,7"],
        check=True,
    )
    ref = vm.warp(v, m, "pullback-linear").array
    assert same_bits(vm.Volume.read(str(out)).array, ref)
    r = subprocess.run(
        [cli, "warp", str(src), "--lattice", str(lat), "-o", str(out), "--method", "pullback-cubic"],
        capture_output=True,
        text=True,
    )
    assert r.returncode != 0 and "pullback-linear" in r.stderr


def test_cli_out_of_core_push_forward_equals_the_in_memory_cli_warp(tmp_path, cli):
    v = axis_aligned((26, 23, 21))
    m = bent_lattice(v, amount=2.5)
    mha = tmp_path / "in.mha"  # MetaImage keeps the geometry exactly
    v.write(str(mha))
    src = tmp_path / "in.ome.zarr"
    subprocess.run([cli, "convert", str(mha), str(src), "--chunk", "9,7,5"], check=True)
    lat = tmp_path / "m.json"
    m.save(str(lat))
    for method, extra in [
        ("pushforward-antialiased", ["--pad", "2", "--default", "1.5"]),
        ("pushforward-nearest", []),
    ]:
        args = ["warp", "--lattice", str(lat), "--method", method, *extra]
        in_memory = tmp_path / f"{method}.mha"
        subprocess.run([cli, *args, str(mha), "-o", str(in_memory)], check=True)
        out = tmp_path / f"{method}.ome.zarr"
        subprocess.run(
            [cli, *args, str(src), "-o", str(out), "--chunk", "5,11,7"], check=True
        )
        a, b = vm.Volume.read(str(in_memory)), vm.Volume.read(str(out))
        assert same_bits(b.array, a.array), method
        assert b.spacing == a.spacing and b.origin == a.origin


# ---- Dask ---------------------------------------------------------------------------------


def test_dask_array_warp_is_bit_identical_on_odd_chunks_with_rotated_grids():
    da = pytest.importorskip("dask.array")
    v = blob((23, 19, 17))  # rotated input grid
    m = bent_lattice(v)
    go = vm.Geometry(
        (21, 18, 20), spacing=(1.0, 1.2, 1.5), origin=(-5.0, -6.0, -9.0), direction=ROTATION.T.tolist()
    )
    ref = vm.warp(v, m, "pullback-linear", geometry=go).array
    src = da.from_array(v.array, chunks=(7, 5, 6))
    for chunks in [(5, 7, 3), (21, 18, 20), (4, 9, 11)]:
        w = vm.dask.warp(src, m, go, chunks=chunks, input_geometry=v.geometry)
        assert w.chunksize == tuple(min(c, s) for c, s in zip(chunks, go.shape))
        assert same_bits(w.compute(), ref), chunks


def test_dask_nearest_u16_and_background():
    da = pytest.importorskip("dask.array")
    v = blob((16, 15, 14), np.uint16)
    m = bent_lattice(v, amount=3.0)
    ref = vm.warp(v, m, "pullback-nearest", background=7.0).array
    w = vm.dask.warp(
        da.from_array(v.array, chunks=5), m, chunks=(6, 4, 9), input_geometry=v.geometry,
        method="pullback-nearest", background=7.0,
    )
    assert same_bits(w.compute(), ref)
    with pytest.raises(vm.InputError, match="pullback-linear"):
        vm.dask.warp(da.from_array(v.array), m, input_geometry=v.geometry, method="pullback-cubic")


def test_dask_ome_zarr_source_and_output(tmp_path):
    da = pytest.importorskip("dask.array")
    v = axis_aligned((22, 19, 18))
    m = bent_lattice(v)
    p = tmp_path / "in.ome.zarr"
    vm.dask.to_ome_zarr(da.from_array(v.array, chunks=(7, 6, 5)), v.geometry, p)
    back, g = vm.dask.from_ome_zarr(p)
    assert back.chunksize == (7, 6, 5) and g.spacing == v.spacing
    assert same_bits(back.compute(), v.array)
    ref = vm.warp(v, m, "pullback-linear").array
    w = vm.dask.warp(str(p), m, chunks=(6, 7, 5))
    # One task per output chunk, no other tasks.
    assert len(w.__dask_graph__()) == np.prod([len(c) for c in w.chunks])
    assert same_bits(w.compute(), ref)
    out = tmp_path / "out.ome.zarr"
    vm.dask.warp(str(p), m, chunks=(8, 8, 8), output=out, zarr_version=3)
    assert same_bits(vm.Volume.read(str(out)).array, ref)


def test_dask_on_a_local_cluster_with_two_worker_processes(tmp_path):
    pytest.importorskip("dask.array")
    distributed = pytest.importorskip("distributed")
    v = axis_aligned((18, 16, 14))
    m = bent_lattice(v)
    p = tmp_path / "in.ome.zarr"
    v.write(str(p))
    ref = vm.warp(v, m, "pullback-linear").array
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster, distributed.Client(cluster) as client:
        w = vm.dask.warp(str(p), m, chunks=(5, 6, 7))
        assert same_bits(client.compute(w).result(), ref)
        out = tmp_path / "out.ome.zarr"
        vm.dask.warp(str(p), m, chunks=(8, 8, 8), output=out)
    assert same_bits(vm.Volume.read(str(out)).array, ref)


def _two_worker_cluster(distributed):
    return distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    )


def test_dask_array_on_a_local_cluster_with_odd_chunks_and_rotated_grids():
    da = pytest.importorskip("dask.array")
    distributed = pytest.importorskip("distributed")
    v = blob((23, 19, 17))  # rotated input grid
    m = bent_lattice(v)
    go = vm.Geometry(
        (21, 18, 20), spacing=(1.0, 1.2, 1.5), origin=(-5.0, -6.0, -9.0), direction=ROTATION.T.tolist()
    )
    ref = vm.warp(v, m, "pullback-linear", geometry=go).array
    with _two_worker_cluster(distributed) as cluster, distributed.Client(cluster) as client:
        assert len(client.scheduler_info()["workers"]) == 2
        src = da.from_array(v.array, chunks=(7, 5, 6))
        w = vm.dask.warp(src, m, go, chunks=(5, 7, 3), input_geometry=v.geometry)
        with distributed.get_task_stream(client) as ts:
            got = client.compute(w).result()
        # The tasks ran in both worker processes.
        workers = {t["worker"] for t in ts.data}
        assert len(workers) == 2, workers
    assert same_bits(got, ref)


# ---- Push-forward on Dask ----------------------------------------------------------------


def padded_rotated_output():
    """An output grid rotated against the input's, larger than the input's image: its corner
    chunks receive nothing (they are the background)."""
    return vm.Geometry(
        (29, 24, 27), spacing=(1.1, 1.3, 1.6), origin=(-14.0, -16.0, -24.0),
        direction=ROTATION.T.tolist(),
    )


def test_dask_push_forward_is_bit_identical_on_odd_chunks_with_rotated_and_padded_grids():
    da = pytest.importorskip("dask.array")
    v = blob((23, 19, 17))  # rotated input grid
    m = bent_lattice(v, amount=2.5)
    go = padded_rotated_output()
    src = da.from_array(v.array, chunks=(7, 5, 6))
    for method, background in [("pushforward-antialiased", 3.5), ("pushforward-nearest", 0.0)]:
        ref = vm.warp(v, m, method, geometry=go, background=background).array
        plan = vm.dask.push_plan(m, v.geometry, go, ((5,) * 5 + (4,), (7,) * 3 + (3,), (9,) * 3))
        assert any(b is None for _, b, _ in plan), "some chunk must receive nothing"
        for chunks in [(5, 7, 9), (29, 24, 27), (4, 11, 3)]:
            w = vm.dask.warp(
                src, m, go, chunks=chunks, input_geometry=v.geometry, method=method,
                background=background,
            )
            assert w.dtype == ref.dtype
            assert same_bits(w.compute(scheduler="threads"), ref), (method, chunks)


def test_dask_push_forward_refuses_what_does_not_chunk():
    da = pytest.importorskip("dask.array")
    v = blob((8, 7, 6))
    m = bent_lattice(v)
    src = da.from_array(v.array, chunks=4)
    with pytest.raises(vm.InputError, match="holes stay 0"):
        vm.dask.warp(src, m, input_geometry=v.geometry, method="pushforward-nearest", background=1)
    with pytest.raises(vm.InputError, match="pushforward-antialiased"):
        vm.dask.warp(src, m, input_geometry=v.geometry, method="inverse-linear")
    with pytest.raises(vm.InputError, match="pull-back"):
        vm.dask.push_plan(m, v.geometry, v.geometry, ((4, 4), (4, 3), (6,)), "pullback-linear")


def test_dask_push_forward_of_an_ome_zarr_store_reads_boxes_and_writes_a_store(tmp_path):
    pytest.importorskip("dask.array")
    v = axis_aligned((22, 19, 18))
    m = bent_lattice(v, amount=2.5)
    p = tmp_path / "in.ome.zarr"
    v.write(str(p))
    ref = vm.warp(v, m, "pushforward-antialiased").array
    w = vm.dask.warp(str(p), m, chunks=(6, 7, 5), method="pushforward-antialiased")
    # One task per output chunk, no other tasks.
    assert len(w.__dask_graph__()) == np.prod([len(c) for c in w.chunks])
    assert same_bits(w.compute(scheduler="threads"), ref)
    out = tmp_path / "out.ome.zarr"
    vm.dask.warp(str(p), m, chunks=(8, 8, 8), output=out, method="pushforward-antialiased")
    assert same_bits(vm.Volume.read(str(out)).array, ref)


def test_dask_push_forward_on_a_local_cluster_with_two_worker_processes(tmp_path):
    da = pytest.importorskip("dask.array")
    distributed = pytest.importorskip("distributed")
    v = blob((23, 19, 17), np.uint16)  # rotated input grid
    m = bent_lattice(v, amount=2.5)
    go = padded_rotated_output()
    ref = vm.warp(v, m, "pushforward-antialiased", geometry=go, background=2.0).array
    a = axis_aligned((21, 18, 19))
    ma = bent_lattice(a, amount=2.5)
    p = tmp_path / "in.ome.zarr"
    a.write(str(p))
    ref_zarr = vm.warp(a, ma, "pushforward-antialiased").array
    with _two_worker_cluster(distributed) as cluster, distributed.Client(cluster) as client:
        assert len(client.scheduler_info()["workers"]) == 2
        src = da.from_array(v.array, chunks=(7, 5, 6))
        w = vm.dask.warp(
            src, m, go, chunks=(5, 7, 9), input_geometry=v.geometry,
            method="pushforward-antialiased", background=2.0,
        )
        with distributed.get_task_stream(client) as ts:
            got = client.compute(w).result()
        # The tasks ran in both worker processes.
        workers = {t["worker"] for t in ts.data}
        assert len(workers) == 2, workers
        got_zarr = client.compute(
            vm.dask.warp(str(p), ma, chunks=(5, 6, 7), method="pushforward-antialiased")
        ).result()
    assert same_bits(got, ref)
    assert same_bits(got_zarr, ref_zarr)


def test_dask_cluster_warp_of_a_store_written_by_ome_zarr_read_back_by_zarr(tmp_path):
    da = pytest.importorskip("dask.array")
    distributed = pytest.importorskip("distributed")
    zarr = pytest.importorskip("zarr")
    pytest.importorskip("ome_zarr")
    from ome_zarr.writer import write_image

    rng = np.random.default_rng(11)
    a = rng.integers(0, 4000, (19, 17, 13), dtype=np.uint16)
    q = tmp_path / "peer.ome.zarr"
    write_image(a, str(q), axes="zyx", scale={"z": 2.0, "y": 0.5, "x": 0.25})
    v = vm.Volume.read(str(q))
    assert same_bits(v.array, a)
    m = bent_lattice(v, amount=0.3)
    ref = vm.warp(v, m, "pullback-linear").array
    out = tmp_path / "warped.ome.zarr"
    with _two_worker_cluster(distributed) as cluster, distributed.Client(cluster):
        w = vm.dask.warp(str(q), m, chunks=(5, 6, 7))
        assert same_bits(w.compute(), ref)
        vm.dask.warp(str(q), m, chunks=(7, 5, 9), output=out, zarr_version=3)
    g = zarr.open_group(str(out), mode="r")
    ms = _multiscales(g, 3)
    assert same_bits(g[ms["datasets"][0]["path"]][...], ref)
    tr = {t["type"]: t for t in ms["datasets"][0]["coordinateTransformations"]}
    assert tr["scale"]["scale"] == [2.0, 0.5, 0.25]


# ---- peers: zarr and ome-zarr -------------------------------------------------------------


def _multiscales(group, version):
    attrs = dict(group.attrs)
    return (attrs["ome"] if version == 3 else attrs)["multiscales"][0]


@pytest.mark.parametrize("version", [2, 3])
def test_stores_written_here_read_in_zarr_with_same_values_and_scales(tmp_path, version):
    da = pytest.importorskip("dask.array")
    zarr = pytest.importorskip("zarr")
    if version == 3 and int(zarr.__version__.split(".")[0]) < 3:
        pytest.skip("Zarr v3 stores need zarr-python >= 3")
    v = axis_aligned((20, 17, 15), np.float32)
    p = tmp_path / "w.ome.zarr"
    vm.dask.to_ome_zarr(da.from_array(v.array, chunks=(8, 8, 8)), v.geometry, p, zarr_version=version)
    g = zarr.open_group(str(p), mode="r")
    ms = _multiscales(g, version)
    assert [a["name"] for a in ms["axes"]] == ["z", "y", "x"]
    ds = ms["datasets"][0]
    tr = {t["type"]: t for t in ds["coordinateTransformations"]}
    assert tr["scale"]["scale"] == list(v.spacing[::-1])
    assert tr["translation"]["translation"] == list(v.origin[::-1])
    assert same_bits(g["0"][...], v.array)
    # Level 1 is the 2×2×2 mean at twice the spacing.
    l1 = g[ms["datasets"][1]["path"]][...]
    assert l1.shape == (10, 9, 8)
    np.testing.assert_allclose(l1[0, 0, 0], v.array[:2, :2, :2].mean(), rtol=1e-6)


def test_stores_written_here_read_in_ome_zarr(tmp_path):
    pytest.importorskip("ome_zarr")
    from ome_zarr.io import parse_url
    from ome_zarr.reader import Reader

    v = axis_aligned((20, 17, 15))
    p = tmp_path / "o.ome.zarr"
    v.write(str(p))
    nodes = list(Reader(parse_url(str(p)))())
    image = nodes[0]
    assert same_bits(np.asarray(image.data[0]), v.array)
    ct = image.metadata["coordinateTransformations"][0]
    scale = [t for t in ct if t["type"] == "scale"][0]["scale"]
    assert scale == list(v.spacing[::-1])


def test_stores_written_by_zarr_and_ome_zarr_read_here(tmp_path):
    zarr = pytest.importorskip("zarr")
    if int(zarr.__version__.split(".")[0]) < 3:
        pytest.skip("this test uses the zarr-python 3 API")
    rng = np.random.default_rng(3)
    a = rng.integers(0, 4000, (13, 11, 9), dtype=np.uint16)
    # zarr-python's Zarr v2 with its default compressor, NGFF v0.4 attributes by hand.
    p = tmp_path / "z.ome.zarr"
    g = zarr.open_group(str(p), mode="w", zarr_format=2)
    arr = g.create_array("0", shape=a.shape, chunks=(5, 4, 3), dtype=a.dtype)
    arr[...] = a
    g.attrs["multiscales"] = [
        {
            "version": "0.4",
            "axes": [{"name": n, "type": "space", "unit": "micrometer"} for n in "zyx"],
            "datasets": [
                {
                    "path": "0",
                    "coordinateTransformations": [
                        {"type": "scale", "scale": [2.0, 0.5, 0.25]},
                        {"type": "translation", "translation": [1.0, 2.0, 3.0]},
                    ],
                }
            ],
        }
    ]
    v = vm.Volume.read(str(p))
    assert same_bits(v.array, a)
    assert v.spacing == (0.25, 0.5, 2.0) and v.origin == (3.0, 2.0, 1.0)
    # ome-zarr's own writer: its current format (v0.5 on Zarr v3), codecs and pyramid.
    pytest.importorskip("ome_zarr")
    from ome_zarr.writer import write_image

    q = tmp_path / "w.ome.zarr"
    write_image(a, str(q), axes="zyx", scale={"z": 2.0, "y": 0.5, "x": 0.25})
    w = vm.Volume.read(str(q))
    assert same_bits(w.array, a)
    assert w.spacing == (0.25, 0.5, 2.0)
