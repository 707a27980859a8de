"""The scene: commands, change reports, undo/redo, project files; drag as the CLI does it."""

import subprocess

import numpy as np
import pytest
from conftest import blob

import volmorph as vm


def warp_recipe(source, map_id, method="pushforward-antialiased"):
    return {
        "recipe": "warp",
        "source": source,
        "map": map_id,
        "method": method,
        "background": 0.0,
        "sampled_nodes": None,
        "swap_handles": False,
    }


def test_drag_undo_redo_and_change_reports(tmp_path):
    v = blob()
    s = vm.Scene()
    vid = s.add_volume("ct", v)
    lid = s.add_map("lattice", vm.Map.lattice(v.geometry, (6, 6, 6)))
    added = s.add_derived("warped", warp_recipe(vid, lid))
    wid = added["added"][0]
    assert added["errors"] == []
    before = s.volume(wid).array.copy()
    centre = np.array([v.geometry.index_to_physical(np.array([[4.0, 5.0, 6.0]]))[0]])
    change = s.drag_points(lid, centre, centre + [1.0, 0.5, 0.0], radius=6.0)
    assert change["drag"]["drags"] == 1 and change["drag"]["max_residual"] < 1e-9
    assert lid in change["modified"] and wid in change["modified"]
    d = [x for x in change["dirty"] if x["object"] == wid][0]
    (i0, j0, k0), (i1, j1, k1) = d["voxels"]
    after = s.volume(wid).array.copy()
    diff = np.argwhere(after != before)
    assert len(diff) > 0
    # Every changed voxel is inside the reported dirty box.
    assert (diff[:, 2] >= i0).all() and (diff[:, 2] < i1).all()
    assert (diff[:, 1] >= j0).all() and (diff[:, 1] < j1).all()
    assert (diff[:, 0] >= k0).all() and (diff[:, 0] < k1).all()
    # The moved lattice maps the grabbed point to the target.
    np.testing.assert_allclose(s.map(lid).map(centre), centre + [1.0, 0.5, 0.0], atol=1e-9)
    assert s.undo_depth == 4
    s.undo()
    np.testing.assert_array_equal(s.volume(wid).array, before)
    s.redo()
    np.testing.assert_array_equal(s.volume(wid).array, after)
    # Save and load: the same objects and data.
    path = tmp_path / "p.vmproj"
    s.save(path)
    t = vm.Scene.load(path)
    assert [o[1:] for o in t.objects()] == [o[1:] for o in s.objects()]
    np.testing.assert_array_equal(t.volume(t.find("warped")).array, after)


def test_refused_commands_raise_scene_errors_and_change_nothing():
    s = vm.Scene()
    vid = s.add_volume("ct", blob())
    lid = s.add_map("m", vm.Map.identity())
    s.add_derived("w", warp_recipe(vid, lid, "pullback-linear"))
    depth = s.undo_depth
    with pytest.raises(vm.SceneError):
        s.remove(vid)  # used by the warp
    with pytest.raises(vm.SceneError):
        s.volume(999)
    with pytest.raises(vm.SceneError):
        s.drag_points(lid, np.zeros((1, 3)), np.ones((1, 3)))  # not a lattice
    with pytest.raises(vm.InputError, match="recipe"):
        s.add_derived("bad", {"recipe": "warp", "source": vid})
    assert s.undo_depth == depth
    assert s.undo() is not None and s.undo_depth == depth - 1


def test_isosurface_and_jacobian_recipes():
    s = vm.Scene()
    v = blob()
    vid = s.add_volume("ct", v)
    iso = s.add_derived(
        "surface",
        {"recipe": "isosurface", "volume": vid, "level": 50.0, "inside_below": False,
         "method": "marching-cubes"},
    )["added"][0]
    sv, sf = s.mesh(iso)
    ov, of = vm.isosurface(v, 50.0)
    np.testing.assert_array_equal(sv, ov)
    np.testing.assert_array_equal(sf, of)


def test_drag_equals_the_cli(tmp_path, cli):
    v = blob()
    v.write(tmp_path / "in.nii.gz")
    src = v.geometry.index_to_physical(np.array([[4.0, 5.0, 6.0]]))[0]
    dst = src + [1.0, -0.5, 0.25]
    fmt = lambda p: ",".join(repr(float(c)) for c in p)  # noqa: E731
    subprocess.run(
        [cli, "drag", str(tmp_path / "in.nii.gz"), "--from", fmt(src), "--to", fmt(dst),
         "--counts", "6,6,6", "--radius", "6", "-o", str(tmp_path / "out.nii.gz"),
         "--lattice-out", str(tmp_path / "l.json")],
        check=True, capture_output=True,
    )
    ours, lat, report = vm.drag(vm.Volume.read(tmp_path / "in.nii.gz"), [src], [dst],
                                counts=(6, 6, 6), radius=6.0)
    np.testing.assert_array_equal(ours.array, vm.Volume.read(tmp_path / "out.nii.gz").array)
    p = np.random.default_rng(0).uniform(-3, 3, size=(10, 3))
    np.testing.assert_array_equal(lat.map(p), vm.Map.load(tmp_path / "l.json").map(p))
    assert report["drag"]["moved"] > 0


def test_metamorphosis_recipe_follows_equation_13_and_set_recipe():
    s = vm.Scene()
    spacing, origin = (0.15, 0.15, 0.15), (-1.2, -1.05, -0.9)
    grid = s.add_volume("grid", vm.Volume(np.zeros((13, 15, 17), np.float32), spacing=spacing, origin=origin))
    f = s.add_frep("ball", "b(x[3], a[1]) { b = a[1]*a[1] - x[1]*x[1] - x[2]*x[2] - x[3]*x[3]; }", {1: 0.8})
    g = s.add_frep("slab", "c(x[3]) { c = 0.3 - x[3]*x[3]; }")

    def recipe(t):
        return {"recipe": "frep-morph", "from": f, "to": g, "t": t, "schedule": "linear", "grid": grid}

    m = s.add_derived("morph", recipe(0.25))["added"][0]
    z, y, x = np.meshgrid(*(o + h * np.arange(n) for o, h, n in zip(origin[::-1], spacing[::-1], (13, 15, 17))),
                          indexing="ij")
    fv, gv = 0.64 - x * x - y * y - z * z, 0.3 - z * z
    np.testing.assert_allclose(np.asarray(s.volume(m)), 0.75 * fv + 0.25 * gv, atol=1e-6)
    s.set_recipe(m, recipe(0.75))
    np.testing.assert_allclose(np.asarray(s.volume(m)), 0.25 * fv + 0.75 * gv, atol=1e-6)
    s.undo()
    np.testing.assert_allclose(np.asarray(s.volume(m)), 0.75 * fv + 0.25 * gv, atol=1e-6)
    with pytest.raises(vm.SceneError, match=r"\[0, 1\]"):
        s.set_recipe(m, recipe(2.0))
