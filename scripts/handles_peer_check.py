#!/usr/bin/env python3
"""Compare volmorph's handle-driven maps with independent implementations.

* 3D thin-plate / biharmonic volume spline (`volmorph handles apply --method tps`) against
  scipy.interpolate.RBFInterpolator with the same kernel and a degree-1 polynomial, for both
  kernels: `--kernel r` (G(r) = r, the 3-D biharmonic; scipy's "linear", whose sign
  convention -r gives the same interpolant) and `--kernel r2logr` (G(r) = r^2 log r, the
  thesis's; scipy's "thin_plate_spline");
* 3D affine moving least squares (`--method affine`, weights 1/|p - v|^2) against `molesq`
  (weights 1/(|p - v|^2 + eps), the same to rounding away from the handles).

Random handle sets and probe points are drawn, the maps evaluated by both, and the largest
relative difference |a - b| / max(1, |b|) reported; agreement within 1e-8 passes.

Usage: scripts/handles_peer_check.py [--volmorph PATH] [--seed N]
Skips (exit 0) when numpy, scipy or molesq are not installed, or the binary is missing.
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile

TOLERANCE = 1e-8


def find_binary(explicit):
    if explicit:
        return explicit
    here = os.path.dirname(os.path.abspath(__file__))
    for build in ("release", "debug"):
        p = os.path.join(here, "..", "target", build, "volmorph")
        if os.path.exists(p):
            return p
    return shutil.which("volmorph")


def run_apply(binary, method, src, dst, probes, workdir, extra=()):
    handles = {
        "points": [
            {"source": [float(v) for v in s], "target": [float(v) for v in t]}
            for s, t in zip(src, dst)
        ]
    }
    hpath = os.path.join(workdir, "h.json")
    ppath = os.path.join(workdir, "probes.txt")
    opath = os.path.join(workdir, "out_%s.txt" % method)
    with open(hpath, "w") as f:
        json.dump(handles, f)
    with open(ppath, "w") as f:
        for p in probes:
            f.write("%r %r %r\n" % (float(p[0]), float(p[1]), float(p[2])))
    subprocess.run(
        [binary, "handles", "apply", ppath, "--handles", hpath, "--method", method, "-o", opath]
        + list(extra),
        check=True,
        stdout=subprocess.DEVNULL,
    )
    import numpy as np

    return np.loadtxt(opath, ndmin=2)


def rel_err(a, b):
    import numpy as np

    return float(np.max(np.linalg.norm(a - b, axis=1) / np.maximum(1.0, np.linalg.norm(b, axis=1))))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--volmorph", help="path of the volmorph binary")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    try:
        import numpy as np
        from scipy.interpolate import RBFInterpolator
    except ImportError as e:
        print("SKIP: numpy/scipy not available (%s)" % e)
        return 0
    try:
        from molesq import Transformer
    except ImportError:
        Transformer = None
        print("SKIP (affine MLS part): molesq not installed (pip install molesq)")
    binary = find_binary(args.volmorph)
    if not binary or not os.path.exists(binary):
        print("SKIP: volmorph binary not found (build it: cargo build -p volmorph-cli)")
        return 0

    rng = np.random.default_rng(args.seed)
    worst = 0.0
    failed = False
    with tempfile.TemporaryDirectory() as work:
        for trial, n in enumerate([5, 12, 40, 150]):
            src = rng.uniform(-50.0, 50.0, size=(n, 3))
            dst = src + rng.normal(0.0, 6.0, size=(n, 3))
            probes = np.vstack([rng.uniform(-70.0, 70.0, size=(200, 3)), src[:3] + 0.5])

            # Thin-plate / biharmonic spline of the displacement, both kernels.
            for kernel, scipy_kernel in (("r", "linear"), ("r2logr", "thin_plate_spline")):
                if n < 4:
                    continue
                ours = run_apply(binary, "tps", src, dst, probes, work, ["--kernel", kernel])
                rbf = RBFInterpolator(src, dst - src, kernel=scipy_kernel, degree=1)
                ref = probes + rbf(probes)
                e = rel_err(ours, ref)
                worst = max(worst, e)
                ok = e <= TOLERANCE
                failed |= not ok
                print("tps %-6s n=%4d  max rel diff vs scipy RBFInterpolator(%s): %.3e  %s"
                      % (kernel, n, scipy_kernel, e, "ok" if ok else "FAIL"))

            if Transformer is not None and n >= 4:
                ours = run_apply(binary, "affine", src, dst, probes, work)
                ref = Transformer(src, dst).transform(probes)
                e = rel_err(ours, ref)
                worst = max(worst, e)
                ok = e <= TOLERANCE
                failed |= not ok
                print("affine n=%4d  max rel diff vs molesq:                 %.3e  %s"
                      % (n, e, "ok" if ok else "FAIL"))
    print("worst relative difference: %.3e (tolerance %.0e)" % (worst, TOLERANCE))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
