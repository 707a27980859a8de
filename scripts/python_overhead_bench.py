#!/usr/bin/env python3
"""Python overhead of `volmorph.warp` over the Rust call (issue 20 target: at most 5 %).

A 256³ float32 volume is warped by pull-back (trilinear) through a moved 9×9×9 cubic lattice.
Each repetition calls `volmorph._volmorph._warp_timed`, which times `warp_volume` inside Rust
and returns that time beside the result; the overhead is (Python wall time − Rust time) / Rust
time: argument checks, the one copy of the input voxels into Rust, and wrapping the result
(moved into numpy without a copy). Median over the repetitions; build the wheel in release
first (`pip install ./python`).

    python3 scripts/python_overhead_bench.py [--size 256] [--repeat 5] [--json OUT]

Exits 0 with a message when volmorph (the Python package) is not installed.
"""

import argparse
import json
import os
import statistics
import sys
import time

TARGET_OVERHEAD = 0.05  # issue 20


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", help="write the numbers here")
    a = ap.parse_args()
    try:
        import numpy as np

        import volmorph as vm
        from volmorph._volmorph import _warp_timed
    except ImportError as e:
        print(f"skipped: {e} (pip install ./python)")
        return 0
    n = a.size
    rng = np.random.default_rng(1)
    vol = vm.Volume(rng.random((n, n, n), dtype=np.float32))
    lat = vm.Map.lattice(vol.geometry, (9, 9, 9))
    cp = lat.control_points.copy()
    cp[1:-1, 1:-1, 1:-1] += rng.uniform(-0.02 * n, 0.02 * n, cp[1:-1, 1:-1, 1:-1].shape)
    lat = lat.with_control_points(cp)
    _warp_timed(vol, lat, "pullback-linear")  # warm-up (page faults, thread pool)
    walls, rusts = [], []
    for _ in range(a.repeat):
        t = time.perf_counter()
        _, rust = _warp_timed(vol, lat, "pullback-linear")
        walls.append(time.perf_counter() - t)
        rusts.append(rust)
    over = [(w - r) / r for w, r in zip(walls, rusts)]
    out = {
        "size": n,
        "repeat": a.repeat,
        "python_s_median": statistics.median(walls),
        "rust_s_median": statistics.median(rusts),
        "overhead_median": statistics.median(over),
        "target": TARGET_OVERHEAD,
        "met": statistics.median(over) <= TARGET_OVERHEAD,
        "loadavg": os.getloadavg(),
    }
    print(
        f"{n}³ pull-back warp: Python {out['python_s_median'] * 1e3:.1f} ms, Rust "
        f"{out['rust_s_median'] * 1e3:.1f} ms, overhead {100 * out['overhead_median']:.1f} % "
        f"(target ≤ {100 * TARGET_OVERHEAD:.0f} %; load {out['loadavg'][0]:.2f})"
    )
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
