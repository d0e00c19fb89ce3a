"""Shell force throughput (hand-derived vs autodiff vs NumPy) and relax time (issue 3 figures).

    python benchmarks/shell.py --device cpu --levels 4 6 8 --out benchmarks/results

Throughput: triangles per second of one energy + force evaluation (3-point rule, active
reference fixed), median over batches after a warm-up, device synchronised around each batch.
The NumPy baseline (benchmarks/numpy_shell.py, float64) computes the identical energy and
gradient in the same run; the printed ratio is Warp / NumPy. Relax: wall time for
`Shell.relax` to reach its default tolerance after a uniform step c = 0 -> 1 on a level-4
icosphere (ascidian parameters, docs/theory/scenes.md). Writes `shell_<device>.json`.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from datetime import date

import numpy as np
import warp as wp

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from numpy_shell import NumpyShell  # noqa: E402

from wavewarp.device import describe_device, device_tag, resolve_device  # noqa: E402
from wavewarp.io import write_json  # noqa: E402
from wavewarp.mesh import icosphere  # noqa: E402
from wavewarp.shell import Shell  # noqa: E402

PARAMETERS = dict(thickness=0.05, young=1.0, AC=0.3, AI=0.5, volume_penalty=24 * 0.05)


def _median_seconds(run, synchronize, budget=1.0, repeats=5):
    run()
    synchronize()
    start = time.perf_counter()
    run()
    synchronize()
    once = time.perf_counter() - start
    batch = max(1, int(budget / max(once, 1e-6) / repeats))
    timings = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(batch):
            run()
        synchronize()
        timings.append((time.perf_counter() - start) / batch)
    return float(np.median(timings))


def force_rows(mesh, device, numpy_baseline):
    rng = np.random.default_rng(0)
    x = mesh.vertices * (1 + 0.01 * rng.standard_normal((mesh.n_vertices, 1)))
    c = rng.random(mesh.n_vertices)
    rows = []
    variants = [(g, d, False) for g in ("analytic", "autodiff") for d in ("float32", "float64")]
    for gradient, dtype, deterministic in variants + [("analytic", "float32", True)]:
        shell = Shell(mesh, **PARAMETERS, gradient=gradient, deterministic=deterministic, device=device, dtype=dtype)
        shell.forces(x, c)  # sets x and the active reference on the device
        seconds = _median_seconds(
            lambda: shell.forces_device(shell._x, shell._forces, shell._energy),
            lambda: wp.synchronize_device(shell.device),
        )
        path = f"warp-{gradient}" + ("-deterministic" if deterministic else "")
        rows.append(dict(path=path, dtype=dtype, triangles=mesh.n_triangles, seconds=seconds))
    if numpy_baseline:
        baseline = NumpyShell(mesh, **PARAMETERS)
        seconds = _median_seconds(lambda: baseline.energy_and_forces(x, c), lambda: None, repeats=3)
        rows.append(dict(path="numpy", dtype="float64", triangles=mesh.n_triangles, seconds=seconds))
    for row in rows:
        row["triangles_per_second"] = row["triangles"] / row["seconds"]
    return rows


def relax_rows(device):
    mesh = icosphere(1.0, 4)
    rows = []
    for dtype in ("float32", "float64"):
        shell = Shell(mesh, thickness=0.05, young=1.0, AC=1.5, AI=1.6, volume_penalty=24 * 0.05, device=device,
                      dtype=dtype)  # fmt: skip
        shell.relax(mesh.vertices, 0.2)  # warm-up: compiles every kernel
        start = time.perf_counter()
        shell.relax(mesh.vertices, 1.0)
        seconds = time.perf_counter() - start
        rows.append(dict(dtype=dtype, triangles=mesh.n_triangles, seconds=seconds,
                         iterations=len(shell.relax_history) - 1))  # fmt: skip
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench shell", description=__doc__.splitlines()[0])
    parser.add_argument("--device", default=None)
    parser.add_argument("--levels", type=int, nargs="+", default=[4, 6, 8])
    parser.add_argument("--numpy-max-level", type=int, default=8, help="skip the NumPy baseline above this level")
    parser.add_argument("--out", default="benchmarks/results")
    parser.add_argument("--quick", action="store_true", help="levels 2 and 3 only (smoke test)")
    args = parser.parse_args(argv)
    wp.config.log_level = wp.LOG_WARNING
    device = resolve_device(args.device)
    levels = [2, 3] if args.quick else args.levels
    forces = []
    for level in levels:
        rows = force_rows(icosphere(1.0, level), device.alias, level <= args.numpy_max_level)
        numpy_seconds = next((r["seconds"] for r in rows if r["path"] == "numpy"), None)
        for row in rows:
            if numpy_seconds:
                row["speedup_vs_numpy"] = numpy_seconds / row["seconds"]
            print(f"{device.alias:7s} {row['triangles']:>9d} tri  {row['path']:29s} {row['dtype']}  "
                  f"{row['triangles_per_second']:10.3e} tri/s" + (f"  x{row['speedup_vs_numpy']:.1f} vs NumPy"
                  if numpy_seconds else ""))  # fmt: skip
        forces += rows
    relax = [] if args.quick else relax_rows(device.alias)
    for row in relax:
        print(f"relax after a uniform c step, level 4 ({row['triangles']} tri), {row['dtype']}: "
              f"{row['seconds']:.3f} s, {row['iterations']} iterations")  # fmt: skip
    result = dict(benchmark="shell", date=date.today().isoformat(), **describe_device(device), parameters=PARAMETERS,
                  forces=forces, relax=relax)  # fmt: skip
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, f"shell_{device_tag(device)}.json")
    write_json(path, result)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
