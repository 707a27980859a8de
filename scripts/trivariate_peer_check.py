#!/usr/bin/env python3
"""Compare volmorph-trivariate evaluation (points and first partial derivatives of rational
volumes, both the refinement and the de Boor method) with splinepy on random volumes.

Skips cleanly (exit 0 with a message) when numpy or splinepy is not installed.
Run from the repository root:  python3 scripts/trivariate_peer_check.py
"""
import json
import os
import subprocess
import sys
import tempfile

try:
    import numpy as np
    import splinepy
except ImportError as e:  # pragma: no cover
    print(f"SKIP: {e.name} not installed")
    sys.exit(0)

TOL = 1e-10
rng = np.random.default_rng(20240611)


def random_volume():
    degrees = [int(d) for d in rng.integers(1, 4, size=3)]
    knots, counts = [], []
    for p in degrees:
        m = int(rng.integers(0, 4))
        interior = sorted(float(x) for x in rng.uniform(0.05, 0.95, size=m))
        knots.append([0.0] * (p + 1) + interior + [1.0] * (p + 1))
        counts.append(p + 1 + m)
    n = counts[0] * counts[1] * counts[2]
    pts = rng.uniform(-2, 2, size=(n, 3))
    ws = rng.uniform(0.3, 2.3, size=(n, 1))
    return degrees, knots, pts, ws


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    subprocess.run(
        ["cargo", "build", "-q", "-p", "volmorph-trivariate", "--features", "examples",
         "--example", "eval_points"],
        cwd=root, check=True)
    exe = os.path.join(root, "target", "debug", "examples", "eval_points")
    worst = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        for trial in range(20):
            degrees, knots, pts, ws = random_volume()
            doc = {
                "format": "volmorph-trivariate", "version": 1, "kind": "volume",
                "geometry": {"degrees": degrees, "knots": knots, "dim": 3,
                             "points": pts.ravel().tolist(), "weights": ws.ravel().tolist()},
            }
            vol = os.path.join(tmp, "v.json")
            with open(vol, "w") as f:
                json.dump(doc, f)
            params = rng.uniform(0, 1, size=(200, 3))
            params[:8] = [[a, b, c] for a in (0, 1) for b in (0, 1) for c in (0, 1)]
            ptxt = os.path.join(tmp, "p.txt")
            np.savetxt(ptxt, params, fmt="%.17e")
            # splinepy stores control points with the first parametric axis fastest, as volmorph.
            ref = splinepy.NURBS(degrees=degrees, knot_vectors=knots, control_points=pts, weights=ws)
            want = np.hstack([ref.evaluate(params)] +
                             [ref.derivative(params, o) for o in ([1, 0, 0], [0, 1, 0], [0, 0, 1])])
            for method in ("refinement", "de-boor"):
                out = subprocess.run([exe, vol, ptxt, method], check=True,
                                     capture_output=True, text=True).stdout
                got = np.array([[float(x) for x in line.split()] for line in out.splitlines()])
                scale = 1.0 + np.abs(want)
                err = float(np.max(np.abs(got - want) / scale))
                worst = max(worst, err)
                status = "ok" if err <= TOL else "FAIL"
                print(f"volume {trial:2d} degrees {degrees} {method:10s}: "
                      f"max rel. error {err:.2e} {status}")
    print(f"worst relative error {worst:.2e} (tolerance {TOL:.0e})")
    return 0 if worst <= TOL else 1


if __name__ == "__main__":
    sys.exit(main())
