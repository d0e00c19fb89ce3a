"""Numbering benchmark (issue 7; docs/theory/geometry.md#numbering-for-memory-locality): the Koiter force kernel in old and new mesh numberings.

    wavewarp bench numbering --device cuda:0 --levels 6 7 8 --out benchmarks/results

The sphere walker's shell without its volume term (the "koiter forces" row of `wavewarp bench
speed`), one icosphere per level in several numberings: `old`, the subdivision's own
(`icosphere(reorder=False)`); `new`, what `icosphere()` returns (vertices in order of first use);
`hilbert`, the order `load` gives a file (triangles along a 3-D Hilbert curve); `shuffled`, a
random numbering (the control). Each variant is timed as the speed benchmark times kernels
(`seconds_per_call`), `Shell.forces_device` without and with the energy, at the same physical
state, and printed with the ratio old / variant (> 1: faster than old), the largest force
difference against old relative to the largest force, and `PatchTables.locality` up to
--stats-max-level. Writes numbering_<device>.json (numbering_<device>_float64.json for float64).
`--quick`: levels 3 and 4, short timings (a CPU smoke run).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from datetime import date

import numpy as np
import warp as wp

from wavewarp.benchmarks.speed import AC, RADIUS, THICKNESS, WALKER, seconds_per_call
from wavewarp.device import describe_device, device_tag, resolve_device
from wavewarp.geometry import patch_tables
from wavewarp.io import write_json
from wavewarp.mesh import icosphere
from wavewarp.shell import Shell

VARIANTS = ("old", "new", "hilbert", "shuffled")


def numberings(level: int, variants) -> dict:
    """name -> (mesh, vertex_order): vertex i of the variant is vertex vertex_order[i] of old."""
    old = icosphere(RADIUS, level, reorder=False)
    out = {}
    for name in variants:
        if name == "old":
            order, mesh = np.arange(old.n_vertices), old
        elif name == "new":
            order, triangles = old.reordering(keep_triangle_order=True)
            mesh = old.permuted(order, triangles)  # = icosphere(RADIUS, level) (tests/test_numbering.py)
        elif name == "hilbert":
            order, triangles = old.reordering()
            mesh = old.permuted(order, triangles)
        elif name == "shuffled":
            rng = np.random.default_rng(level)
            order = rng.permutation(old.n_vertices)
            mesh = old.permuted(order, rng.permutation(old.n_triangles))
        else:
            raise ValueError(f"unknown variant {name!r}; valid: {', '.join(VARIANTS)}")
        out[name] = (mesh, order)
    return out


def level_rows(level: int, variants, device, dtype: str, budget: float, stats: bool) -> list:
    """One row per variant (old first: the reference of the ratios and of the force differences)."""
    built = time.perf_counter()
    meshes = numberings(level, variants)
    rng = np.random.default_rng(level)
    old = meshes["old"][0]
    x = old.vertices * (1 + 0.01 * rng.standard_normal((old.n_vertices, 1)))
    c = rng.random(old.n_vertices)
    print(f"level {level}: {old.n_triangles:,} triangles, {old.n_vertices:,} vertices "
          f"(meshes built in {time.perf_counter() - built:.1f} s)", flush=True)  # fmt: skip
    rows, reference = [], None
    for name, (mesh, order) in meshes.items():
        built = time.perf_counter()
        shell = Shell(mesh, thickness=THICKNESS, young=WALKER["young"], poisson=WALKER["poisson"], AC=AC, AI=0.0,
                      device=device, dtype=dtype)  # fmt: skip
        forces = shell.forces(x[order], c[order]).astype(np.float64)  # sets x and the active reference on the device
        if reference is None:
            reference = forces
        deviation = float(np.abs(forces - reference[order]).max() / np.abs(reference).max())
        row = dict(level=level, variant=name, triangles=mesh.n_triangles, vertices=mesh.n_vertices, dtype=dtype,
                   force_deviation=deviation)  # fmt: skip
        for label, call in (
            ("forces", lambda s=shell: s.forces_device(s._x, s._forces)),
            ("forces_energy", lambda s=shell: s.forces_device(s._x, s._forces, s._energy)),
        ):
            seconds = seconds_per_call(call, device, budget)
            row[f"{label}_ms"] = seconds * 1e3
            row[f"{label}_triangles_per_s"] = mesh.n_triangles / seconds
        if stats:
            row.update(patch_tables(mesh).locality())
        row["host_seconds"] = time.perf_counter() - built
        first = rows[0] if rows else row
        row.update(speedup_vs_old=first["forces_ms"] / row["forces_ms"],
                   speedup_vs_old_with_energy=first["forces_energy_ms"] / row["forces_energy_ms"])  # fmt: skip
        rows.append(row)
        locality = ("" if not stats else f"  span {row['span']:9.0f}  warp sectors/tri {row['warp_sectors']:5.2f}"
                    f"  block sectors/tri {row['block_sectors']:5.3f}")  # fmt: skip
        print(f"  {name:9s} forces {row['forces_ms']:8.4f} ms {row['forces_triangles_per_s']:9.3e} tri/s"
              f"  x{row['speedup_vs_old']:5.3f} | +energy {row['forces_energy_ms']:8.4f} ms"
              f" {row['forces_energy_triangles_per_s']:9.3e} tri/s  x{row['speedup_vs_old_with_energy']:5.3f}"
              f" | dF {deviation:.1e}{locality}  (host {row['host_seconds']:.1f} s)", flush=True)  # fmt: skip
        del shell
    return rows


def summary(rows: list, variants) -> None:
    """The ratios old / variant, one line per level and kernel, the variants side by side."""
    print("old / variant (> 1: faster than old)")
    print(f"{'':19s}" + "".join(f"{v:>10s}" for v in variants))
    for level in sorted({r["level"] for r in rows}):
        by_name = {r["variant"]: r for r in rows if r["level"] == level}
        for key, label in (("speedup_vs_old", "forces"), ("speedup_vs_old_with_energy", "+energy")):
            print(f"  level {level:<2d} {label:8s}" + "".join(f"{by_name[v][key]:10.3f}" for v in variants))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench numbering", description=__doc__.splitlines()[0])
    parser.add_argument("--device", default=None, help="cpu, cuda, cuda:N (default: CUDA when present)")
    parser.add_argument("--levels", type=int, nargs="+", default=[6, 7, 8], help="icosphere levels (default 6 7 8)")
    parser.add_argument("--dtype", default="float32", choices=("float32", "float64"))
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS,
                        help="numberings to time (old is always run: the reference)")  # fmt: skip
    parser.add_argument("--budget", type=float, default=0.25, help="seconds per timing (default 0.25)")
    parser.add_argument("--stats-max-level", type=int, default=7,
                        help="locality statistics up to this level (host side: ~2 s per variant at level 8; default 7)")
    parser.add_argument("--out", default="benchmarks/results")
    parser.add_argument("--quick", action="store_true", help="levels 3 and 4, short timings (a CPU smoke run)")
    args = parser.parse_args(argv)
    wp.config.log_level = wp.LOG_WARNING
    device = resolve_device(args.device)
    levels, budget = ([3, 4], 0.02) if args.quick else (args.levels, args.budget)
    variants = ["old"] + [v for v in dict.fromkeys(args.variants) if v != "old"]
    print(f"{device.alias} ({device.name}), {args.dtype}, Warp {wp.config.version}", flush=True)
    rows, begin = [], time.perf_counter()
    for level in levels:
        rows += level_rows(level, variants, device.alias, args.dtype, budget, level <= args.stats_max_level)
    summary(rows, variants)
    print(f"total {time.perf_counter() - begin:.1f} s")
    result = dict(benchmark="numbering", date=date.today().isoformat(), **describe_device(device), quick=args.quick,
                  dtype=args.dtype, budget=budget, levels=levels, variants=variants, rows=rows)  # fmt: skip
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, f"numbering_{device_tag(device)}" + ("_float64" if args.dtype == "float64" else "")
                        + ".json")  # fmt: skip
    write_json(path, result)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
