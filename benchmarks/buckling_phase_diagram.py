"""The supplement's Fig. S1b as a phase diagram: the buckling mode n over AI × h/R, from buckling-modes sweeps.

    wavewarp sweep buckling-modes --grid AI=7.5,8.5,...,13.5 --grid thickness=0.1,0.2,...,0.75 \\
        --set adaptive_dt=false --set self_contact=false --set level=4 [--set k=3] --batch 49 --out DIR
    wavewarp bench buckling_phase_diagram --sweeps DIR [DIR ...] --labels "k = 1" ["k = 3"] --out benchmarks/results

One panel per sweep folder: each cell is a grid point, its colour and number the mode n the shell
buckled into (`n_onset`, the first nonzero symmetry number; from the points' frames where the folder
keeps them, else the table's column; where only `n_mode` is in the table, that), its amplitude in
units of h below it (`amplitude_max_h`), and a cross where the run stopped early. Writes
buckling_phase_diagram.png and .json (the cells).
"""

from __future__ import annotations

import argparse
import csv
import glob
import json
import os
import sys
from datetime import date

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from wavewarp.io import write_json, write_png  # noqa: E402
from wavewarp.measurements import buckling_modes  # noqa: E402
from wavewarp.scenes.buckling_modes import Parameters  # noqa: E402

N_COLOURS = plt.get_cmap("tab10")


def sweep_cells(folder: str) -> tuple:
    """(cells, definition): one cell per point of the sweep in `folder`: AI, h/R, n (and which measure
    gave it), amplitude, status."""
    with open(os.path.join(folder, "sweep.json")) as f:
        definition = json.load(f)
    fixed = dict(item.split("=", 1) for item in definition["fixed"])
    radius = float(fixed.get("radius", Parameters.radius))
    with open(os.path.join(folder, "table.csv")) as f:
        rows = {row["point"]: row for row in csv.DictReader(f)}
    frames = {}
    for path in glob.glob(os.path.join(folder, "points", "*.json")):
        with open(path) as f:
            result = json.load(f)
        frames[result["point"]] = result.get("measurements", {}).get("symmetry_numbers")
    cells = []
    for name, row in rows.items():
        if frames.get(name) is not None:
            n, source = buckling_modes(frames[name])["n_onset"], "n_onset"
        else:
            source = "n_onset" if row.get("n_onset") not in (None, "") else "n_mode"
            n = int(float(row[source])) if row.get(source) not in (None, "") else None
        cells.append({"AI": float(row["AI"]), "h_over_R": float(row["thickness"]) / radius, "n": n, "source": source,
                      "amplitude_h": float(row["amplitude_max_h"]) if row.get("amplitude_max_h") else None,
                      "status": row["status"], "device": row.get("device", "")})  # fmt: skip
    return cells, definition


def draw(ax, cells: list, label: str) -> None:
    ais = sorted({c["AI"] for c in cells})
    hs = sorted({c["h_over_R"] for c in cells})
    for cell in cells:
        i, j = ais.index(cell["AI"]), hs.index(cell["h_over_R"])
        n = cell["n"]
        colour = "0.92" if not n else N_COLOURS(n % 10)
        ax.add_patch(plt.Rectangle((i - 0.5, j - 0.5), 1, 1, color=colour))
        ax.text(i, j + 0.1, "?" if n is None else str(n), ha="center", va="center", fontsize=10,
                color="k" if not n else "w", weight="bold")  # fmt: skip
        if cell["amplitude_h"] is not None:
            ax.text(i, j - 0.25, f"{cell['amplitude_h']:.2g} h", ha="center", va="center", fontsize=6,
                    color="0.3" if not n else "w")  # fmt: skip
        if cell["status"] != "done":
            ax.plot([i - 0.45, i + 0.45], [j - 0.45, j + 0.45], color="k", lw=0.8)
    sources = sorted({c["source"] for c in cells})
    ax.set_xlim(-0.5, len(ais) - 0.5)
    ax.set_ylim(-0.5, len(hs) - 0.5)
    ax.set_xticks(range(len(ais)), [f"{a:g}" for a in ais])
    ax.set_yticks(range(len(hs)), [f"{h:.3g}" for h in hs])
    ax.set_xlabel("curvature coupling AI")
    ax.set_ylabel("h / R")
    ax.set_title(f"{label}: n = {' / '.join(sources)} (0: axisymmetric)", fontsize=9)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench buckling_phase_diagram", description=__doc__.splitlines()[0])
    parser.add_argument("--sweeps", nargs="+", required=True, help="buckling-modes sweep folders (one panel each)")
    parser.add_argument("--labels", nargs="+", default=None, help="a title per panel (default: the folder names)")
    parser.add_argument("--out", default="benchmarks/results")
    args = parser.parse_args(argv)
    labels = args.labels or [os.path.basename(os.path.normpath(s)) for s in args.sweeps]
    if len(labels) != len(args.sweeps):
        parser.error(f"--labels needs one title per sweep folder: {len(labels)} for {len(args.sweeps)}")
    fig, axes = plt.subplots(1, len(args.sweeps), figsize=(5.6 * len(args.sweeps), 5.0), squeeze=False)
    panels = []
    for ax, folder, label in zip(axes[0], args.sweeps, labels):
        cells, definition = sweep_cells(folder)
        draw(ax, cells, label)
        panels.append({"label": label, "folder": folder, "sweep": definition, "cells": cells})
        counts = np.bincount([c["n"] or 0 for c in cells])
        print(f"{label}: {len(cells)} points; n = " + ", ".join(f"{n}: {k}" for n, k in enumerate(counts) if k))
    fig.suptitle("Buckling mode n of the steady front (supplement Fig. S1b): wavewarp buckling-modes", fontsize=10)
    fig.tight_layout()
    os.makedirs(args.out, exist_ok=True)
    stem = os.path.join(args.out, "buckling_phase_diagram")
    write_png(fig, f"{stem}.png")
    write_json(f"{stem}.json", {"benchmark": "buckling_phase_diagram", "date": date.today().isoformat(), "panels": panels})
    return 0


if __name__ == "__main__":
    sys.exit(main())
