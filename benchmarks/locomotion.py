"""Locomotion benchmark (issue 6; paper Fig. 3a): how fast the walkers walk, sensitive against insensitive.

    wavewarp bench locomotion --device cuda --out benchmarks/results [--quick] [--periods N] [--set NAME=VALUE]
                              [--scenes sphere-walker prism-walker] [--twins both|sensitive|insensitive]
                              [--mechanics inertial|overdamped] [--seeds K [--noise E]]

Runs the sphere and prism walkers, each deformation-sensitive and -insensitive (the twin whose
wave runs on the rest shell), over `--periods` FHN periods (default 6) at the scenes' defaults
(`--set` overrides apply to every run). Writes locomotion.json: the device, the date, the twins' ratios per scene
(`twins`: T and the first front's mean arrival, sensitive over insensitive; the speed, insensitive
over sensitive) and a list of runs with `scene`, `sensitive`, `period` (T, measured),
`speed_R_per_T`, `distance_R`, `pulse_displacements_R`, `pulse_alignment`, `crossing_heights_R`, `lateral_R`, `sag_R`,
`first_front_mean_arrival`, `total_concentration_error`, the resolved parameters and the wall time; and locomotion.png, the forward displacement in R against t/T (Fig. 3a: sensitive
solid, insensitive dashed). `--quick`: coarse meshes over 2.2 periods (a CPU smoke run).
`--seeds K` runs every walker K times, its rest shape perturbed by `--noise` (default 1e-3 R) with
seeds 0..K-1: the JSON gains `ensembles` (per scene and twin: the mean and standard deviation of the
speed and the distance over the seeds) and the chart shows each twin's mean with a ± one standard
deviation band. `--mechanics` picks the walkers' mechanics (the same as --set mechanics=...).
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from datetime import date

import numpy as np

SCENES = ("sphere-walker", "prism-walker")
QUICK = {"sphere-walker": ["level=2"], "prism-walker": ["divisions=4"]}


def run_walker(scene: str, sensitive: bool, *, device, periods: float, overrides=(), seed: int = 0) -> tuple:
    """One walker run through the scene API (its rest-shape noise seeded by `seed`); returns (summary, run)."""
    from wavewarp.parameters import load_scene, resolve

    module = load_scene(scene)
    p = resolve(module.Parameters, None, [*overrides, f"sensitive={str(sensitive).lower()}", f"periods={periods}"])
    start = time.perf_counter()
    run = module.build(p, device=device, seed=seed, report=lambda message: None)
    run.record(run.time, run.frame())
    for _ in range(run.frames):
        run.advance_frame()
        run.record(run.time, run.frame())
    summary = {"scene": scene, "sensitive": sensitive, "seed": seed, **run.measurements(),
               "wall_time_s": time.perf_counter() - start, "parameters": run.resolved}  # fmt: skip
    return summary, run


def twin_ratios(runs: list) -> dict:
    """Sensitive over insensitive: the period T, the first front's mean arrival over the shell (the
    mechanical feedback on the wave) and, insensitive over sensitive, the speed (Fig. 3a's ratio);
    each twin's value is its mean over the seeds run."""
    if {r["sensitive"] for r in runs} != {True, False}:
        return {}

    def mean(name, sensitive):
        values = [r.get(name) for r in runs if r["sensitive"] == sensitive]
        return None if any(v is None for v in values) else float(np.mean(values))

    def ratio(name, top, bottom):
        a, b = mean(name, top), mean(name, bottom)
        return a / b if a is not None and b else None

    return {"period_sensitive_over_insensitive": ratio("period", True, False),
            "arrival_sensitive_over_insensitive": ratio("first_front_mean_arrival", True, False),
            "speed_insensitive_over_sensitive": ratio("speed_R_per_T", False, True)}  # fmt: skip


def ensembles(runs: list) -> dict:
    """Per scene and twin (over the seeds): n, and the mean and standard deviation of the speed (where
    measured) and of the distance."""
    def statistics(values):
        values = [v for v in values if v is not None]
        return {"n": len(values), "mean": float(np.mean(values)) if values else None,
                "sd": float(np.std(values, ddof=1)) if len(values) > 1 else None}  # fmt: skip

    out = {}
    for scene in dict.fromkeys(r["scene"] for r in runs):
        for sensitive in (True, False):
            chosen = [r for r in runs if r["scene"] == scene and r["sensitive"] == sensitive]
            if chosen:
                out.setdefault(scene, {})["sensitive" if sensitive else "insensitive"] = {
                    "speed_R_per_T": statistics([r["speed_R_per_T"] for r in chosen]),
                    "distance_R": statistics([r["distance_R"] for r in chosen])}  # fmt: skip
    return out


def main(argv=None) -> int:
    import warp as wp

    from wavewarp.device import resolve_device
    from wavewarp.io import write_json
    from wavewarp.figures import locomotion_png

    parser = argparse.ArgumentParser(prog="wavewarp bench locomotion", description=__doc__.split("\n")[0])
    parser.add_argument("--device", default=None, help="cpu, cuda, cuda:N (default: CUDA when present)")
    parser.add_argument("--out", default=".", help="folder for locomotion.json and locomotion.png")
    parser.add_argument("--periods", type=float, default=None, help="run length in FHN periods (default 6; --quick 2.2)")
    parser.add_argument("--quick", action="store_true", help="coarse meshes over 2.2 periods (a CPU smoke run)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="override for every run")
    parser.add_argument("--scenes", nargs="+", choices=SCENES, default=list(SCENES), help="walkers to run (default both)")
    parser.add_argument("--twins", choices=("both", "sensitive", "insensitive"), default="both",
                        help="which of the twins to run (default both)")
    parser.add_argument("--mechanics", choices=("inertial", "overdamped"), default=None,
                        help="the walkers' mechanics (default: the scenes')")  # fmt: skip
    parser.add_argument("--seeds", type=int, default=1, help="runs per walker, rest shapes perturbed with seeds 0..K-1")
    parser.add_argument("--noise", type=float, default=1e-3, help="with --seeds > 1: the rest-shape noise / R")
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error(f"--seeds must be at least 1, got {args.seeds}")
    wp.config.log_level = wp.LOG_WARNING
    device = resolve_device(args.device)
    periods = args.periods or (2.2 if args.quick else 6.0)
    os.makedirs(args.out, exist_ok=True)
    runs, lines = [], []
    twins = {"both": (True, False), "sensitive": (True,), "insensitive": (False,)}[args.twins]
    chosen = ([f"mechanics={args.mechanics}"] if args.mechanics else []) + (
        [f"noise={args.noise}"] if args.seeds > 1 else [])
    for scene in args.scenes:
        for sensitive in twins:
            for seed in range(args.seeds):
                overrides = (QUICK[scene] if args.quick else []) + chosen + args.set
                summary, run = run_walker(scene, sensitive, device=str(device), periods=periods, overrides=overrides,
                                          seed=seed)  # fmt: skip
                runs.append(summary)
                lines.append((scene, sensitive, run.trace, run.forward, run.radius))
                speed = summary["speed_R_per_T"]
                print(f"{scene:14s} {'sensitive' if sensitive else 'insensitive':11s} seed {seed} T = "
                      f"{summary['period'] or float('nan'):7.2f}  speed = {speed if speed is not None else float('nan'):+.4f}"
                      f" R/T  distance = {summary['distance_R']:+.4f} R  ({summary['wall_time_s']:.1f} s)", flush=True)  # fmt: skip
    twins_measured = {scene: twin_ratios([r for r in runs if r["scene"] == scene]) for scene in args.scenes}
    for scene, ratios in twins_measured.items():
        if ratios:
            print(f"{scene}: " + ", ".join(f"{name} {value:.4f}" for name, value in ratios.items() if value is not None))
    result = {"benchmark": "locomotion", "device": str(device), "device_name": wp.get_device(device).name,
              "host": platform.node(), "date": date.today().isoformat(), "quick": args.quick, "periods": periods,
              "seeds": args.seeds, "twins": twins_measured, "runs": runs}  # fmt: skip
    if args.seeds > 1:
        result["noise"], result["ensembles"] = args.noise, ensembles(runs)
    write_json(os.path.join(args.out, "locomotion.json"), result)
    locomotion_png(lines, os.path.join(args.out, "locomotion.png"),
                   title=f"walkers, {wp.get_device(device).name}: displacement against time (Fig. 3a)")  # fmt: skip
    print(f"wrote {os.path.join(args.out, 'locomotion.json')} and locomotion.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
