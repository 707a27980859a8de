#!/usr/bin/env python3
"""Out-of-core and Dask benchmarks of chunked warps, pull-back and push-forward (issue 20).

    python3 scripts/dask_ooc_bench.py make PATH [--size 1024] [--chunk 64]
        Write a SIZE³ uint16 OME-Zarr (v0.4) test volume to PATH chunk by chunk (never the
        whole volume in memory), and the moved 9×9×9 lattice beside it (PATH.lattice.json).
    python3 scripts/dask_ooc_bench.py ooc PATH [--volmorph BIN] [--repeat 3] [--method M]
                                          [--compare crop|whole]
        The out-of-core CLI warp of the store (`volmorph warp PATH --lattice … --method M
        -o OUT.ome.zarr`) under /usr/bin/time -v: wall time and peak resident memory (target
        ≤ 1 GiB), against the in-memory CLI warp with the same method of the central
        half-size crop (written once as PATH.crop.mha) or, with `--compare whole`, of the
        whole volume (written once as PATH.mha), both in voxels per second (target: out of
        core ≥ 50 % of in memory). With `--compare whole` the two results are also compared
        voxel for voxel (the chunked warp is bit for bit the in-memory one).
    python3 scripts/dask_ooc_bench.py dask PATH [--workers 1 2] [--chunk 64] [--method M]
        Time `volmorph.dask.warp` (method M) of the store on a distributed.LocalCluster with 1 and 2
        single-threaded worker processes (target: 2 workers ≥ 1.6× one). Each run computes
        the whole warped volume (the graph cloned with fresh keys, so nothing is reused
        from an earlier run) and only its sum is gathered to the client.

Generate stores under /tmp, never inside the repository. Exits 0 with a message when
volmorph, numpy, dask or distributed is missing.
"""

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import time

TARGET_RSS_BYTES = 1 << 30  # issue 20: out-of-core peak resident memory
TARGET_OOC_RATIO = 0.5  # issue 20: out-of-core throughput over the in-memory crop's
TARGET_SPEEDUP = 1.6  # issue 20: 2 workers over 1


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


def timed(cmd):
    """Run `cmd` under /usr/bin/time -v: (wall seconds, peak RSS bytes)."""
    t = time.perf_counter()
    r = subprocess.run(["/usr/bin/time", "-v"] + cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{r.stderr}")
    rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", r.stderr).group(1))
    return wall, rss * 1024


def ooc(a, vm, np):
    exe = a.volmorph or os.environ.get("VOLMORPH") or shutil.which("volmorph")
    if not exe or not os.path.exists("/usr/bin/time"):
        print("skipped: needs the volmorph binary (--volmorph or $VOLMORPH) and /usr/bin/time")
        return 0
    base = a.path.rstrip("/")
    lattice = base + ".lattice.json"
    geometry, _, _ = vm._volmorph.zarr_info(a.path)
    n = geometry.shape
    if a.compare == "whole":
        ref = base + ".mha"
        if not os.path.exists(ref):
            subprocess.run([exe, "-q", "convert", a.path, ref], check=True)
        ref_voxels = int(np.prod(n))
    else:
        ref = base + ".crop.mha"
        if not os.path.exists(ref):
            lo = tuple(s // 4 for s in n)
            hi = tuple(l + s // 2 for l, s in zip(lo, n))
            vm._volmorph.zarr_read_box(a.path, lo, hi).write(ref)
        ref_voxels = int(np.prod([s // 2 for s in n]))
    out_z, out_m = base + ".warped.ome.zarr", base + "." + a.compare + ".warped.mha"
    method = ["--method", a.method]
    mem = "in-memory " + a.compare
    runs = {"out-of-core": [], mem: []}
    for _ in range(a.repeat):
        shutil.rmtree(out_z, ignore_errors=True)
        runs["out-of-core"].append(
            timed([exe, "-q", "warp", a.path, "--lattice", lattice, *method, "-o", out_z])
        )
        runs[mem].append(timed([exe, "-q", "warp", ref, "--lattice", lattice, *method, "-o", out_m]))
    voxels = {"out-of-core": int(np.prod(n)), mem: ref_voxels}
    rate = {}
    for k, rs in runs.items():
        wall = statistics.median(w for w, _ in rs)
        rss = max(r for _, r in rs)
        rate[k] = voxels[k] / wall
        print(
            f"{k}: {voxels[k]} voxels, median wall {wall:.2f} s over {len(rs)} runs "
            f"{[round(w, 2) for w, _ in rs]}, {rate[k] / 1e6:.1f} Mvoxel/s, peak RSS "
            f"{rss / 2**20:.0f} MiB"
        )
    peak = max(r for _, r in runs["out-of-core"])
    ratio = rate["out-of-core"] / rate[mem]
    print(
        f"{a.method}: out-of-core peak RSS {peak / 2**20:.0f} MiB (target ≤ "
        f"{TARGET_RSS_BYTES / 2**20:.0f} MiB); throughput {100 * ratio:.0f} % of the {mem}'s "
        f"(target ≥ {100 * TARGET_OOC_RATIO:.0f} %); load {os.getloadavg()}"
    )
    if a.compare == "whole":
        same = np.array_equal(vm.Volume.read(out_m).array, vm.Volume.read(out_z).array)
        print(f"out-of-core result {'equals' if same else 'DIFFERS FROM'} the in-memory one")
        if not same:
            return 1
    if not a.keep:
        shutil.rmtree(out_z, ignore_errors=True)
        os.remove(out_m)
    return 0


def dask_scaling(a, vm, np):
    try:
        import distributed
    except ImportError as e:
        print(f"skipped: {e} (pip install dask distributed)")
        return 0
    from dask.graph_manipulation import clone

    lat = vm.Map.load(a.path.rstrip("/") + ".lattice.json")
    results = {}
    for nw in a.workers:
        with distributed.LocalCluster(
            n_workers=nw, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster, distributed.Client(cluster) as client:
            t = time.perf_counter()
            w = vm.dask.warp(a.path, lat, chunks=(a.chunk,) * 3, method=a.method)
            # A push-forward is planned here, on the client (one pass of the map over the input).
            print(f"{a.method}, {nw} worker(s): graph built in {time.perf_counter() - t:.2f} s")
            c = a.chunk
            # Warm-up (imports, the map parsed once per worker): one chunk per worker.
            client.compute(clone(w)[: c * nw, :c, :c].sum()).result()
            times = []
            for _ in range(a.repeat):
                # `clone` gives the graph fresh keys, so no result of an earlier run is
                # reused; the sum keeps the warped voxels on the workers.
                t = time.perf_counter()
                client.compute(clone(w).sum()).result()
                times.append(time.perf_counter() - t)
            results[nw] = statistics.median(times)
            print(
                f"{a.method}, {nw} worker(s): median {results[nw]:.2f} s over {a.repeat} runs "
                f"{times}; load {os.getloadavg()}"
            )
    if 1 in results and 2 in results:
        print(
            f"speed-up 2 vs 1 workers: {results[1] / results[2]:.2f}× (target ≥ "
            f"{TARGET_SPEEDUP}×); load {os.getloadavg()}"
        )
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=["make", "ooc", "dask"])
    ap.add_argument("path")
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--chunk", type=int, default=64)
    ap.add_argument("--levels", type=int, default=None)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--volmorph", help="the volmorph binary (default: $VOLMORPH, then PATH)")
    ap.add_argument(
        "--method",
        default="pullback-linear",
        help="warp method (pullback-linear|nearest, pushforward-antialiased|nearest)",
    )
    ap.add_argument(
        "--compare",
        choices=["crop", "whole"],
        default="crop",
        help="ooc: the in-memory reference warps the central half-size crop or the whole volume",
    )
    ap.add_argument("--keep", action="store_true", help="ooc: keep the warped outputs")
    a = ap.parse_args()
    try:
        import numpy as np

        import volmorph as vm
        import volmorph.dask  # noqa: F401
    except ImportError as e:
        print(f"skipped: {e} (pip install ./python dask)")
        return 0
    return {"make": make, "ooc": ooc, "dask": dask_scaling}[a.what](a, vm, np)


if __name__ == "__main__":
    sys.exit(main())
