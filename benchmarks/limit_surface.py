"""Limit-surface kernel throughput, table size and cold compile time (issue 2 figures).

    python benchmarks/limit_surface.py --device cpu --levels 4 6 7 --out benchmarks/results

Throughput is quadrature points per second of `limit_surface_kernel` (3-point rule), the
median over repeated launches after a warm-up, with the device synchronised around each
batch. Writes `limit_surface_<device>.json`.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from datetime import date

import numpy as np
import warp as wp

from wavewarp.device import describe_device, device_tag, resolve_device
from wavewarp.geometry import SurfaceTables, evaluate
from wavewarp.mesh import icosphere

COLD_COMPILE = """
import time, warp as wp
wp.config.log_level = wp.LOG_WARNING
from wavewarp.geometry import limit_surface
from wavewarp.mesh import icosphere
mesh = icosphere(1.0, 1)
start = time.perf_counter()
for dtype in ("float32", "float64"):
    limit_surface(mesh, device={device!r}, dtype=dtype)
print(time.perf_counter() - start)
"""


def cold_compile_seconds(device: str) -> float:
    """Kernel build time of both dtypes in a fresh process with an empty kernel cache."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, WARP_CACHE_PATH=cache)
        out = subprocess.run(
            [sys.executable, "-c", COLD_COMPILE.format(device=device)], env=env, capture_output=True, text=True, check=True
        )
    return float(out.stdout.strip().splitlines()[-1])


def throughput(mesh, device: str, dtype: str, repeats: int) -> dict:
    tables = SurfaceTables.of(mesh, "3", device=device, dtype=dtype)
    x = tables.positions()
    out = evaluate(tables, x)  # warm-up and allocation
    wp.synchronize_device(tables.device)
    batch = max(1, int(2e6 // tables.n_quadrature_points))
    timings = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(batch):
            evaluate(tables, x, out)
        wp.synchronize_device(tables.device)
        timings.append((time.perf_counter() - start) / batch)
    seconds = float(np.median(timings))
    scalar = 4 if dtype == "float32" else 8
    return {
        "triangles": mesh.n_triangles,
        "quadrature_points": tables.n_quadrature_points,
        "dtype": dtype,
        "seconds_per_launch": seconds,
        "points_per_second": tables.n_quadrature_points / seconds,
        "table_bytes_per_triangle": tables.host.nbytes_per_triangle(scalar),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench limit_surface", description=__doc__.splitlines()[0])
    parser.add_argument("--device", default=None)
    parser.add_argument("--levels", type=int, nargs="+", default=[4, 6, 7])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", default="benchmarks/results")
    args = parser.parse_args(argv)
    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    device = resolve_device(args.device)
    rows = []
    for level in args.levels:
        mesh = icosphere(1.0, level)
        for dtype in ("float32", "float64"):
            row = throughput(mesh, device.alias, dtype, args.repeats)
            rows.append(row)
            print(
                f"{device.alias:8s} {dtype}  {row['triangles']:>9d} triangles  "
                f"{row['points_per_second'] / 1e6:10.2f} M points/s  {row['table_bytes_per_triangle']:.1f} B/triangle"
            )
    compile_s = cold_compile_seconds(device.alias)
    print(f"cold compile of the limit-surface kernels (float32 + float64) on {device.alias}: {compile_s:.2f} s")
    result = {
        "benchmark": "limit_surface",
        "date": date.today().isoformat(),
        **describe_device(device),
        "cold_compile_seconds": compile_s,
        "rows": rows,
    }
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, f"limit_surface_{device_tag(device)}.json")
    from wavewarp.io import write_json

    write_json(path, result)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
