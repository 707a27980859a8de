#!/usr/bin/env python3
"""Time volmorph's hot paths against their peers side by side, in one run (issue 22).

Each comparison runs the same work in both programs on this machine and prints volmorph's
median, the peer's median and the ratio (peer / volmorph, so higher is better for volmorph),
with the issue's target ratio:

* mc        marching cubes of the 256³ sphere signed distance (`volmorph phantom sphere
            --kind sdf`, the isosurface suite's input) against VTK's vtkFlyingEdges3D on the
            same file read by vtkNIFTIImageReader (with per-vertex normals, as volmorph
            computes them; gradients and scalars off; VTK's STDThread SMP back end on all
            cores). Target ≥ 4×. The triangle counts are compared too.
* tps       thin-plate spline through 1000 landmarks, fit plus evaluation on a 32³ grid:
            `volmorph bench handles` (items "TPS: factorise" + "TPS: evaluate on grid")
            against scipy.interpolate.RBFInterpolator(kernel="thin_plate_spline", degree=1)
            on 1000 random landmarks in the same box, fit plus evaluation on 32³ points.
            Target ≥ 10×.
* pullback  trilinear pull-back of the 256³ teapot (f32) through a moved 9³ cubic lattice:
            `volmorph bench warp` (item "pull-back trilinear (f32)") against SimpleITK's
            Resample with a third-order BSplineTransform of 9³ control points (mesh 6³) over
            the same image, its inner control points moved at random by up to half a region,
            linear interpolation. The issue's target is an absolute 60 ms; the ratio is shown.
* splinepy  B-spline volume evaluation against splinepy's NURBS/BSpline (its C++ core on all
            cores, `nthreads`): (a) point + gradient of a rational tricubic volume of 8³
            control points at 2²⁰ random parameters (`volmorph bench ffd`, item "trivariate
            point + gradient"; splinepy's `derivative` with orders 000, 100, 010, 001 in one
            call); (b) the vertex FFD's map, a degree-2 volume of 6×8×6 control points at the
            1 001 114 vertices' parameters (item "vertex FFD, positions only", which also maps
            each vertex from physical to parameter space; splinepy is handed the parameters).
            Random volumes of the same degrees and sizes on splinepy's side: evaluation cost
            does not depend on the control point values. Target ≥ 1× (ahead of the peer).

volmorph's figures are the medians its own `volmorph bench … --json` reports (inputs built
once, outside the clock); the peers' are medians of the same call timed here after one
warm-up, also with inputs built outside the clock.

Skips each comparison cleanly (a SKIP line) when its peer is not importable; exits 0 unless a
check failed (triangle counts apart by more than 1 %, or volmorph failed).
Build first:  cargo build --release -p volmorph-cli
Peers:        pip install numpy vtk scipy SimpleITK splinepy
Run from the repository root:
    python3 scripts/peer_speed.py [--repeat 5] [--only mc,tps,pullback,splinepy]
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

FAILED = False


def volmorph_exe():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    exe = os.path.join(os.environ.get("CARGO_TARGET_DIR", os.path.join(root, "target")),
                       "release", "volmorph")
    if not os.path.isfile(exe):
        sys.exit(f"build first: cargo build --release -p volmorph-cli (no {exe})")
    return exe


def bench_json(exe, args):
    p = subprocess.run([exe, "-q", "bench"] + args + ["--json"], capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"volmorph bench {' '.join(args)} failed: {p.stderr.strip()}")
    return json.loads(p.stdout)


def item(report, name):
    for it in report["items"]:
        if it["name"] == name:
            return it
    raise RuntimeError(f"no item {name!r} in the {report['suite']} report")


def median_time(fn, repeat):
    fn()  # warm-up
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def line(name, ours, peer, peer_name, target):
    ratio = peer / ours
    verdict = "met" if ratio >= target else "not met"
    print(f"{name:10} volmorph {1e3 * ours:9.2f} ms   {peer_name} {1e3 * peer:9.2f} ms   "
          f"ratio {ratio:6.2f}x   (target >= {target:g}x: {verdict})", flush=True)


def load_average():
    try:
        return os.getloadavg()[0]
    except OSError:
        return float("nan")


def compare_mc(exe, repeat, tmp):
    global FAILED
    try:
        import vtk
    except ImportError:
        print("SKIP mc: vtk not installed (pip install vtk)")
        return
    size = 256
    path = os.path.join(tmp, "sphere_sdf.nii")
    subprocess.run([exe, "-q", "phantom", "sphere", "--kind", "sdf", "--size", str(size),
                    "--output", path], check=True, capture_output=True)
    smp = vtk.vtkSMPTools()
    # VTK's PyPI wheels default to the sequential back end; STDThread runs on every core,
    # as volmorph does.
    smp.SetBackend("STDThread")
    smp.Initialize(os.cpu_count() or 1)
    reader = vtk.vtkNIFTIImageReader()
    reader.SetFileName(path)
    reader.Update()
    image = vtk.vtkImageData()
    image.DeepCopy(reader.GetOutput())
    fe = vtk.vtkFlyingEdges3D()
    fe.SetInputData(image)
    fe.SetValue(0, 0.0)
    # volmorph's marching cubes always computes per-vertex normals from the field's gradient;
    # so does VTK here.
    fe.ComputeNormalsOn()
    fe.ComputeGradientsOff()
    fe.ComputeScalarsOff()

    def run_vtk():
        fe.Modified()
        fe.Update()

    peer = median_time(run_vtk, repeat)
    vtk_tris = fe.GetOutput().GetNumberOfPolys()
    report = bench_json(exe, ["isosurface", "--size", str(size), "--repeat", str(repeat)])
    mc = item(report, "marching cubes")
    ours = mc["median_s"]
    print(f"mc: VTK {vtk.vtkVersion.GetVTKVersion()} SMP back end "
          f"{smp.GetBackend()} on {smp.GetEstimatedNumberOfThreads()} threads; "
          f"triangles volmorph {mc['triangles']}, VTK {vtk_tris}")
    if abs(mc["triangles"] - vtk_tris) > 0.01 * vtk_tris:
        print("FAIL mc: triangle counts differ by more than 1 %")
        FAILED = True
    line("mc", ours, peer, "VTK FlyingEdges3D", 4.0)


def compare_tps(exe, repeat):
    try:
        import numpy as np
        from scipy.interpolate import RBFInterpolator
    except ImportError:
        print("SKIP tps: scipy and numpy are needed (pip install numpy scipy)")
        return
    landmarks, grid = 1000, 32
    rng = np.random.default_rng(22)
    src = rng.uniform(0.0, 1.0, size=(landmarks, 3))
    dst = src + rng.uniform(-0.05, 0.05, size=(landmarks, 3))
    ax = np.linspace(0.0, 1.0, grid)
    pts = np.stack(np.meshgrid(ax, ax, ax, indexing="ij"), axis=-1).reshape(-1, 3)

    def run_scipy():
        rbf = RBFInterpolator(src, dst - src, kernel="thin_plate_spline", degree=1)
        rbf(pts)

    peer = median_time(run_scipy, repeat)
    report = bench_json(exe, ["handles", "--landmarks", str(landmarks), "--grid", str(grid),
                              "--repeat", str(repeat)])
    ours = item(report, "TPS: factorise")["median_s"] + \
        item(report, "TPS: evaluate on grid")["median_s"]
    import scipy
    print(f"tps: scipy {scipy.__version__}, {landmarks} landmarks, {grid}³ points; volmorph's "
          f"figure is the sum of the factorise and evaluate medians")
    line("tps", ours, peer, "scipy RBFInterpolator", 10.0)


def compare_pullback(exe, repeat, tmp):
    try:
        import numpy as np
        import SimpleITK as sitk
    except ImportError:
        print("SKIP pullback: SimpleITK and numpy are needed (pip install numpy SimpleITK)")
        return
    size, counts = 256, 9
    path = os.path.join(tmp, "teapot.nii")
    subprocess.run([exe, "-q", "phantom", "teapot", "--size", str(size), "--output", path],
                   check=True, capture_output=True)
    image = sitk.Cast(sitk.ReadImage(path), sitk.sitkFloat32)
    tx = sitk.BSplineTransformInitializer(image, [counts - 3] * 3, 3)
    params = np.zeros(len(tx.GetParameters()))
    region = np.array(image.GetSpacing()) * (size - 1) / (counts - 3)
    rng = np.random.default_rng(22)
    n = counts ** 3
    for axis in range(3):
        block = np.zeros((counts, counts, counts))
        block[1:-1, 1:-1, 1:-1] = region[axis] * rng.uniform(-0.5, 0.5, (counts - 2,) * 3)
        params[axis * n:(axis + 1) * n] = block.ravel()
    tx.SetParameters(params.tolist())

    def run_sitk():
        sitk.Resample(image, image, tx, sitk.sitkLinear, 0.0, sitk.sitkFloat32)

    peer_runs = max(1, min(repeat, 3))  # SimpleITK takes seconds per run
    peer = median_time(run_sitk, peer_runs)
    report = bench_json(exe, ["warp", "--size", str(size), "--lattice", str(counts),
                              "--repeat", str(repeat)])
    ours = item(report, "pull-back trilinear (f32)")["median_s"]
    print(f"pullback: SimpleITK {sitk.Version.VersionString()} on "
          f"{sitk.ProcessObject.GetGlobalDefaultNumberOfThreads()} threads, "
          f"{size}³ f32, {counts}³ control points (peer median of {peer_runs} runs)")
    line("pullback", ours, peer, "SimpleITK Resample", 1.0)


def compare_splinepy(exe, repeat):
    try:
        import numpy as np
        import splinepy
    except ImportError:
        print("SKIP splinepy: splinepy and numpy are needed (pip install numpy splinepy)")
        return
    threads = os.cpu_count() or 1
    peer_runs = max(1, min(repeat, 3))  # splinepy takes seconds per run
    rng = np.random.default_rng(22)

    def clamped(degree, count):
        inner = np.linspace(0.0, 1.0, count - degree + 1)
        return np.concatenate([[0.0] * degree, inner, [1.0] * degree]).tolist()

    # (a) rational tricubic, 8³ control points, 2²⁰ points: point and the three partials.
    points = 1 << 20
    n = 8
    rational = splinepy.NURBS(
        degrees=[3, 3, 3],
        knot_vectors=[clamped(3, n)] * 3,
        control_points=rng.uniform(-1.0, 1.0, (n ** 3, 3)),
        weights=rng.uniform(0.5, 2.0, (n ** 3, 1)),
    )
    queries = rng.uniform(0.0, 1.0, (points, 3))
    orders = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    peer_a = median_time(lambda: rational.derivative(queries, orders, nthreads=threads),
                         peer_runs)

    # (b) the vertex FFD's volume: degree 2, 6 × 8 × 6 control points, 1 001 114 points.
    counts = [6, 8, 6]
    volume = splinepy.BSpline(
        degrees=[2, 2, 2],
        knot_vectors=[clamped(2, c) for c in counts],
        control_points=rng.uniform(-1.0, 1.0, (int(np.prod(counts)), 3)),
    )
    vertices = rng.uniform(0.0, 1.0, (1_001_114, 3))
    peer_b = median_time(lambda: volume.evaluate(vertices, nthreads=threads), peer_runs)

    report = bench_json(exe, ["ffd", "--repeat", str(repeat)])
    ours_a = item(report, "trivariate point + gradient")["median_s"]
    ours_b = item(report, "vertex FFD, positions only")["median_s"]
    print(f"splinepy {splinepy.__version__} on {threads} threads: (a) rational tricubic 8³, "
          f"{points} points, point + gradient; (b) degree-2 6×8×6 volume at 1 001 114 points "
          f"(peer medians of {peer_runs} runs)")
    line("trivariate", ours_a, peer_a, "splinepy derivative", 1.0)
    line("vertex ffd", ours_b, peer_b, "splinepy evaluate", 1.0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--only", default="mc,tps,pullback,splinepy")
    args = ap.parse_args()
    exe = volmorph_exe()
    only = set(args.only.split(","))
    print(f"load average at start: {load_average():.2f}")
    with tempfile.TemporaryDirectory() as tmp:
        try:
            if "mc" in only:
                compare_mc(exe, args.repeat, tmp)
            if "tps" in only:
                compare_tps(exe, args.repeat)
            if "pullback" in only:
                compare_pullback(exe, args.repeat, tmp)
            if "splinepy" in only:
                compare_splinepy(exe, args.repeat)
        except (RuntimeError, subprocess.CalledProcessError) as e:
            print(f"FAIL: {e}")
            global FAILED
            FAILED = True
    print(f"load average at end: {load_average():.2f}")
    sys.exit(1 if FAILED else 0)


if __name__ == "__main__":
    main()
