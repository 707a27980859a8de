"""Isosurfaces, F-rep models, mesh FFD (vertex and accurate to STEP), NURBS volumes."""

import numpy as np
import pytest
from conftest import bent_lattice

import volmorph as vm

SPHERE = """
ball(x[3], a[1])
{
  array c[3];
  c = [0, 0, 0];
  ball = hfSphere(x, c, a[1]);
}
"""


def sphere_volume(n=24, r=0.7):
    g = vm.Geometry((n, n, n), spacing=(2 / (n - 1),) * 3, origin=(-1.0, -1.0, -1.0))
    return vm.Frep(SPHERE, {1: r}).sample(g)


def euler(faces):
    edges = {tuple(sorted(e)) for f in faces for e in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0]))}
    vertices = np.unique(faces)
    return len(vertices) - len(edges) + len(faces)


@pytest.mark.parametrize("method", ["marching-cubes", "dual-contouring"])
def test_isosurface_of_a_sphere_is_a_closed_sphere(method):
    v = sphere_volume()
    verts, faces = vm.isosurface(v, 0.0, method=method)
    assert verts.dtype == np.float64 and verts.shape[1] == 3
    assert faces.dtype == np.uint32 and faces.shape[1] == 3
    assert faces.max() < len(verts)
    r = np.linalg.norm(verts, axis=1)
    np.testing.assert_allclose(r, 0.7, atol=0.03)
    assert euler(faces) == 2
    # Outward orientation: the signed volume is positive, about 4/3 π r³.
    a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    vol = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6
    assert vol == pytest.approx(4 / 3 * np.pi * 0.7**3, rel=0.05)


def test_frep_evaluates_the_hyperfun_formula():
    s = vm.Frep(SPHERE, {1: 0.5})
    p = np.random.default_rng(1).uniform(-1, 1, size=(100, 3))
    np.testing.assert_allclose(s.evaluate(p), 0.25 - (p**2).sum(axis=1), atol=1e-12)
    g = vm.Geometry((5, 6, 7), spacing=(0.3, 0.3, 0.3), origin=(-1.0, -1.0, -1.0))
    sampled = s.sample(g)
    assert sampled.dtype == "float32" and sampled.shape == (5, 6, 7)
    idx = np.argwhere(np.ones(sampled.shape))[:, ::-1].astype(float)
    pts = g.index_to_physical(idx)
    np.testing.assert_allclose(sampled.array.ravel(), s.evaluate(pts), atol=1e-6)
    verts, faces = s.mesh(vm.Geometry((20, 20, 20), spacing=(0.1,) * 3, origin=(-1.0,) * 3))
    np.testing.assert_allclose(np.linalg.norm(verts, axis=1), 0.5, atol=0.02)


OFF_CENTRE = """
ball(x[3], a[1])
{
  array c[3];
  c = [3, -2, 0.5];
  ball = hfSphere(x, c, a[1]);
}
"""


@pytest.mark.parametrize("source,centre", [(SPHERE, (0, 0, 0)), (OFF_CENTRE, (3, -2, 0.5))])
def test_frep_bounds_frame_the_solid_as_the_command_line_does(source, centre):
    s = vm.Frep(source, {1: 0.5})
    lo, hi = (np.array(b) for b in s.bounds())
    c = np.array(centre, dtype=float)
    # The solid's box [c - 0.5, c + 0.5] with a margin of 5 % of its side (0.05), which
    # interval arithmetic may widen a little but never narrow.
    assert np.all(lo <= c - 0.55 + 1e-9) and np.all(lo >= c - 0.65)
    assert np.all(hi >= c + 0.55 - 1e-9) and np.all(hi <= c + 0.65)
    g = s.grid((21, 22, 23))
    assert g.shape == (21, 22, 23) and g.direction == [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
    np.testing.assert_allclose(g.origin, lo)
    corner = g.index_to_physical(np.array([[22.0, 21.0, 20.0]]))[0]
    np.testing.assert_allclose(corner, hi, atol=1e-12)
    # The framed grid holds the whole solid: inside points, and none on the box's faces.
    f = s.sample(g).array
    assert (f > 0).any()
    faces = [f[0], f[-1], f[:, 0], f[:, -1], f[:, :, 0], f[:, :, -1]]
    assert all((face < 0).all() for face in faces)


def test_frep_bounds_of_a_model_with_no_solid_warn_and_fall_back():
    s = vm.Frep("none(x[3]) { none = -1; }")
    with pytest.warns(UserWarning, match="no solid"):
        lo, hi = s.bounds()
    assert lo == (-1.6, -1.6, -1.6) and hi == (1.6, 1.6, 1.6)
    with pytest.raises(vm.InputError, match="at least 2"):
        with pytest.warns(UserWarning):
            s.grid((1, 5, 5))


def test_frep_errors_are_model_errors(tmp_path):
    with pytest.raises(vm.ModelError):
        vm.Frep("ball(x[3]) { ball = hfSphere(x, ; }")
    with pytest.raises(vm.InputError, match="a1 must be finite"):
        vm.Frep(SPHERE, {1: float("nan")})
    path = tmp_path / "m.hf"
    path.write_text(SPHERE)
    assert vm.Frep.load(path, {1: 1.0}).evaluate(np.zeros((1, 3)))[0] == 1.0
    with pytest.raises(vm.FileError, match="missing.hf"):
        vm.Frep.load(tmp_path / "missing.hf")


def cube_mesh(h=0.5):
    v = np.array([[x, y, z] for z in (-h, h) for y in (-h, h) for x in (-h, h)], dtype=float)
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    faces = np.array([t for q in quads for t in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))])
    return v, faces


def test_vertex_ffd_moves_vertices_by_the_map():
    v, f = cube_mesh()
    g = vm.Geometry((9, 9, 9), spacing=(0.25,) * 3, origin=(-1.0,) * 3)
    lat = bent_lattice(vm.Volume(np.zeros((9, 9, 9), np.float32), geometry=g), amount=0.2)
    out_v, out_f = vm.ffd(v, f, lat, mode="vertex")
    np.testing.assert_allclose(out_v, lat.map(v), atol=1e-12)
    np.testing.assert_array_equal(out_f, f)
    with pytest.raises(vm.InputError, match="accurate"):
        vm.ffd(v, f, lat, mode="vertex", step="x.step")
    with pytest.raises(vm.InputError, match="lattice"):
        vm.ffd(v, f, vm.Map.identity())


def test_accurate_ffd_writes_step_and_a_tessellation_on_the_exact_image(tmp_path):
    v, f = cube_mesh()
    g = vm.Geometry((9, 9, 9), spacing=(0.25,) * 3, origin=(-1.0,) * 3)
    lat = bent_lattice(vm.Volume(np.zeros((9, 9, 9), np.float32), geometry=g), amount=0.15)
    step = tmp_path / "cube.step"
    tv, tf = vm.ffd(v, f, lat, mode="accurate", step=step, chordal=1e-3)
    assert step.read_text().startswith("ISO-10303-21;")
    assert len(tf) > len(f)
    # Every tessellation vertex lies on the deformed surface: it is the image of a point of
    # the undeformed cube's surface (found through the inverse map).
    pre = lat.inverse().map(tv)
    assert np.abs(np.abs(pre).max(axis=1) - 0.5).max() < 1e-4


def test_nurbs_fit_evaluate_slice_and_files(tmp_path):
    v = sphere_volume(n=8)
    model = vm.Nurbs.fit(v, order=3, counts=(6, 6, 6), name="density")
    assert model.attributes == ["density"]
    u = np.random.default_rng(2).uniform(0.1, 0.9, size=(20, 3))
    e = model.evaluate(u)
    assert e["points"].shape == (20, 3) and e["density"].shape == (20,)
    path = tmp_path / "m.json"
    model.save(path)
    again = vm.Nurbs.load(path).evaluate(u)
    np.testing.assert_array_equal(again["points"], e["points"])
    np.testing.assert_array_equal(again["density"], e["density"])
    s = model.slice((0.0, 0.0, 1.0, 0.0), attribute="density")
    assert s["attribute"] == "density"
    np.testing.assert_allclose(s["vertices"][:, 2], 0.0, atol=1e-6)
    assert len(s["values"]) == len(s["vertices"])
    iso = model.isosurface("density", 0.0)
    assert len(iso["faces"]) > 0
    with pytest.raises(vm.FileError, match="missing.json"):
        vm.Nurbs.load(tmp_path / "missing.json")
