"""Maps (every kind through one class), warps against the CLI bit for bit, Jacobians."""

import subprocess

import numpy as np
import pytest
from conftest import blob

import volmorph as vm

RNG = np.random.default_rng(11)


def test_affine_map_and_jacobian_are_exact():
    a = np.array([[1.1, 0.2, 0.0], [0.0, 0.9, 0.3], [0.1, 0.0, 1.2]])
    t = np.array([1.0, -2.0, 0.5])
    m = vm.Map.affine(a.tolist(), tuple(t))
    p = RNG.normal(size=(50, 3))
    np.testing.assert_allclose(m.map(p), p @ a.T + t, rtol=0, atol=1e-12)
    j = m.jacobian(p)
    assert j.shape == (50, 3, 3)
    np.testing.assert_allclose(j, np.broadcast_to(a, (50, 3, 3)), atol=1e-8)
    inv = m.inverse()
    np.testing.assert_allclose(inv.map(m.map(p)), p, atol=1e-12)
    assert m.kind == "affine"


def test_lattice_inverse_and_composition(volume, lattice):
    p = volume.geometry.index_to_physical(RNG.uniform(2, 7, size=(40, 3)))
    y = lattice.map(p)
    assert np.abs(y - p).max() > 0.05  # the lattice really moves points
    back = lattice.inverse().map(y)
    np.testing.assert_allclose(back, p, atol=1e-6)
    shift = vm.Map.affine(np.eye(3).tolist(), (1.0, 2.0, 3.0))
    both = lattice.then(shift)
    np.testing.assert_allclose(both.map(p), y + [1.0, 2.0, 3.0], atol=1e-12)
    assert both.kind == "compose"
    # The lattice's Jacobian agrees with central differences of map().
    h = 1e-5
    j = lattice.jacobian(p[:5])
    for c in range(3):
        e = np.zeros(3)
        e[c] = h
        fd = (lattice.map(p[:5] + e) - lattice.map(p[:5] - e)) / (2 * h)
        np.testing.assert_allclose(j[:, :, c], fd, atol=1e-6)


@pytest.mark.parametrize("method", ["tps", "affine", "rigid", "similarity", "wendland"])
def test_handle_maps(method):
    src = RNG.uniform(-5, 5, size=(12, 3))
    dst = src + RNG.normal(0, 0.3, size=src.shape)
    m = vm.Map.from_handles(src, dst, method=method)
    out = m.map(src)
    if method in ("tps", "wendland"):
        np.testing.assert_allclose(out, dst, atol=1e-6)  # interpolating splines
    else:
        assert np.abs(out - dst).max() < np.abs(src - dst).max() + 1.0
    back = vm.Map.from_handles(src, dst, method=method, backward=True)
    if method == "tps":
        np.testing.assert_allclose(back.map(dst), src, atol=1e-6)


def _tps_reference(src, dst, query, kernel):
    """The interpolating thin-plate spline solved directly: [K P; Pᵀ 0] [w; a] = [dst; 0]."""
    green = {
        "r": lambda r: r,
        "r2logr": lambda r: np.where(r > 0, r * r * np.log(np.where(r > 0, r, 1)), 0.0),
    }[kernel]
    n = len(src)
    k = green(np.linalg.norm(src[:, None] - src[None], axis=-1))
    p = np.hstack([np.ones((n, 1)), src])
    a = np.zeros((n + 4, n + 4))
    a[:n, :n], a[:n, n:], a[n:, :n] = k, p, p.T
    coef = np.linalg.solve(a, np.vstack([dst, np.zeros((4, 3))]))
    kq = green(np.linalg.norm(query[:, None] - src[None], axis=-1))
    return kq @ coef[:n] + np.hstack([np.ones((len(query), 1)), query]) @ coef[n:]


@pytest.mark.parametrize("kernel", ["r", "r2logr"])
def test_thin_plate_kernels_match_the_direct_solve(kernel):
    src = RNG.uniform(-5, 5, size=(15, 3))
    dst = src + RNG.normal(0, 0.4, size=src.shape)
    query = RNG.uniform(-6, 6, size=(40, 3))
    m = vm.Map.from_handles(src, dst, method="tps", kernel=kernel)
    np.testing.assert_allclose(m.map(src), dst, atol=1e-8)
    np.testing.assert_allclose(m.map(query), _tps_reference(src, dst, query, kernel), atol=1e-8)
    if kernel == "r":
        default = vm.Map.from_handles(src, dst, method="tps")
        np.testing.assert_array_equal(default.map(query), m.map(query))
    else:
        other = vm.Map.from_handles(src, dst, method="tps", kernel="r")
        assert np.abs(other.map(query) - m.map(query)).max() > 1e-3


def test_kernel_and_support_are_checked():
    src = RNG.uniform(-5, 5, size=(15, 3))
    dst = src + RNG.normal(0, 0.3, size=src.shape)
    with pytest.raises(vm.InputError, match="only the tps method"):
        vm.Map.from_handles(src, dst, method="rigid", kernel="r2logr")
    with pytest.raises(vm.InputError, match="r2logr"):
        vm.Map.from_handles(src, dst, method="tps", kernel="gaussian")
    with pytest.raises(vm.InputError, match="only the wendland method"):
        vm.Map.from_handles(src, dst, method="tps", support=2.0)
    with pytest.raises(vm.InputError, match="> 0"):
        vm.Map.from_handles(src, dst, method="wendland", support=-1.0)
    # A support radius changes the Wendland map away from the handles, not at them.
    narrow = vm.Map.from_handles(src, dst, method="wendland", support=3.0)
    wide = vm.Map.from_handles(src, dst, method="wendland", support=30.0)
    np.testing.assert_allclose(narrow.map(src), dst, atol=1e-6)
    np.testing.assert_allclose(wide.map(src), dst, atol=1e-6)
    # Beyond the support of every handle the map is the least-squares affine trend.
    far = np.array([[40.0, 40.0, 40.0], [-30.0, 35.0, 0.0]])
    h = np.hstack([src, np.ones((len(src), 1))])
    trend = np.linalg.lstsq(h, dst, rcond=None)[0]
    np.testing.assert_allclose(narrow.map(far), np.hstack([far, np.ones((2, 1))]) @ trend, atol=1e-8)
    mid = src[:1] + 2.0
    assert np.abs(narrow.map(mid) - wide.map(mid)).max() > 1e-4


@pytest.mark.parametrize("ext", [".json", ".tfm"])
def test_map_files_round_trip(tmp_path, lattice, ext):
    path = tmp_path / f"m{ext}"
    lattice.save(path)
    loaded = vm.Map.load(path)
    p = RNG.uniform(-3, 3, size=(30, 3))
    np.testing.assert_allclose(loaded.map(p), lattice.map(p), rtol=0, atol=1e-12)
    again = vm.Map.from_json(lattice.to_json())
    np.testing.assert_array_equal(again.map(p), lattice.map(p))


def test_nan_in_maps_is_refused(lattice):
    with pytest.raises(vm.InputError, match="finite"):
        vm.Map.affine([[1, 0, 0], [0, np.nan, 0], [0, 0, 1]], (0, 0, 0))
    with pytest.raises(vm.InputError, match="point 1 is not finite"):
        lattice.map(np.array([[0.0, 0.0, 0.0], [np.nan, 0.0, 0.0]]))
    src = RNG.uniform(size=(5, 3))
    bad = src.copy()
    bad[2, 1] = np.nan
    with pytest.raises(vm.InputError, match="not finite"):
        vm.Map.from_handles(src, bad)
    cp = lattice.control_points.copy()
    cp[2, 2, 2, 0] = np.inf
    with pytest.raises(vm.VolmorphError):
        lattice.with_control_points(cp)
    text = lattice.to_json().replace('"control_points"', '"control_points_"', 1)
    with pytest.raises(vm.MapError):
        vm.Map.from_json(text)


def test_wrong_point_shapes_and_names():
    m = vm.Map.identity()
    with pytest.raises(vm.InputError, match="N×3"):
        m.map(np.zeros((4, 2)))
    with pytest.raises(vm.InputError, match="unknown handle method"):
        vm.Map.from_handles(np.zeros((3, 3)), np.zeros((3, 3)), method="spline")
    with pytest.raises(vm.InputError, match="unknown warp method"):
        vm.warp(blob(), m, "pullback-quintic")
    with pytest.raises(vm.FileError, match="cannot read the map"):
        vm.Map.load("/nonexistent/map.json")


METHODS = [
    "pullback-nearest",
    "pullback-linear",
    "pullback-cubic",
    "pushforward-nearest",
    "pushforward-antialiased",
    "inverse-linear",
]


@pytest.mark.parametrize("method", METHODS)
def test_warp_equals_the_cli_bit_for_bit(tmp_path, cli, volume, lattice, method):
    src = tmp_path / "in.nii.gz"
    mp = tmp_path / "lattice.json"
    out = tmp_path / "out.nii.gz"
    volume.write(src)
    lattice.save(mp)
    subprocess.run(
        [cli, "warp", str(src), "--map", str(mp), "-o", str(out), "--method", method],
        check=True,
    )
    theirs = vm.Volume.read(out)
    # Read back through the file, as the CLI did (the NIfTI round trip is exact for f32).
    ours = vm.warp(vm.Volume.read(src), vm.Map.load(mp), method)
    assert ours.dtype == theirs.dtype == "float32"
    np.testing.assert_array_equal(ours.array, theirs.array)
    assert np.abs(ours.array - volume.array).max() > 1.0  # the warp did something


def test_warp_onto_another_grid_and_inverse_mask(volume, lattice):
    g = vm.Geometry((7, 8, 9), spacing=(2.0, 2.0, 2.0), origin=volume.origin,
                    direction=volume.direction)
    w = vm.warp(volume, lattice, "pullback-linear", geometry=g, background=-1.0)
    assert w.shape == (7, 8, 9)
    assert w.spacing == (2.0, 2.0, 2.0)
    assert (w.array == -1.0).any()  # outside the input
    v, mask = vm.warp(volume, lattice, "inverse-linear", mask=True)
    assert mask.dtype == "uint8" and mask.shape == volume.shape
    with pytest.raises(vm.InputError, match="inverse"):
        vm.warp(volume, lattice, "pullback-linear", mask=True)


def test_jacobian_map_of_an_affine_map_is_its_determinant(volume):
    a = np.array([[1.2, 0.1, 0.0], [0.0, 0.8, 0.0], [0.0, 0.2, 1.5]])
    det = vm.jacobian_map(vm.Map.affine(a.tolist(), (0, 0, 0)), volume.geometry)
    assert det.dtype == "float32" and det.shape == volume.shape
    np.testing.assert_allclose(det.array, np.linalg.det(a), rtol=1e-5)


def test_jacobian_map_equals_the_cli(tmp_path, cli, volume, lattice):
    volume.write(tmp_path / "g.nii.gz")
    lattice.save(tmp_path / "l.json")
    subprocess.run(
        [cli, "jacobian", "--map", str(tmp_path / "l.json"), "--grid",
         str(tmp_path / "g.nii.gz"), "-o", str(tmp_path / "j.nii.gz")],
        check=True,
    )
    theirs = vm.Volume.read(tmp_path / "j.nii.gz")
    ours = vm.jacobian_map(vm.Map.load(tmp_path / "l.json"),
                           vm.Volume.read(tmp_path / "g.nii.gz").geometry)
    np.testing.assert_array_equal(ours.array, theirs.array)


def test_the_gil_is_released_during_a_warp(volume, lattice):
    # Four warps on four threads finish, each equal to the warp done alone (no deadlock,
    # no shared state).
    import threading

    alone = vm.warp(volume, lattice, "pullback-cubic").array
    results = [None] * 4

    def run(i):
        results[i] = vm.warp(volume, lattice, "pullback-cubic").array

    threads = [threading.Thread(target=run, args=(i,)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for r in results:
        np.testing.assert_array_equal(r, alone)


def test_timed_warp_returns_the_same_volume_and_the_rust_time(volume, lattice):
    from volmorph._volmorph import _warp_timed

    w, seconds = _warp_timed(volume, lattice, "pullback-cubic")
    np.testing.assert_array_equal(w.array, vm.warp(volume, lattice, "pullback-cubic").array)
    assert 0 < seconds < 60
