#!/usr/bin/env python3
"""Registration accuracy and speed of volmorph against itk-elastix and SimpleITK.

On each pair with known ground truth it runs
  * volmorph:  `volmorph register FIXED MOVING -o OUT --dense` (handles, NCC matches, handle
               map, dense B-spline correction), timed as a whole command including all outputs;
  * elastix:   itk-elastix with its default B-spline parameter map (multi-resolution,
               AdvancedMattesMutualInformation, adaptive stochastic gradient descent);
  * SimpleITK: ImageRegistrationMethod with a B-spline transform (10 mm mesh spacing), Mattes
               mutual information, LBFGS-B, shrink factors 4/2/1;
and prints the target registration error (mean, sd, 95th percentile, max, mm) at the pair's
landmarks and the wall time of each, side by side.

Pairs (written with volmorph itself into --work):
  * phantom       `volmorph register phantom`: breathing lung phantom, landmarks at vessel
                  bifurcations (inhale -> exhale);
  * cranium-M     ../shared/data/volumes/cranium_ct.nii.gz deformed by a known random smooth
                  B-spline field of magnitude M mm (`volmorph register known-pair`);
  * mni-M         the MNI152 T1 template, likewise;
  * mni-inter     the MNI152 template with a large field (10 mm) and changed intensities (gain,
                  gamma, bias field): an inter-subject-like pair.
Pairs whose input file is absent are skipped.

Every map goes from fixed to moving (ITK's convention), so TRE_i = |T(x_i) - y_i| for fixed
landmark x_i and moving landmark y_i, all in physical LPS millimetres.

Usage: scripts/register_peer_check.py [--volmorph target/release/volmorph] [--data DIR]
       [--work DIR] [--pairs phantom,cranium-4,...] [--skip elastix,simpleitk] [--json OUT.json]
Exits 0 with a SKIP message when itk-elastix or SimpleITK is not importable or the volmorph
binary is missing (`cargo build --release -p volmorph-cli`).
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

try:
    import numpy as np
    import itk
    import SimpleITK as sitk
except ImportError as e:
    print(f"SKIP: {e.name} is not installed (pip install itk-elastix SimpleITK)")
    sys.exit(0)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def read_points(path):
    pts = []
    with open(path) as f:
        for line in f:
            line = line.split("#")[0].strip()
            if line:
                pts.append([float(v) for v in line.replace(",", " ").split()[:3]])
    return np.array(pts)


def stats(err):
    err = np.asarray(err)
    return {
        "mean": float(err.mean()),
        "sd": float(err.std()),
        "p95": float(np.percentile(err, 95)),
        "max": float(err.max()),
    }


def run_volmorph(exe, fixed, moving, lf, lm, out):
    t0 = time.perf_counter()
    subprocess.run(
        [exe, "register", fixed, moving, "-o", out, "--dense", "--landmarks", f"{lf},{lm}"],
        check=True,
        stdout=subprocess.DEVNULL,
    )
    wall = time.perf_counter() - t0
    with open(os.path.join(out, "report.json")) as f:
        rep = json.load(f)
    t = rep["tre_after"]
    return {k: t[k] for k in ("mean", "sd", "p95", "max")}, wall, rep["tre_before"]["mean"]


def field_at(field, points):
    """Trilinear sample of an ITK vector image (fixed grid) at physical points."""
    arr = itk.array_view_from_image(field)  # z, y, x, 3
    out = []
    for p in points:
        idx = field.TransformPhysicalPointToContinuousIndex([float(v) for v in p])
        i = np.array([idx[0], idx[1], idx[2]])
        i0 = np.clip(np.floor(i).astype(int), 0, np.array(arr.shape[2::-1]) - 2)
        f = i - i0
        acc = np.zeros(3)
        for dz in (0, 1):
            for dy in (0, 1):
                for dx in (0, 1):
                    w = (f[0] if dx else 1 - f[0]) * (f[1] if dy else 1 - f[1]) * (f[2] if dz else 1 - f[2])
                    acc += w * arr[i0[2] + dz, i0[1] + dy, i0[0] + dx]
        out.append(acc)
    return np.array(out)


def run_elastix(fixed, moving, lf, lm, out):
    """elastix and transformix write their files (deformationField.nii, logs) into `out`."""
    os.makedirs(out, exist_ok=True)
    f = itk.imread(fixed, itk.F)
    m = itk.imread(moving, itk.F)
    po = itk.ParameterObject.New()
    po.AddParameterMap(po.GetDefaultParameterMap("bspline"))
    t0 = time.perf_counter()
    _, tp = itk.elastix_registration_method(
        f, m, parameter_object=po, log_to_console=False, output_directory=out
    )
    wall = time.perf_counter() - t0
    field = itk.transformix_deformation_field(m, tp, output_directory=out)
    a, b = read_points(lf), read_points(lm)
    mapped = a + field_at(field, a)
    return stats(np.linalg.norm(mapped - b, axis=1)), wall


def run_simpleitk(fixed, moving, lf, lm, out):
    f = sitk.ReadImage(fixed, sitk.sitkFloat32)
    m = sitk.ReadImage(moving, sitk.sitkFloat32)
    t0 = time.perf_counter()
    size = [sz * sp for sz, sp in zip(f.GetSize(), f.GetSpacing())]
    mesh = [max(1, int(round(s / 10.0))) for s in size]
    tx = sitk.BSplineTransformInitializer(f, mesh, order=3)
    r = sitk.ImageRegistrationMethod()
    r.SetMetricAsMattesMutualInformation(numberOfHistogramBins=50)
    r.SetMetricSamplingStrategy(r.RANDOM)
    r.SetMetricSamplingPercentage(0.05, seed=1)
    r.SetInterpolator(sitk.sitkLinear)
    r.SetOptimizerAsLBFGSB(gradientConvergenceTolerance=1e-5, numberOfIterations=100)
    r.SetInitialTransform(tx, inPlace=True)
    r.SetShrinkFactorsPerLevel([4, 2, 1])
    r.SetSmoothingSigmasPerLevel([2, 1, 0])
    r.SmoothingSigmasAreSpecifiedInPhysicalUnitsOff()
    out = r.Execute(f, m)
    wall = time.perf_counter() - t0
    a, b = read_points(lf), read_points(lm)
    mapped = np.array([out.TransformPoint(tuple(float(v) for v in p)) for p in a])
    return stats(np.linalg.norm(mapped - b, axis=1)), wall


def make_pairs(exe, data, work, names):
    pairs = []
    for name in names:
        d = os.path.join(work, name)
        if name == "phantom":
            subprocess.run([exe, "register", "phantom", "-o", d], check=True, stdout=subprocess.DEVNULL)
            pairs.append((name, f"{d}/inhale.nii.gz", f"{d}/exhale.nii.gz",
                          f"{d}/landmarks_inhale.txt", f"{d}/landmarks_exhale.txt"))
            continue
        base, _, arg = name.partition("-")
        src = {"cranium": "cranium_ct.nii.gz", "mni": "mni152_t1_1mm.nii.gz"}.get(base)
        if src is None or not os.path.exists(os.path.join(data, "volumes", src)):
            print(f"skip {name}: {src} not in {data}/volumes")
            continue
        cmd = [exe, "register", "known-pair", os.path.join(data, "volumes", src), "-o", d, "--seed", "7"]
        if arg == "inter":
            cmd += ["--magnitude", "10", "--intensity-change"]
        else:
            cmd += ["--magnitude", arg]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        pairs.append((name, f"{d}/fixed.nii.gz", f"{d}/moving.nii.gz",
                      f"{d}/landmarks_fixed.txt", f"{d}/landmarks_moving.txt"))
    return pairs


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--volmorph", default=os.path.join(ROOT, "target", "release", "volmorph"))
    ap.add_argument("--data", default=os.path.join(ROOT, "..", "shared", "data"))
    ap.add_argument("--work", help="folder for the pairs and outputs (default: a temporary one)")
    ap.add_argument("--pairs", default="phantom,cranium-4,cranium-8,mni-4,mni-8,mni-inter")
    ap.add_argument("--json", help="write the table as JSON")
    ap.add_argument("--skip", default="", help="peers to leave out, e.g. simpleitk")
    a = ap.parse_args()
    a.volmorph, a.data = os.path.abspath(a.volmorph), os.path.abspath(a.data)
    if not os.path.exists(a.volmorph):
        print(f"SKIP: no volmorph binary at {a.volmorph} (cargo build --release -p volmorph-cli)")
        return 0
    work = os.path.abspath(a.work or tempfile.mkdtemp(prefix="volmorph-peer-"))
    os.makedirs(work, exist_ok=True)
    # Peers that write beside the current folder (elastix, transformix) write into the work
    # folder, never into the checkout.
    os.chdir(work)
    print(f"pairs and outputs in {work}")
    rows = []
    for name, fixed, moving, lf, lm in make_pairs(a.volmorph, a.data, work, a.pairs.split(",")):
        print(f"\n{name}:")
        print(f"  {'tool':<10} {'mean':>6} {'sd':>6} {'p95':>6} {'max':>6} {'time s':>8}")
        row = {"pair": name}

        def show(tool, t, w):
            row[tool] = [t, w]
            print(f"  {tool:<10} {t['mean']:6.2f} {t['sd']:6.2f} {t['p95']:6.2f} {t['max']:6.2f} {w:8.1f}")
            sys.stdout.flush()

        v, vt, before = run_volmorph(a.volmorph, fixed, moving, lf, lm, os.path.join(work, name, "volmorph"))
        row["before"] = before
        print(f"  {'before':<10} {before:6.2f}")
        show("volmorph", v, vt)
        for tool, fn in (("elastix", run_elastix), ("SimpleITK", run_simpleitk)):
            if tool.lower() in a.skip.lower().split(","):
                continue
            t, w = fn(fixed, moving, lf, lm, os.path.join(work, name, tool.lower()))
            show(tool, t, w)
        rows.append(row)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
