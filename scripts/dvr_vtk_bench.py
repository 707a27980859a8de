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
    python3 scripts/dvr_vtk_bench.py ../shared/data/volumes/cranium_ct.nii.gz [--repeat 5]
"""
import argparse
import json
import math
import os
import random
import re
import statistics
import subprocess
import sys
import tempfile
import time

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


def run_volmorph(exe, args):
    out = subprocess.run([exe, "render"] + args, check=True, capture_output=True, text=True).stdout
    m = re.search(r"median ([0-9.]+) ms", out)
    if not m:
        sys.exit(f"unexpected volmorph output: {out}")
    return float(m.group(1)), out.strip()


def physical_bounds(exe, volume):
    """The volume's physical bounds as volmorph reads them (spacing and direction applied)."""
    out = subprocess.run([exe, "info", volume], check=True, capture_output=True, text=True).stdout
    m = re.search(r"bounds:\s*\(([^)]*)\)\s*\.\.\s*\(([^)]*)\)", out)
    if not m:
        sys.exit(f"unexpected volmorph info output: {out}")
    return tuple([float(x) for x in g.split(",")] for g in m.groups())


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


def vtk_render_times(volume, tf, step, size, repeat, png):
    reader = vtk.vtkNIFTIImageReader()
    reader.SetFileName(volume)
    reader.Update()
    img = reader.GetOutput()
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

    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        win.Render()
        times.append(time.perf_counter() - t)
    if png:
        grab = vtk.vtkWindowToImageFilter()
        grab.SetInput(win)
        grab.Update()
        w = vtk.vtkPNGWriter()
        w.SetFileName(png)
        w.SetInputConnection(grab.GetOutputPort())
        w.Write()
    return statistics.median(times) * 1e3, (lo_s, hi_s), (b[0::2], b[1::2])


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("volume", nargs="?",
                   default=os.path.join("..", "shared", "data", "volumes", "cranium_ct.nii.gz"))
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--size", type=int, default=512)
    p.add_argument("--keep", help="folder for the pictures (default: a temporary one)")
    a = p.parse_args()
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
        common = ["--transfer", "ct-bone", "--size", size, "--view", "anterior",
                  "--repeat", str(a.repeat)]
        ours, text = run_volmorph(exe, [a.volume, "-o", os.path.join(out, "volmorph.png"),
                                        "--save-transfer", tf_path] + common)
        print(text)
        step = float(re.search(r"step ([0-9.]+)", text).group(1))
        with open(tf_path) as f:
            tf = json.load(f)
        theirs, _, _ = vtk_render_times(a.volume, tf, step, a.size, a.repeat,
                                             os.path.join(out, "vtk.png"))
        h = os.path.join(out, "handles200.json")
        handles_file(h, physical_bounds(exe, a.volume))
        deformed, text = run_volmorph(exe, [a.volume, "-o", os.path.join(out, "deformed.png"),
                                            "--handles", h, "--method", "affine",
                                            "--grid", "33"] + common)
        print(text)
    print(f"\n{a.size}×{a.size} composite, CT bone, step {step:.3f}, median of {a.repeat}:")
    print(f"  VTK vtkFixedPointVolumeRayCastMapper {theirs:9.1f} ms")
    print(f"  volmorph                             {ours:9.1f} ms   "
          f"VTK / volmorph = {theirs / ours:.2f} (target ≥ 2)")
    print(f"  volmorph, 200-handle MLS on 33³      {deformed:9.1f} ms   "
          f"deformed / undeformed = {deformed / ours:.2f} (target ≤ 1.5)")


if __name__ == "__main__":
    main()
