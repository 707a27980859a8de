#!/usr/bin/env python3
"""Peer check of volmorph's ITK BSplineTransform export against SimpleITK.

For each seed, runs the `itk_bspline_check` example of volmorph-deform, which writes a random
cubic B-spline lattice as an ITK text transform file plus the lattice's images of random points
(some outside the lattice box), then reads the file with SimpleITK and compares
`TransformPoint(p)` with volmorph's `apply(p)`. Then the reverse direction: SimpleITK writes
the transform it read to a new file, volmorph reads that file (`--read` mode of the example)
and its `apply` is compared with `TransformPoint` again.

Usage: scripts/itk_bspline_check.py [--seeds N] [--points M] [--tol T]
Exits 0 with a SKIP message when SimpleITK is not importable, 1 on any disagreement.
"""
import argparse
import os
import subprocess
import sys
import tempfile

try:
    import SimpleITK as sitk
except ImportError:
    print("SKIP: SimpleITK is not installed (pip install SimpleITK)")
    sys.exit(0)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--points", type=int, default=500)
    ap.add_argument("--tol", type=float, default=1e-9, help="relative to the lattice size")
    args = ap.parse_args()

    subprocess.run(
        ["cargo", "build", "-q", "-p", "volmorph-deform", "--example", "itk_bspline_check"],
        cwd=ROOT,
        check=True,
    )
    exe = os.path.join(
        os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target")),
        "debug",
        "examples",
        "itk_bspline_check",
    )
    print(f"SimpleITK {sitk.Version.VersionString()} (ITK {sitk.Version.ITKVersionString()})")
    worst = 0.0
    failed = False
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(1, args.seeds + 1):
            tfm = os.path.join(tmp, f"lat{seed}.tfm")
            pts = os.path.join(tmp, f"pts{seed}.txt")
            info = subprocess.run(
                [exe, tfm, pts, str(seed), str(args.points)],
                check=True,
                capture_output=True,
                text=True,
            ).stdout.strip()
            tx = sitk.ReadTransform(tfm)
            rows = [list(map(float, l.split())) for l in open(pts) if l.strip()]
            scale = max(max(abs(v) for v in r) for r in rows)
            err = 0.0
            moved = 0
            for r in rows:
                p, q = r[:3], r[3:]
                t = tx.TransformPoint(p)
                err = max(err, max(abs(a - b) for a, b in zip(t, q)))
                moved += any(abs(a - b) > 0 for a, b in zip(p, q))
            back = os.path.join(tmp, f"back{seed}.tfm")
            sitk.WriteTransform(tx, back)
            mapped = subprocess.run(
                [exe, "--read", back, pts], check=True, capture_output=True, text=True
            ).stdout.split("\n")
            for r, line in zip(rows, mapped):
                t = tx.TransformPoint(r[:3])
                q = list(map(float, line.split()))
                err = max(err, max(abs(a - b) for a, b in zip(t, q)))
            rel = err / scale
            worst = max(worst, rel)
            ok = rel <= args.tol
            failed |= not ok
            print(
                f"seed {seed:3}: {info}; {len(rows)} points ({moved} moved), "
                f"max |ITK - volmorph| (both directions) = {err:.3e} ({rel:.1e} relative) {'ok' if ok else 'FAIL'}"
            )
    print(f"worst relative disagreement {worst:.2e} (tolerance {args.tol:.0e})")
    print("FAIL" if failed else "PASS")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
