#!/usr/bin/env python3
"""Out-of-core and Dask benchmarks of chunked pull-back warps (issue 20 targets).

    python3 scripts/dask_ooc_bench.py make PATH [--size 1024] [--chunk 64]
        Write a SIZE³ uint16 OME-Zarr (v0.4) test volume to PATH chunk by chunk (never the
        whole volume in memory), and the moved 9×9×9 lattice beside it (PATH.lattice.json).
    python3 scripts/dask_ooc_bench.py dask PATH [--workers 1 2] [--chunk 64]
        Time `volmorph.dask.warp` of the store on a distributed.LocalCluster with 1 and 2
        single-threaded worker processes (target: 2 workers ≥ 1.6× one).

The out-of-core CLI run is measured with /usr/bin/time -v (peak RSS target ≤ 1 GiB):

    /usr/bin/time -v target/release/volmorph warp PATH --lattice PATH.lattice.json -o OUT.ome.zarr

Generate stores under /tmp, never inside the repository. Exits 0 with a message when
volmorph, numpy, dask or distributed is missing.
"""

import argparse
import os
import statistics
import sys
import time


def moved_lattice(vm, np, geometry, rng, amount):
    lat = vm.Map.lattice(geometry, (9, 9, 9))
    cp = lat.control_points.copy()
    cp[1:-1, 1:-1, 1:-1] += rng.uniform(-amount, amount, cp[1:-1, 1:-1, 1:-1].shape)
    return lat.with_control_points(cp)


def make(a, vm, np):
    n, c = a.size, a.chunk
    g = vm.Geometry((n, n, n), spacing=(1.0, 1.0, 1.0))
    w = vm._volmorph.OmeZarrWriter(a.path, g, "uint16", (c, c, c), 2, a.levels)
    staging = str(w.staging)
    zz, yy, xx = np.meshgrid(*[np.arange(c)] * 3, indexing="ij")
    t = time.perf_counter()
    for z in range(0, n, c):
        for y in range(0, n, c):
            for x in range(0, n, c):
                block = ((xx + x) * 7 + (yy + y) * 13 + (zz + z) * 29) % 4096
                block = block[: n - z, : n - y, : n - x].astype(np.uint16)
                vm._volmorph.zarr_store_chunk(staging, (z, y, x), vm.Volume(np.ascontiguousarray(block)))
    w.finish()
    lat = moved_lattice(vm, np, g, np.random.default_rng(1), 0.02 * n)
    lat.save(a.path.rstrip("/") + ".lattice.json")
    print(f"wrote {a.path} ({n}³ u16, chunks {c}³) in {time.perf_counter() - t:.1f} s")
    return 0


def dask_scaling(a, vm, np):
    try:
        import distributed
    except ImportError as e:
        print(f"skipped: {e} (pip install dask distributed)")
        return 0
    lat = vm.Map.load(a.path.rstrip("/") + ".lattice.json")
    results = {}
    for nw in a.workers:
        with distributed.LocalCluster(
            n_workers=nw, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster, distributed.Client(cluster) as client:
            w = vm.dask.warp(a.path, lat, chunks=(a.chunk,) * 3)
            client.compute(w.sum()).result()  # warm-up: imports, page cache
            times = []
            for _ in range(a.repeat):
                t = time.perf_counter()
                client.compute(w.sum()).result()
                times.append(time.perf_counter() - t)
            results[nw] = statistics.median(times)
            print(f"{nw} worker(s): median {results[nw]:.2f} s over {a.repeat} runs {times}")
    if 1 in results and 2 in results:
        print(f"speed-up 2 vs 1 workers: {results[1] / results[2]:.2f}× (target ≥ 1.6×); load {os.getloadavg()[0]:.2f}")
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=["make", "dask"])
    ap.add_argument("path")
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--chunk", type=int, default=64)
    ap.add_argument("--levels", type=int, default=None)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    try:
        import numpy as np

        import volmorph as vm
        import volmorph.dask  # noqa: F401
    except ImportError as e:
        print(f"skipped: {e} (pip install ./python dask)")
        return 0
    return make(a, vm, np) if a.what == "make" else dask_scaling(a, vm, np)


if __name__ == "__main__":
    sys.exit(main())
