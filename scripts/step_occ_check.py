#!/usr/bin/env python3
"""Validate a STEP file written by `volmorph ffd --mode accurate` with OpenCASCADE.

Checks: the file loads (the time and peak memory of reading and transferring it are
printed, and written with --json); BRepCheck_Analyzer finds the shape valid; the largest edge tolerance
is at most 1e-6; every edge shared by two or more faces is shared by exactly two (edges used
by one face are boundary edges of an open model); and, with --area A (or --report R.json from
`volmorph ffd --report`), the total surface area matches volmorph's own to 1e-6 relative.

Needs `cadquery-ocp` (pip install cadquery-ocp). Without it the script prints a note and
exits 0, so it can run on machines without OpenCASCADE.

Usage:
  python3 scripts/step_occ_check.py OUT.step [--report OUT.json | --area A] [--tol 1e-6]
                                   [--load-only] [--json RESULT.json]
  python3 scripts/step_occ_check.py OUT.step --entities
      (no OpenCASCADE needed: bytes and count of each entity type of the DATA section, and the
      control points of the B-spline surfaces, to see where the size of a file goes)
"""

import argparse
import json
import os
import resource
import sys
import time


def entity_sizes(path: str) -> int:
    """Print bytes and count per entity type of a STEP file (instances `#N=TYPE(...);`)."""
    import re

    text = open(path, encoding="ascii", errors="replace").read()
    start = text.find("DATA;")
    body = text[start + 5:text.find("ENDSEC;", start)] if start >= 0 else text
    stats = {}
    surf_points = []
    # Instances end at ';' outside strings; volmorph writes no ';' inside strings.
    for inst in body.split(";"):
        inst = inst.strip()
        m = re.match(r"#\d+\s*=\s*\(?\s*([A-Z_0-9]+)", inst)
        if not m:
            continue
        kind = m.group(1)
        n, b = stats.get(kind, (0, 0))
        stats[kind] = (n + 1, b + len(inst) + 2)
        if kind.startswith("B_SPLINE_SURFACE") or "B_SPLINE_SURFACE" in inst[:200]:
            surf_points.append(inst.count("#") - 1)
    total = sum(b for _, b in stats.values())
    print(f"{path}: {os.path.getsize(path) / 1e6:.1f} MB, {sum(n for n, _ in stats.values())} "
          f"instances")
    print(f"{'entity':40} {'count':>10} {'MB':>9} {'%':>6} {'bytes each':>11}")
    for kind, (n, b) in sorted(stats.items(), key=lambda kv: -kv[1][1]):
        print(f"{kind:40} {n:10d} {b / 1e6:9.2f} {100 * b / total:6.1f} {b / n:11.1f}")
    if surf_points:
        surf_points.sort()
        print(f"B-spline surfaces: {len(surf_points)}, control points each: median "
              f"{surf_points[len(surf_points) // 2]}, max {surf_points[-1]}")
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("step")
    ap.add_argument("--report", help="JSON report of `volmorph ffd --report`")
    ap.add_argument("--area", type=float, help="surface area computed by volmorph")
    ap.add_argument("--tol", type=float, default=1e-6, help="largest edge tolerance allowed")
    ap.add_argument("--area-rel", type=float, default=1e-6, help="relative area tolerance")
    ap.add_argument("--load-only", action="store_true", help="time the load and stop")
    ap.add_argument("--json", help="write size, load time and peak memory to this file")
    ap.add_argument("--surfacecurve-mode", type=int,
                    help="OpenCASCADE's read.surfacecurve.mode (0 default, 2/-2 prefer/force "
                         "pcurves, 3/-3 prefer/force 3-D curves) for timing the transfer")
    ap.add_argument("--entities", action="store_true",
                    help="print bytes and count per entity type (no OpenCASCADE needed)")
    a = ap.parse_args()
    if a.entities:
        return entity_sizes(a.step)

    try:
        from OCP.STEPControl import STEPControl_Reader
        from OCP.IFSelect import IFSelect_RetDone
        from OCP.BRepCheck import BRepCheck_Analyzer
        from OCP.TopExp import TopExp_Explorer
        from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE
        from OCP.BRep import BRep_Tool
        from OCP.GProp import GProp_GProps
        from OCP.BRepGProp import BRepGProp
        from OCP.TopoDS import TopoDS
    except ImportError:
        print("SKIP: OpenCASCADE (cadquery-ocp) is not installed")
        return 0

    area_ref = a.area
    if a.report:
        with open(a.report) as f:
            area_ref = json.load(f)["surface_area"]

    if a.surfacecurve_mode is not None:
        from OCP.Interface import Interface_Static

        Interface_Static.SetIVal_s("read.surfacecurve.mode", a.surfacecurve_mode)
    t0 = time.perf_counter()
    reader = STEPControl_Reader()
    if reader.ReadFile(a.step) != IFSelect_RetDone:
        print(f"FAIL: {a.step} does not load")
        return 1
    t1 = time.perf_counter()
    reader.TransferRoots()
    shape = reader.OneShape()
    t2 = time.perf_counter()
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    size_mb = os.path.getsize(a.step) / 1e6
    print(
        f"file {size_mb:.1f} MB; OpenCASCADE read {t1 - t0:.2f} s + transfer {t2 - t1:.2f} s "
        f"= {t2 - t0:.2f} s, peak memory {rss_mb:.0f} MB"
    )
    if a.json:
        with open(a.json, "w") as f:
            json.dump(
                {"size_mb": size_mb, "read_s": t1 - t0, "transfer_s": t2 - t1,
                 "load_s": t2 - t0, "peak_rss_mb": rss_mb},
                f,
            )
    if a.load_only:
        return 0
    ok = True

    nfaces = 0
    exp = TopExp_Explorer(shape, TopAbs_FACE)
    while exp.More():
        nfaces += 1
        exp.Next()
    print(f"loaded: {nfaces} faces")

    valid = BRepCheck_Analyzer(shape).IsValid()
    print(f"BRepCheck_Analyzer valid: {valid}")
    ok &= valid

    to_edge = getattr(TopoDS, "Edge_s", None) or TopoDS.Edge
    # Edge → number of faces using it (edges compared with IsSame, bucketed by hash).
    buckets = {}
    fexp = TopExp_Explorer(shape, TopAbs_FACE)
    while fexp.More():
        face = fexp.Current()
        seen = []
        eexp = TopExp_Explorer(face, TopAbs_EDGE)
        while eexp.More():
            e = eexp.Current()
            if not any(e.IsSame(s) for s in seen):
                seen.append(e)
                bucket = buckets.setdefault(hash(e), [])
                for entry in bucket:
                    if entry[0].IsSame(e):
                        entry[1] += 1
                        break
                else:
                    bucket.append([e, 1])
            eexp.Next()
        fexp.Next()
    max_tol = 0.0
    hist = {}
    nedges = 0
    for bucket in buckets.values():
        for e, n in bucket:
            nedges += 1
            max_tol = max(max_tol, BRep_Tool.Tolerance_s(to_edge(e)))
            hist[n] = hist.get(n, 0) + 1
    print(f"edges: {nedges}, faces per edge: {dict(sorted(hist.items()))}")
    print(f"largest edge tolerance: {max_tol:.3e} (limit {a.tol:.1e})")
    ok &= max_tol <= a.tol
    shared_ok = all(n in (1, 2) for n in hist)
    print(f"every interior edge shared by exactly two faces: {shared_ok}")
    ok &= shared_ok

    props = GProp_GProps()
    BRepGProp.SurfaceProperties_s(shape, props, 1e-10)
    area = props.Mass()
    print(f"OpenCASCADE area: {area:.15e}")
    if area_ref is not None:
        rel = abs(area - area_ref) / abs(area_ref)
        print(f"volmorph area:    {area_ref:.15e} (relative difference {rel:.2e})")
        ok &= rel <= a.area_rel
    print("PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
