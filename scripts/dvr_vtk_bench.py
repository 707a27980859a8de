#!/usr/bin/env python3
"""Time volmorph's direct volume rendering against VTK's vtkFixedPointVolumeRayCastMapper.

Renders the same volume at the same size with the same transfer function (volmorph's CT bone
preset, written by `volmorph render --save-transfer` and rebuilt as VTK colour and opacity
functions), the same sample distance, shading and scalar-opacity unit distance, from the same
viewing direction and framing, in one run. Also times the picture with the volume deformed by
a 200-handle affine MLS map sampled on a 33³ grid, and reports both ratios against the targets
(volmorph at least 2× faster than VTK; deformed at most 1.5× the undeformed time).

Skips cleanly (exit 0 with a message) when VTK is not installed or the volume is absent.
Build first:  cargo build --release -p volmorph-cli
Run from the repository root:
    python3 scripts/dvr_vtk_bench.py ../shared/data/volumes/cranium_ct.nii.gz [--repeat 5] [--rounds 3]
"""
import argparse
import json
import math
import os
import random
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time

# Offscreen through EGL (no X server needed); VTK's PyPI wheels choose the window at run time.
os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

try:
    import vtk
except ImportError:  # pragma: no cover
    print("SKIP: vtk not installed (pip install vtk)")
    sys.exit(0)

# Must match volmorph_render::DEFAULT_FOV_Y (radians) and FIT_MARGIN (sphere framing).
FOV_Y = 0.6
FIT_MARGIN = 1.05


def volmorph_exe(root):
    exe = os.path.join(os.environ.get("CARGO_TARGET_DIR", os.path.join(root, "target")),
                       "release", "volmorph")
    if not os.path.isfile(exe):
        sys.exit(f"build first: cargo build --release -p volmorph-cli (no {exe})")
    return exe


def children_cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run_volmorph(exe, args):
    """Median wall milliseconds per picture (as volmorph reports it), CPU seconds of the whole
    run (all threads, reading and preparation included) and volmorph's summary line."""
    cpu = children_cpu()
    out = subprocess.run([exe, "render"] + args, check=True, capture_output=True, text=True).stdout
    cpu = children_cpu() - cpu
    m = re.search(r"median ([0-9.]+) ms", out)
    if not m:
        sys.exit(f"unexpected volmorph output: {out}")
    return float(m.group(1)), cpu, out.strip()


def volmorph_times(exe, args, repeat):
    """Median wall ms per picture, and CPU ms per picture: the CPU time of a run of `repeat`
    pictures less that of a run of one, over `repeat − 1` (so reading and preparation cancel)."""
    wall, cpu, text = run_volmorph(exe, args + ["--repeat", str(repeat)])
    _, cpu1, _ = run_volmorph(exe, args + ["--repeat", "1"])
    return wall, (cpu - cpu1) / (repeat - 1) * 1e3, text


def geometry(exe, volume):
    """The volume's geometry as volmorph reads it: physical bounds of the voxel centres,
    origin and direction columns (LPS, spacing and direction applied)."""
    out = subprocess.run([exe, "info", volume], check=True, capture_output=True, text=True).stdout
    num = r"\(([^)]*)\)"
    b = re.search(r"bounds:\s*" + num + r"\s*\.\.\s*" + num, out)
    o = re.search(r"origin:\s*" + num, out)
    d = re.search(r"direction:\s*" + num + r"\s*" + num + r"\s*" + num, out)
    if not (b and o and d):
        sys.exit(f"unexpected volmorph info output: {out}")
    vec = lambda g: [float(x) for x in g.split(",")]
    return {"bounds": (vec(b.group(1)), vec(b.group(2))), "origin": vec(o.group(1)),
            "direction": [vec(g) for g in d.groups()]}


def handles_file(path, bounds, n=200, seed=20241201):
    """n handle pairs: sources spread through the box, targets moved by a smooth bend."""
    rng = random.Random(seed)
    lo, hi = bounds
    c = [(a + b) / 2 for a, b in zip(lo, hi)]
    size = [b - a for a, b in zip(lo, hi)]
    pts = []
    for _ in range(n):
        s = [lo[i] + rng.random() * size[i] for i in range(3)]
        q = [s[i] - c[i] for i in range(3)]
        t = [s[0] + 0.04 * size[0] * math.sin(q[2] / size[2] * math.pi),
             s[1] + 0.03 * size[1] * math.cos(q[0] / size[0] * math.pi),
             s[2]]
        pts.append({"source": s, "target": t})
    with open(path, "w") as f:
        json.dump({"points": pts}, f)


def vtk_renderer(volume, geo, tf, step, size):
    """VTK's pipeline for the picture; returns the render window after a first picture."""
    reader = vtk.vtkNIFTIImageReader()
    reader.SetFileName(volume)
    reader.Update()
    img = reader.GetOutput()
    # vtkNIFTIImageReader gives the voxel grid with spacing only; the orientation goes into
    # the volume's matrix so that VTK's world is volmorph's (LPS, the same anterior view).
    img.SetOrigin(0.0, 0.0, 0.0)
    lo_s, hi_s = img.GetScalarRange()

    color = vtk.vtkColorTransferFunction()
    for v, r, g, b in tf["color"]:
        color.AddRGBPoint(v, r, g, b)
    opacity = vtk.vtkPiecewiseFunction()
    for v, a in tf["opacity"]:
        opacity.AddPoint(v, a)

    prop = vtk.vtkVolumeProperty()
    prop.SetColor(color)
    prop.SetScalarOpacity(opacity)
    prop.SetScalarOpacityUnitDistance(tf.get("unit_distance", 1.0))
    prop.SetInterpolationTypeToLinear()
    prop.ShadeOn()
    prop.SetAmbient(0.2)
    prop.SetDiffuse(0.8)
    prop.SetSpecular(0.25)
    prop.SetSpecularPower(32.0)

    mapper = vtk.vtkFixedPointVolumeRayCastMapper()
    mapper.SetInputData(img)
    mapper.SetAutoAdjustSampleDistances(0)
    mapper.SetSampleDistance(step)
    mapper.SetInteractiveSampleDistance(step)
    mapper.SetImageSampleDistance(1.0)
    mapper.SetNumberOfThreads(os.cpu_count() or 1)

    vol = vtk.vtkVolume()
    vol.SetMapper(mapper)
    m = vtk.vtkMatrix4x4()
    for r in range(3):
        for c in range(3):
            m.SetElement(r, c, geo["direction"][c][r])
        m.SetElement(r, 3, geo["origin"][r])
    vol.SetUserMatrix(m)
    vol.SetProperty(prop)
    ren = vtk.vtkRenderer()
    ren.AddVolume(vol)
    ren.SetBackground(0, 0, 0)
    win = vtk.vtkRenderWindow()
    win.SetOffScreenRendering(1)
    win.AddRenderer(ren)
    win.SetSize(size, size)

    # The same framing as volmorph's anterior view (azimuth −90°, z up, Framing::Sphere).
    b = vol.GetBounds()
    c = [(b[0] + b[1]) / 2, (b[2] + b[3]) / 2, (b[4] + b[5]) / 2]
    radius = 0.5 * math.sqrt((b[1] - b[0]) ** 2 + (b[3] - b[2]) ** 2 + (b[5] - b[4]) ** 2)
    dist = FIT_MARGIN * radius / math.sin(FOV_Y / 2)
    cam = ren.GetActiveCamera()
    cam.SetFocalPoint(*c)
    cam.SetPosition(c[0], c[1] - dist, c[2])
    cam.SetViewUp(0, 0, 1)
    cam.SetViewAngle(math.degrees(FOV_Y))
    ren.ResetCameraClippingRange()

    win.Render()  # first picture: set-up, kept out of the timings
    print(f"VTK {vtk.vtkVersion.GetVTKVersion()}, {win.GetClassName()}, "
          f"{mapper.GetNumberOfThreads()} threads")
    return win


def vtk_times(win, repeat):
    """Median wall milliseconds of `repeat` pictures, and the mean CPU milliseconds per
    picture of this process (all threads: VTK's ray casters and the EGL driver's)."""
    times = []
    cpu = time.process_time()
    for _ in range(repeat):
        t = time.perf_counter()
        win.Render()
        times.append(time.perf_counter() - t)
    cpu = time.process_time() - cpu
    return statistics.median(times) * 1e3, cpu / repeat * 1e3


def vtk_png(win, png):
    grab = vtk.vtkWindowToImageFilter()
    grab.SetInput(win)
    grab.Update()
    w = vtk.vtkPNGWriter()
    w.SetFileName(png)
    w.SetInputConnection(grab.GetOutputPort())
    w.Write()


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("volume", nargs="?",
                   default=os.path.join("..", "shared", "data", "volumes", "cranium_ct.nii.gz"))
    p.add_argument("--repeat", type=int, default=5,
                   help="pictures per round and renderer (at least 2)")
    p.add_argument("--rounds", type=int, default=3,
                   help="rounds, each timing volmorph, VTK and the deformed picture in turn "
                        "(so that a change of machine load affects all three alike)")
    p.add_argument("--size", type=int, default=512)
    p.add_argument("--keep", help="folder for the pictures (default: a temporary one)")
    a = p.parse_args()
    if a.repeat < 2:
        sys.exit("--repeat must be at least 2")
    if not os.path.isfile(a.volume):
        print(f"SKIP: {a.volume} not found")
        return
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    exe = volmorph_exe(root)
    with tempfile.TemporaryDirectory() as tmp:
        out = a.keep or tmp
        os.makedirs(out, exist_ok=True)
        tf_path = os.path.join(out, "ct_bone.json")
        size = f"{a.size}x{a.size}"
        common = ["--transfer", "ct-bone", "--size", size, "--view", "anterior"]
        plain_args = [a.volume, "-o", os.path.join(out, "volmorph.png"),
                      "--save-transfer", tf_path] + common
        _, _, text = run_volmorph(exe, plain_args)
        print(text)
        step = float(re.search(r"step ([0-9.]+)", text).group(1))
        with open(tf_path) as f:
            tf = json.load(f)
        geo = geometry(exe, a.volume)
        win = vtk_renderer(a.volume, geo, tf, step, a.size)
        vtk_png(win, os.path.join(out, "vtk.png"))
        h = os.path.join(out, "handles200.json")
        handles_file(h, geo["bounds"])
        deformed_args = [a.volume, "-o", os.path.join(out, "deformed.png"),
                         "--handles", h, "--method", "affine", "--grid", "33"] + common
        rounds = []
        for r in range(a.rounds):
            ours = volmorph_times(exe, plain_args, a.repeat)
            theirs = vtk_times(win, a.repeat)
            deformed = volmorph_times(exe, deformed_args, a.repeat)
            if r == 0:
                print(deformed[2])
            rounds.append((ours[:2], theirs, deformed[:2]))
            print(f"round {r + 1} (wall / CPU ms per picture): volmorph {ours[0]:.1f} / "
                  f"{ours[1]:.1f}, VTK {theirs[0]:.1f} / {theirs[1]:.1f}, deformed "
                  f"{deformed[0]:.1f} / {deformed[1]:.1f}")
    med = statistics.median
    print(f"\n{a.size}×{a.size} composite, CT bone, step {step:.3f}; medians over {a.rounds} "
          f"rounds of {a.repeat} pictures (ratios: medians of the per-round ratios)")
    print("                                        wall ms    CPU ms")
    for name, k in [("VTK vtkFixedPointVolumeRayCastMapper", 1), ("volmorph", 0),
                    ("volmorph, 200-handle MLS on 33³", 2)]:
        print(f"  {name:36s} {med(r[k][0] for r in rounds):9.1f} "
              f"{med(r[k][1] for r in rounds):9.1f}")
    for what, i in [("wall", 0), ("CPU", 1)]:
        speedup = med(r[1][i] / r[0][i] for r in rounds)
        slowdown = med(r[2][i] / r[0][i] for r in rounds)
        print(f"  {what:4s}: VTK / volmorph = {speedup:.2f} (target ≥ 2), "
              f"deformed / undeformed = {slowdown:.2f} (target ≤ 1.5)")

if __name__ == "__main__":
    main()
