#!/usr/bin/env python3
"""Compare `volmorph sculpt` with manifold3d's exact mesh Booleans.

For every base mesh (the Stanford bunny and the Stanford dragon at two resolutions) and every
tool (a sphere, a rotated box and a scaled, rotated bunny placed half-way into the surface)
it runs `volmorph sculpt --op subtract` and `--op add` on a grid of N points (default 256)
and the same Boolean with manifold3d, and checks:

* the volume of the result is within 0.5 % of manifold3d's;
* the symmetric Hausdorff distance (trimesh's exact point-to-surface distances, from every
  vertex and 20 000 surface samples of each mesh) is at most one grid spacing, once
  connected pieces that hold no grid point are no longer measured from (they still count as
  targets): such specks — the exact Boolean sometimes leaves one of the base behind — cannot
  be represented on the grid at all. The raw distance and the specks are printed too;
* trimesh reports the result watertight with consistent winding, and manifold3d accepts it
  as a manifold.

It prints an accuracy table and a speed table (our edit steps beside manifold3d's Boolean,
both on this machine), and exits 1 if a check fails.

The dragon meshes have edges shared by four faces (touching sheets); both tools are given
manifold3d's manifold version of them. The full-resolution dragon is skipped: manifold3d
cannot make it a manifold (it returns an empty mesh).

Skips cleanly (exit 0 with a message) without numpy, trimesh (with rtree for distances) or
manifold3d, or without the data folder.

Run from the repository root:
    python3 scripts/sculpt_peer_check.py [--data ../shared/data] [--grid 256] [--quick]
"""
import argparse
import gzip
import io
import json
import os
import re
import subprocess
import sys
import tempfile
import time

try:
    import numpy as np
    import trimesh
    import manifold3d as m3
    import rtree  # noqa: F401  (trimesh's exact closest-point queries need it)
except ImportError as e:  # pragma: no cover
    print(f"SKIP: {e.name} not installed (pip install numpy trimesh rtree manifold3d)")
    sys.exit(0)

VOLUME_TOL = 0.005  # 0.5 % (the target)
SAMPLES = 20_000


def find_data(arg):
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    candidates = [arg] if arg else [
        os.path.join(root, "..", "shared", "data"),
        os.path.join(root, "..", "..", "shared", "data"),
    ]
    for c in candidates:
        if c and os.path.isdir(os.path.join(c, "meshes")):
            return os.path.abspath(c)
    return None


def load(path):
    if path.endswith(".gz"):
        with gzip.open(path) as f:
            data = f.read()
        kind = path[:-3].rsplit(".", 1)[1]
        return trimesh.load(io.BytesIO(data), file_type=kind, process=False)
    return trimesh.load(path, process=False)


def to_manifold(mesh):
    return m3.Manifold(m3.Mesh(
        vert_properties=np.asarray(mesh.vertices, np.float32),
        tri_verts=np.asarray(mesh.faces, np.uint32)))


def from_manifold(man):
    out = man.to_mesh()
    return trimesh.Trimesh(np.asarray(out.vert_properties[:, :3], np.float64),
                           np.asarray(out.tri_verts), process=False)


def place(tool, size, centre, axis, degrees):
    """`tool` scaled to extent `size`, rotated about `axis`, centred at `centre`."""
    t = tool.copy()
    t.apply_translation(-t.bounds.mean(axis=0))
    t.apply_scale(size / t.extents.max())
    t.apply_transform(trimesh.transformations.rotation_matrix(np.radians(degrees), axis))
    t.apply_translation(centre)
    return t


def one_sided(a, b):
    pts = np.vstack([a.vertices, a.sample(SAMPLES, seed=7)])
    _, dist, _ = trimesh.proximity.closest_point(b, pts)
    return float(dist.max())


def hausdorff(a, b):
    return max(one_sided(a, b), one_sided(b, a))


def without_debris(mesh, origin, spacing):
    """`mesh` without its specks: connected pieces at most three cells across that hold no
    point of the grid (`origin`, `spacing`); and the largest extent of each speck (in
    spacings)."""
    parts = mesh.split(only_watertight=False)
    keep, debris = [], []
    for p in parts:
        # Only specks can miss every grid point; anything larger is a real feature.
        if p.extents.max() >= 3 * spacing:
            keep.append(p)
            continue
        lo = np.ceil((p.bounds[0] - origin) / spacing)
        hi = np.floor((p.bounds[1] - origin) / spacing)
        holds = False
        if np.all(hi >= lo) and p.volume > 0:
            axes = [np.arange(lo[k], hi[k] + 1) for k in range(3)]
            grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
            holds = bool(p.contains(origin + grid * spacing).any())
        if holds or p.volume <= 0:
            keep.append(p)
        else:
            debris.append(round(float(p.extents.max() / spacing), 2))
    if not debris:
        return mesh, debris
    return trimesh.util.concatenate(keep), debris


def parse_timings(stdout):
    t = {}
    for line in stdout.splitlines():
        m = re.match(r"^(.+?)\s{2,}([0-9.]+) ms$", line.strip())
        if m:
            t[m.group(1).strip()] = float(m.group(2))
    counts = re.search(r"triangles kept (\d+), removed (\d+), added (\d+)", stdout)
    grid = re.search(r"spacing ([0-9.eE+-]+), origin ([0-9.eE+-]+),([0-9.eE+-]+),([0-9.eE+-]+)",
                     stdout)
    spacing = float(grid.group(1))
    origin = np.array([float(grid.group(k)) for k in (2, 3, 4)])
    return t, counts.groups() if counts else None, spacing, origin


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data")
    ap.add_argument("--grid", type=int, default=256)
    ap.add_argument("--volmorph", help="volmorph binary (default: build the release one)")
    ap.add_argument("--quick", action="store_true", help="bunny and the small dragon only")
    ap.add_argument("--json", help="write the results here")
    a = ap.parse_args()
    data = find_data(a.data)
    if data is None:
        print("SKIP: data folder with meshes/ not found (pass --data)")
        return 0
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    exe = a.volmorph
    if exe is None:
        subprocess.run(["cargo", "build", "-q", "--release", "-p", "volmorph-cli"], cwd=root,
                       check=True)
        target = os.environ.get("CARGO_TARGET_DIR", os.path.join(root, "target"))
        exe = os.path.join(target, "release", "volmorph")

    bunny = load(os.path.join(data, "meshes", "bunny.obj"))
    bases = [("bunny", bunny)]
    dragons = ["dragon_vrip_res3.ply.gz"] if a.quick else [
        "dragon_vrip_res3.ply.gz", "dragon_vrip_res2.ply.gz"]
    for name in dragons:
        path = os.path.join(data, "meshes", name)
        if os.path.exists(path):
            label = "dragon " + ("48k" if "res3" in name else "200k")
            bases.append((label, from_manifold(to_manifold(load(path)))))
    if not a.quick and os.path.exists(os.path.join(data, "meshes", "dragon_vrip.ply.gz")):
        print("note: the full-resolution dragon is skipped: manifold3d cannot make it a "
              "manifold (it returns an empty mesh)")

    results = []
    failed = False
    with tempfile.TemporaryDirectory() as tmp:
        for bname, base in bases:
            ext = base.extents.max()
            # A point on the surface far out along a fixed direction, the tool half in it.
            d = np.array([0.6, 0.7, 0.38])
            centre = base.vertices[np.argmax(base.vertices @ d)]
            size = 0.3 * ext
            tools = [
                ("sphere", place(trimesh.creation.icosphere(subdivisions=4), size, centre,
                                 [0, 0, 1], 0)),
                ("box", place(trimesh.creation.box(extents=[1.0, 0.7, 0.5]), size, centre,
                              [1, 2, 3], 37)),
                ("bunny", place(bunny, size, centre, [2, -1, 1], 71)),
            ]
            base_path = os.path.join(tmp, "base.ply")
            base.export(base_path)
            man_base = to_manifold(base)
            for tname, tool in tools:
                tool_path = os.path.join(tmp, "tool.ply")
                tool.export(tool_path)
                man_tool = to_manifold(tool)
                for op in ["subtract", "add"]:
                    out_path = os.path.join(tmp, "out.ply")
                    run = subprocess.run(
                        [exe, "sculpt", base_path, "--tool", tool_path, "--op", op,
                         "--grid", str(a.grid), "-o", out_path],
                        capture_output=True, text=True)
                    if run.returncode != 0:
                        print(f"FAIL {bname} {op} {tname}: volmorph: {run.stderr.strip()}")
                        failed = True
                        continue
                    times, counts, spacing, origin = parse_timings(run.stdout)
                    ours = trimesh.load(out_path, process=False)
                    t0 = time.perf_counter()
                    ref_man = (man_base - man_tool) if op == "subtract" else (man_base + man_tool)
                    ref_out = ref_man.to_mesh()
                    t_ref = time.perf_counter() - t0
                    ref = trimesh.Trimesh(np.asarray(ref_out.vert_properties[:, :3], np.float64),
                                          np.asarray(ref_out.tri_verts), process=False)
                    vol_err = abs(ours.volume / ref.volume - 1.0)
                    hd_raw = hausdorff(ours, ref)
                    ours_c, debris_ours = without_debris(ours, origin, spacing)
                    ref_c, debris_ref = without_debris(ref, origin, spacing)
                    # Debris only stops being a source of distances; it stays a target.
                    hd = hd_raw if not (debris_ours or debris_ref) else max(
                        one_sided(ours_c, ref), one_sided(ref_c, ours))
                    watertight = bool(ours.is_watertight and ours.is_winding_consistent)
                    manifold_ok = to_manifold(ours).status() == m3.Error.NoError
                    edit_ms = sum(times.get(k, 0.0) for k in
                                  ["peel tool", "paint rays", "contour", "stitch"])
                    r = {
                        "mesh": bname, "tool": tname, "op": op,
                        "triangles": len(base.faces), "spacing": spacing,
                        "volume_error_pct": 100 * vol_err,
                        "hausdorff_spacings": hd / spacing,
                        "hausdorff_raw_spacings": hd_raw / spacing,
                        "debris_ours": debris_ours, "debris_manifold3d": debris_ref,
                        "watertight": watertight, "manifold3d_accepts": manifold_ok,
                        "build_tridexel_ms": times.get("build tri-dexel"),
                        "edit_ms": edit_ms, "stitch_ms": times.get("stitch"),
                        "manifold3d_boolean_ms": 1e3 * t_ref,
                        "kept_removed_added": counts,
                    }
                    ok = vol_err <= VOLUME_TOL and hd <= spacing and watertight and manifold_ok
                    r["ok"] = ok
                    failed |= not ok
                    results.append(r)
                    print(f"{'ok  ' if ok else 'FAIL'} {bname:11} {op:8} {tname:6} "
                          f"volume {100 * vol_err:6.3f} %  Hausdorff {hd / spacing:5.2f} h  "
                          f"watertight {watertight}  manifold {manifold_ok}  "
                          f"edit {edit_ms:8.1f} ms  manifold3d {1e3 * t_ref:8.1f} ms",
                          flush=True)
                    if debris_ours or debris_ref:
                        print(f"     raw Hausdorff {hd_raw / spacing:.2f} h; pieces holding no "
                              f"grid point (largest extent in spacings): ours {debris_ours}, "
                              f"manifold3d {debris_ref}", flush=True)

    print("\n| mesh | op | tool | volume error % | Hausdorff (spacings) | raw, with debris |"
          " watertight+manifold |")
    print("| --- | --- | --- | ---: | ---: | ---: | --- |")
    for r in results:
        print(f"| {r['mesh']} | {r['op']} | {r['tool']} | {r['volume_error_pct']:.3f} | "
              f"{r['hausdorff_spacings']:.2f} | {r['hausdorff_raw_spacings']:.2f} | "
              f"{'yes' if r['watertight'] and r['manifold3d_accepts'] else 'NO'} |")
    print("\n| mesh | op | tool | build tri-dexel ms | edit (peel+paint+contour+stitch) ms |"
          " manifold3d Boolean ms |")
    print("| --- | --- | --- | ---: | ---: | ---: |")
    for r in results:
        print(f"| {r['mesh']} | {r['op']} | {r['tool']} | {r['build_tridexel_ms']:.1f} | "
              f"{r['edit_ms']:.1f} | {r['manifold3d_boolean_ms']:.1f} |")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(results, f, indent=1)
    if failed:
        print("\nFAILED")
        return 1
    print(f"\nall {len(results)} checks passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
