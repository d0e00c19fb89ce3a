"""Locomotion against AC over seeds (issue 28 showcase): the sphere and prism walkers, sensitive and
insensitive, each AC with 8 rest shapes perturbed by seeded noise; mean speed and its spread.

    wavewarp bench locomotion_ensemble --device cuda --out benchmarks/results

Each scene is one `wavewarp sweep` (AC × sensitive × seeds, `--batch 56`: the seeds and AC values of
one twin form one batched run, wavewarp/batch.py) in OUT/sweeps/locomotion_ensemble_<scene>_<device>
(the same command after a kill computes only the missing points) whose table is kept as
locomotion_ensemble_<scene>_<device>.csv; `--tables` charts existing tables instead (the sweep
tables of the same grid; a scene's several tables, such as a later sweep's added seeds from
`--first-seed`, are joined: a table belongs to the scene its file name holds). Writes
locomotion_ensemble_<device>.json (n, mean, standard deviation per scene, twin and AC) and .png
(mean ± one standard deviation, the seeds as dots).
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import sys
from datetime import date

import numpy as np

from wavewarp.device import describe_device, device_tag, resolve_device
from wavewarp.io import write_png, write_result
from wavewarp.sweep import SweepSpec, sweep

SCENES = ("sphere-walker", "prism-walker")
AC = ("0", "0.05", "0.1", "0.15", "0.2", "0.25", "0.3")


def run_scene(scene: str, args, device) -> list:
    """The scene's sweep over AC × sensitive × seeds on `device`'s kind, in OUT/sweeps/NAME (a re-run after a
    kill computes only the points without a result), its table kept as OUT/NAME.csv; the table's rows."""
    grid = {"AC": list(args.ac), "sensitive": ["true", "false"]}
    spec = SweepSpec(scene, grid=grid, seeds=args.seeds, first_seed=args.first_seed, fixed=(f"noise={args.noise}", *args.set),
                     quick=args.quick, device="cuda" if device.is_cuda else "cpu", h5=args.h5)  # fmt: skip
    seeds = f"_seeds{args.first_seed}-{args.first_seed + args.seeds - 1}" if args.first_seed else ""
    name = f"locomotion_ensemble_{scene}_{device_tag(device)}{seeds}"
    folder = os.path.join(args.out, "sweeps", name)
    rows = sweep(spec, folder, batch=args.batch, progress=sys.stderr.isatty(), report=lambda line: print(f"{scene}: {line}"))
    shutil.copy(os.path.join(folder, "table.csv"), os.path.join(args.out, f"{name}.csv"))
    return rows


def read_table(path: str) -> list:
    with open(path) as f:
        return list(csv.DictReader(f))


def scene_tables(paths: list, scenes: list) -> list:
    """Each scene's rows: those of every table whose file name holds the scene's name (ValueError naming a
    scene without a table, or a table of no scene)."""
    owners = {path: [scene for scene in scenes if scene in os.path.basename(path)] for path in paths}
    for path, found in owners.items():
        if len(found) != 1:
            raise ValueError(f"--tables {path}: its file name must hold exactly one of {', '.join(scenes)}")
    rows = {scene: [row for path in paths if owners[path] == [scene] for row in read_table(path)] for scene in scenes}
    for scene, found in rows.items():
        if not found:
            raise ValueError(f"--tables: no table of {scene} (file names hold the scene's name)")
    return [rows[scene] for scene in scenes]


def summary(rows: list) -> list:
    """Per (AC, sensitive): n, mean and standard deviation of speed_R_per_T over the seeds with a speed."""
    out = []
    for ac in sorted({float(r["AC"]) for r in rows}):
        for sensitive in ("true", "false"):
            speeds = [float(r["speed_R_per_T"]) for r in rows if float(r["AC"]) == ac
                      and str(r["sensitive"]).lower() == sensitive and r.get("speed_R_per_T") not in (None, "")]  # fmt: skip
            out.append({"AC": ac, "sensitive": sensitive == "true", "n": len(speeds), "speeds": speeds,
                        "mean": float(np.mean(speeds)) if speeds else None,
                        "std": float(np.std(speeds, ddof=1)) if len(speeds) > 1 else None})  # fmt: skip
    return out


def chart(result: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = list(result["scenes"])
    fig, axes = plt.subplots(1, len(scenes), figsize=(5.5 * len(scenes), 4.3), squeeze=False)
    for ax, scene in zip(axes[0], scenes):
        for k, (sensitive, label) in enumerate(((True, "sensitive"), (False, "insensitive twin"))):
            cells = [c for c in result["scenes"][scene] if c["sensitive"] == sensitive and c["n"]]
            shift = 0.004 * (1 if sensitive else -1)
            ac = np.array([c["AC"] for c in cells]) + shift
            ax.errorbar(ac, [c["mean"] for c in cells], yerr=[c["std"] or 0.0 for c in cells], fmt="o-", color=f"C{k}",
                        capsize=3, label=f"{label}, mean ± sd")  # fmt: skip
            for a, c in zip(ac, cells):
                ax.plot([a] * c["n"], c["speeds"], ".", color=f"C{k}", alpha=0.35, ms=4)
        ax.axhline(0.0, color="grey", lw=0.8)
        ax.set_xlabel("AC")
        ax.set_ylabel("speed (R per T)")
        ax.set_title(f"{scene}, {result['seeds']} seeds (noise {result['noise']} R)")
        ax.legend(fontsize=7)
    fig.suptitle(f"locomotion against AC, {result['device_name']}", fontsize=10)
    fig.tight_layout()
    write_png(fig, path, dpi=110)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench locomotion_ensemble", description=__doc__.splitlines()[0])
    parser.add_argument("--device", default=None)
    parser.add_argument("--scenes", nargs="+", default=list(SCENES))
    parser.add_argument("--ac", nargs="+", default=list(AC))
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--first-seed", type=int, default=0, help="seeds N … N+seeds-1: more seeds for an ensemble")
    parser.add_argument("--noise", type=float, default=0.01, help="rest-shape noise / R (seeded)")
    parser.add_argument("--batch", type=int, default=56, help="worlds per batched run")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="fixed for every point")
    parser.add_argument("--tables", nargs="+", default=None, metavar="CSV",
                        help="chart these sweep tables (each scene's name in its file name; several a scene are joined)")  # fmt: skip
    parser.add_argument("--device-name", default=None, help="with --tables: the GPU or CPU that computed them")
    parser.add_argument("--out", default="benchmarks/results")
    parser.add_argument("--quick", action="store_true", help="the scenes' quick runs, 2 AC values, 2 seeds")
    parser.add_argument("--h5", action="store_true", help="keep each world's trajectory in its sweep's folder: a batch "
                        "killed part-way goes on from its last stored frame when run again")  # fmt: skip
    args = parser.parse_args(argv)
    if args.quick:
        args.ac, args.seeds = ["0", "0.2"], 2
    os.makedirs(args.out, exist_ok=True)
    if args.tables is not None:
        if not args.device_name:
            parser.error("--tables needs --device-name: the GPU or CPU that computed them")
        try:
            tables = scene_tables(args.tables, args.scenes)
        except ValueError as error:
            parser.error(str(error))
        tag = tables[0][0]["device"].replace(":", "")
        described = {"device": tables[0][0]["device"], "device_name": args.device_name}
    else:
        device = resolve_device(args.device)
        tables = [run_scene(scene, args, device) for scene in args.scenes]
        tag, described = device_tag(device), describe_device(device)
    scenes = {scene: summary(rows) for scene, rows in zip(args.scenes, tables)}
    seeds = max(cell["n"] for cells in scenes.values() for cell in cells)
    result = dict(benchmark="locomotion_ensemble", date=date.today().isoformat(), **described, seeds=seeds,
                  noise=args.noise, scenes=scenes)  # fmt: skip
    write_result(result, args.out, f"locomotion_ensemble_{tag}", chart)
    return 0


if __name__ == "__main__":
    sys.exit(main())
